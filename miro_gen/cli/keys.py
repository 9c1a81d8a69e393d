"""`miro keys new`: make the key of a robot or a fleet (docs/SECURITY.md): the CURVE pair of
the ZeroMQ backbone and the TLS files of the Zenoh backbone (a CA and a certificate), or, with
`--ca FLEET`, one more certificate of an existing fleet's CA."""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Sequence

from miro_gen.cli.verbs import verb
from miro_gen.transport.keyfiles import DEFAULT_KEY, KEY_SUFFIX, write_key_pair
from miro_gen.transport.tlsfiles import CERT_SECRET_SUFFIX, TlsFiles, base_of, tls_available
from miro_gen.transport.usage import UsageError


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
    new.add_argument(
        "--ca",
        metavar="FLEET",
        help="make only NAME's TLS certificate and private key (NAME.cert.pem, "
        "NAME.cert_secret.pem), signed by the CA of the key FLEET (made here before with "
        "`miro keys new FLEET`), with a copy of FLEET's CA certificate: a robot's own key "
        "for the Zenoh backbone, whose router lets in every certificate of FLEET's CA",
    )
    ns = new.parse_args(argv)
    base = base_of(ns.name)
    if ns.ca is not None:
        return _certificate(new, base, ns.ca, ns.force)
    secret = base + KEY_SUFFIX
    if not ns.force:
        for taken in (secret, base + CERT_SECRET_SUFFIX):
            if os.path.lexists(taken):
                new.error(
                    f"{taken} exists (use --force to replace it: processes holding the old "
                    "key can then no longer connect)"
                )
    try:
        public_file, secret_file = write_key_pair(base, replace=True)
        tls = _tls(base, None) if tls_available() else None
    except UsageError as e:
        print(f"miro keys: {e}", file=sys.stderr)
        return 1
    except OSError as e:
        print(f"miro keys: cannot write {e.filename or secret}: {e.strerror or e}", file=sys.stderr)
        return 1
    print(f"secret key: {secret_file}")
    print(f"public key: {public_file}")
    if tls is None:
        print("TLS files for the Zenoh backbone: not made (pip install 'miro-gen[zenoh]')")
    else:
        print(f"TLS (Zenoh): CA {tls.ca}, certificate {tls.certificate}, key {tls.private_key}")
    print(f"give it to every process of the robot or fleet: --keys {secret_file}")
    return 0


def _tls(base: str, ca: str | None) -> TlsFiles:
    from miro_gen.transport.tlsfiles import write_tls

    return write_tls(base, ca_base=ca, replace=True)


def _certificate(new: argparse.ArgumentParser, base: str, ca: str, force: bool) -> int:
    """`miro keys new NAME --ca FLEET`."""
    if not tls_available():
        new.error("--ca needs the cryptography package: pip install 'miro-gen[zenoh]'")
    taken = base + CERT_SECRET_SUFFIX
    if not force and os.path.lexists(taken):
        new.error(f"{taken} exists (use --force to replace it)")
    if base_of(ca) == base:
        new.error("--ca names another key than NAME: the fleet's, whose CA signs NAME's")
    try:
        tls = _tls(base, ca)
    except UsageError as e:
        print(f"miro keys: {e}", file=sys.stderr)
        return 1
    except OSError as e:
        print(f"miro keys: cannot write {e.filename or taken}: {e.strerror or e}", file=sys.stderr)
        return 1
    print(f"certificate: {tls.certificate} (signed by the CA of {base_of(ca)})")
    print(f"private key: {tls.private_key}")
    print(f"CA: {tls.ca}")
    print(f"give it to every process of {tls.name} on the Zenoh backbone: --keys {base}")
    return 0
