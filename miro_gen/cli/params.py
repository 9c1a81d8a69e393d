"""`miro-params`: the makeParams compiler's command line (the parameters issue implements it)."""

from __future__ import annotations

import sys
from collections.abc import Sequence


def main(argv: Sequence[str] | None = None) -> int:
    print(
        "miro-params: not available yet in this version of miro-gen "
        "(parameter compilation lands with the miro-params issue)",
        file=sys.stderr,
    )
    return 2


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
