"""What the live tools' commands (call, list, pub, param) share: their arguments read with the
common options checked and taken out first (so that `--help` and usage errors come before any
look for the naming service), then a connection to the robot."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from miro_gen.cli.eventargs import split_common
from miro_gen.live.remote import LiveError, Robot


def connect(
    p: argparse.ArgumentParser, prog: str, argv: Sequence[str]
) -> tuple[Robot, argparse.Namespace]:
    ns = p.parse_args(split_common(p, argv))
    try:
        return Robot([prog, *argv]), ns
    except LiveError as e:  # a naming service the live tools cannot use
        print(f"{prog}: {e}", file=sys.stderr)
        raise SystemExit(1) from None
