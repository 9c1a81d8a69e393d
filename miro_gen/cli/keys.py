"""`miro keys new`: make the CURVE key of a robot or a fleet (docs/SECURITY.md)."""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Sequence

from miro_gen.transport.keyfiles import DEFAULT_KEY, KEY_SUFFIX, write_key_pair


def keys_main(argv: Sequence[str]) -> int:
    p = argparse.ArgumentParser(
        prog="miro keys",
        description="Make the key that the processes of a robot (or of a fleet) share: with it "
        "(--keys FILE, or MIRO_KEYS), every connection is encrypted and only processes that "
        "hold it can call, publish or subscribe (ZeroMQ CURVE).",
    )
    sub = p.add_subparsers(dest="command", metavar="COMMAND")
    new = sub.add_parser(
        "new",
        help="write a new key pair: NAME.key_secret (secret: copy it to each machine that must "
        "take part, readable by its user only) and NAME.key (public)",
    )
    new.add_argument(
        "name",
        nargs="?",
        default=DEFAULT_KEY.removesuffix(KEY_SUFFIX),
        metavar="NAME",
        help=f"where to write it, without suffix (default {DEFAULT_KEY.removesuffix(KEY_SUFFIX)}:"
        " the key services use without --keys)",
    )
    new.add_argument("-f", "--force", action="store_true", help="replace an existing key")
    ns = p.parse_args(argv)
    if ns.command is None:
        p.print_help()
        return 0
    base = os.path.expanduser(ns.name).removesuffix(KEY_SUFFIX)
    secret = base + KEY_SUFFIX
    try:
        public_file, secret_file = write_key_pair(base, replace=ns.force)
    except FileExistsError:
        p.error(
            f"{secret} exists (use --force to replace it: processes holding the old key "
            "can then no longer connect)"
        )
    except OSError as e:
        print(f"miro keys: cannot write {secret}: {e.strerror or e}", file=sys.stderr)
        return 1
    print(f"secret key: {secret_file}")
    print(f"public key: {public_file}")
    print(f"give it to every process of the robot or fleet: --keys {secret_file}")
    return 0
