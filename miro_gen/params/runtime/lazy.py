"""`secrets` loaded without OpenSSL, before pydantic imports it.

`pydantic.types` imports `secrets` for `compare_digest` alone (the equality of its Secret
types), and `secrets` imports `hmac`, which loads `_hashlib` and OpenSSL's libcrypto: 3.4 MB
of every service's resident memory and milliseconds of its start, for a comparison no
parameter class makes. `load_secrets` imports `secrets` with `_hashlib` hidden, which `hmac`
and `hashlib` are written to do without (builds without OpenSSL): `secrets.compare_digest` is
then the standard library's other constant-time comparison (`_operator._compare_digest`), and
everything else in `secrets` uses neither module. The two are then dropped from `sys.modules`,
so that whoever imports `hashlib` or `hmac` later gets them whole, with OpenSSL.
"""

from __future__ import annotations

import _imp
import sys

_HIDDEN = "_hashlib"
_WITHOUT = ("hashlib", "hmac")  # the modules that load _hashlib when they can


def load_secrets() -> None:
    """Import `secrets` without OpenSSL; nothing if it or OpenSSL's module is loaded already
    (there is nothing left to save). Under the interpreter's import lock, so that no other
    thread imports `hashlib` while `_hashlib` is hidden."""
    _imp.acquire_lock()
    try:
        if (
            "secrets" in sys.modules
            or _HIDDEN in sys.modules
            or any(name in sys.modules for name in _WITHOUT)
        ):
            return
        sys.modules[_HIDDEN] = None  # type: ignore[assignment]  # `import _hashlib` fails
        try:
            import secrets  # noqa: F401
        finally:
            del sys.modules[_HIDDEN]
            for name in _WITHOUT:
                sys.modules.pop(name, None)
    finally:
        _imp.release_lock()
