"""Key files: a robot's or fleet's CURVE key pair in ZeroMQ's certificate format (`miro keys
new`, docs/SECURITY.md), written so that the secret is never readable by anyone else, and read
only when nobody else can read it.

Writing: each file is first written as a new file of its own beside its place, created with
`O_EXCL | O_NOFOLLOW` (so neither a file nor a link planted there is ever opened) and mode 0600
(0644 for the public key), then renamed into place: a rename replaces a link, it never writes
through it, and the old key stays whole until the new one is complete.

Reading: as ssh does with its private keys, a secret that others may read or change (any
permission for the group or others), or that belongs to another user, is refused.
"""

from __future__ import annotations

import contextlib
import os

from miro_gen.transport.usage import UsageError

KEY_SUFFIX = ".key_secret"
PUBLIC_SUFFIX = ".key"
DEFAULT_KEY = os.path.join("~", ".config", "miro", "fleet" + KEY_SUFFIX)
_NEW = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0) | os.O_CLOEXEC


def certificate(public: bytes, secret: bytes | None) -> str:
    """The text of a ZeroMQ certificate (ZPL): the public key, and the secret one if given
    (zmq.auth.load_certificate reads it)."""
    import datetime  # here: a service that only reads keys starts without it

    what = "Secret" if secret is not None else "Public"
    lines = [
        f"#   ZeroMQ CURVE {what} Certificate, made by miro keys new on "
        f"{datetime.datetime.now().isoformat(timespec='seconds')}",
    ]
    if secret is not None:
        lines.append("#   Keep it readable by its owner only (mode 0600): others are refused.")
    lines += ["", "metadata", "curve", f'    public-key = "{public.decode()}"']
    if secret is not None:
        lines.append(f'    secret-key = "{secret.decode()}"')
    return "\n".join(lines) + "\n"


def _write_new(path: str, text: str, mode: int) -> str:
    """Write `text` to a new file beside `path` (see the module's docstring); its name."""
    folder, name = os.path.split(path)
    temporary = os.path.join(folder, f".{name}.{os.urandom(8).hex()}.new")
    fd = os.open(temporary, _NEW, 0o600)
    try:
        os.fchmod(fd, mode)  # exactly: the umask only takes away
        os.write(fd, text.encode())
        os.fsync(fd)
    except BaseException:
        os.close(fd)
        os.unlink(temporary)
        raise
    os.close(fd)
    return temporary


def write_key_pair(base: str, *, replace: bool = False) -> tuple[str, str]:
    """Make a new key pair and write it to `base`.key_secret (mode 0600) and `base`.key (0644);
    their paths (public, secret). FileExistsError when the secret's place is taken (by a file
    or a link, even a dangling one) and not `replace`; OSError when it cannot be written."""
    import zmq

    secret_path, public_path = base + KEY_SUFFIX, base + PUBLIC_SUFFIX
    if not replace and os.path.lexists(secret_path):
        raise FileExistsError(secret_path)
    public, secret = zmq.curve_keypair()
    install(
        [
            (public_path, certificate(public, None), 0o644),
            (secret_path, certificate(public, secret), 0o600),
        ]
    )
    return public_path, secret_path


def install(files: list[tuple[str, str, int]]) -> None:
    """Write each (path, text, mode) as a new file beside its place, then rename them all into
    place (see the module's docstring): none is renamed unless all were written."""
    folders = {os.path.dirname(os.path.abspath(path)) for path, _, _ in files}
    for folder in sorted(folders):
        os.makedirs(folder, mode=0o700, exist_ok=True)
    written: list[str] = []
    try:
        for path, text, mode in files:
            written.append(_write_new(path, text, mode))
        for (path, _, _), temporary in zip(files, written, strict=True):
            os.replace(temporary, path)
    finally:
        for temporary in written:
            with contextlib.suppress(FileNotFoundError):
                os.unlink(temporary)
    for folder in sorted(folders):
        with contextlib.suppress(OSError):  # the renames survive a power cut
            fd = os.open(folder, os.O_RDONLY)
            try:
                os.fsync(fd)
            finally:
                os.close(fd)


def read_key_pair(path: str) -> tuple[str, bytes, bytes]:
    """(the file's path, public key, secret key) of the secret key file `path` (`NAME` alone is
    accepted for `NAME.key_secret`); UsageError, one line, when it is not one, or when others
    may read it."""
    from zmq.auth.certs import load_certificate

    full = os.path.expanduser(path)
    if not full.endswith(KEY_SUFFIX) and not os.path.exists(full):
        full += KEY_SUFFIX
    try:
        public, secret = load_certificate(full)
    except (OSError, ValueError) as e:
        raise UsageError(f"--keys {path}: cannot read a key pair: {e}") from None
    if secret is None or len(public) != 40 or len(secret) != 40:
        raise UsageError(
            f"--keys {path}: not a secret key file (make one with `miro keys new`; the "
            f"{KEY_SUFFIX} file holds the secret)"
        )
    problem = exposure(full)
    if problem:
        raise UsageError(f"--keys {path}: {problem}")
    return full, public, secret


def exposure(full: str) -> str:
    """Why others may read or change the secret key file `full` ('' when they may not)."""
    try:
        st = os.stat(full)
    except OSError as e:
        return f"cannot read it: {e.strerror or e}"
    if not hasattr(os, "getuid"):
        return ""
    if st.st_mode & 0o077:
        return (
            f"{full} is open to others (mode {st.st_mode & 0o777:04o}), so the secret key is "
            f"refused, as ssh refuses such a key: make it the owner's only: chmod 600 {full}"
        )
    if st.st_uid not in (os.getuid(), 0):
        return (
            f"{full} belongs to another user (uid {st.st_uid}), who can read the secret key: "
            "refused; give each user a copy of their own"
        )
    return ""
