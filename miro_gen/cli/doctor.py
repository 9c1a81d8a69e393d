"""`miro doctor`: what naming services this machine can see, and why a connection fails."""

from __future__ import annotations

import argparse
from collections.abc import Sequence


def doctor_main(argv: Sequence[str]) -> int:
    p = argparse.ArgumentParser(
        prog="miro doctor",
        description="Say where processes here look for the naming service and whether one "
        "answers there, this machine's networks, and the naming services announced on them "
        "(multicast DNS), each with whether it answers and why not. Accepts --naming URL.",
    )
    p.add_argument("--naming", metavar="URL", help="check this address instead of the default")
    p.add_argument(
        "--timeout", type=float, default=3.0, metavar="S", help="seconds to listen (default 3)"
    )
    ns = p.parse_args(argv)
    from miro_gen.service.options import UsageError, parse_common_options
    from miro_gen.transport.naming.discovery import diagnose

    try:
        opts, _ = parse_common_options(["--naming", ns.naming] if ns.naming else [])
    except UsageError as e:
        p.error(str(e))
    for line in diagnose(opts.naming, ns.timeout):
        print(line)
    return 0
