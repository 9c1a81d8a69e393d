"""`miro keys new`: make the CURVE key of a robot or a fleet (docs/SECURITY.md)."""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Sequence

from miro_gen.cli.verbs import verb
from miro_gen.transport.keyfiles import DEFAULT_KEY, KEY_SUFFIX, write_key_pair


def new_main(argv: Sequence[str]) -> int:
    """`miro keys new`."""
    what = verb("keys new").help
    new = argparse.ArgumentParser(
        prog="miro keys new", description=f"{what[0].upper()}{what[1:]}. {verb('keys').description}"
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
    ns = new.parse_args(argv)
    base = os.path.expanduser(ns.name).removesuffix(KEY_SUFFIX)
    secret = base + KEY_SUFFIX
    try:
        public_file, secret_file = write_key_pair(base, replace=ns.force)
    except FileExistsError:
        new.error(
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
