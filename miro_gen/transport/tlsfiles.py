"""TLS files of a robot or fleet for the Zenoh backbone's TLS (`miro keys new`,
docs/SECURITY.md): what CURVE's key pair is to ZeroMQ, in the form Zenoh's TLS links take.

Beside a key `NAME` (`NAME.key_secret`, the CURVE pair) live, as PEM:

    NAME.ca.pem            the certificate authority (CA) of the fleet: whom it trusts
    NAME.ca_secret.pem     its private key (0600): only for making more certificates
                           (`miro keys new OTHER --ca NAME`); keep it at the base
    NAME.cert.pem          this key's certificate (common name NAME), signed by the CA
    NAME.cert_secret.pem   its private key (0600)

Every session presents its certificate and accepts only peers whose certificate the CA
signed (mutual TLS), so holding `NAME.cert_secret.pem` is what "one of ours" means, as
holding the CURVE secret is on ZeroMQ. Keys are ECDSA P-256, which Zenoh's TLS (rustls)
takes; certificates are valid for 20 years (CURVE keys do not expire; make new ones to
revoke). Written as keyfiles writes keys (exclusively, 0600, renamed into place) and read
only when nobody else may read the secret, as ssh does. `cryptography` makes and checks them
(the `zenoh` extra); the checks at start-up turn a wrong or missing file into one line
instead of a refused link later.
"""

from __future__ import annotations

import datetime
import os
import re
from dataclasses import dataclass
from typing import Any

from miro_gen.transport.keyfiles import KEY_SUFFIX, exposure, install
from miro_gen.transport.usage import UsageError

CA_SUFFIX = ".ca.pem"
CA_SECRET_SUFFIX = ".ca_secret.pem"
CERT_SUFFIX = ".cert.pem"
CERT_SECRET_SUFFIX = ".cert_secret.pem"
VALID_DAYS = 20 * 365
_SUFFIXES = (KEY_SUFFIX, CERT_SECRET_SUFFIX, CERT_SUFFIX, CA_SECRET_SUFFIX, CA_SUFFIX)


@dataclass(frozen=True)
class TlsFiles:
    """The files a Zenoh session's TLS takes, checked: they belong together."""

    ca: str  # the CA certificate: peers must be signed by it
    certificate: str  # this process's certificate, which the CA signed
    private_key: str  # its private key
    name: str  # the certificate's common name (the key's NAME)


def base_of(keys: str) -> str:
    """The key's NAME, from any of its files' paths (or NAME itself)."""
    full = os.path.expanduser(keys)
    for suffix in _SUFFIXES:
        if full.endswith(suffix):
            return full.removesuffix(suffix)
    return full


def has_tls(keys: str) -> bool:
    """Whether the key `keys` has TLS files (its certificate) beside it."""
    return os.path.exists(base_of(keys) + CERT_SUFFIX)


def tls_available() -> bool:
    """Whether the cryptography package, which makes and checks TLS files, is installed."""
    try:
        import cryptography.x509  # noqa: F401  (a dependency of the zenoh extra)
    except ImportError:
        return False
    return True


def _crypto() -> None:
    if not tls_available():
        raise UsageError(
            "TLS keys for the Zenoh backbone need the cryptography package: "
            "pip install 'miro-gen[zenoh]'"
        )


def _dns_name(name: str) -> str:
    """A DNS name made of `name` (certificates name their subject so; nobody checks it)."""
    return re.sub(r"[^a-z0-9-]+", "-", name.lower()).strip("-") or "miro"


def write_tls(base: str, *, ca_base: str | None = None, replace: bool = False) -> TlsFiles:
    """Make `base`'s certificate and private key, signed by a new CA written beside them, or
    by the CA of the key `ca_base` (whose CA certificate is copied beside them). FileExistsError
    when the private key's place is taken and not `replace`; UsageError when `ca_base` has no
    usable CA; OSError when a file cannot be written."""
    _crypto()
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes, serialization
    from cryptography.hazmat.primitives.asymmetric import ec
    from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

    secret_path = base + CERT_SECRET_SUFFIX
    if not replace and os.path.lexists(secret_path):
        raise FileExistsError(secret_path)
    name = os.path.basename(base)
    now = datetime.datetime.now(datetime.UTC)
    since, until = now - datetime.timedelta(hours=1), now + datetime.timedelta(days=VALID_DAYS)
    files: list[tuple[str, str, int]] = []
    if ca_base is None:
        ca_key = ec.generate_private_key(ec.SECP256R1())
        ca_name = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, f"miro CA {name}")])
        usage = dict.fromkeys(
            ("content_commitment", "key_encipherment", "data_encipherment", "key_agreement"),
            False,
        )
        ca_cert = (
            x509.CertificateBuilder()
            .subject_name(ca_name)
            .issuer_name(ca_name)
            .public_key(ca_key.public_key())
            .serial_number(x509.random_serial_number())
            .not_valid_before(since)
            .not_valid_after(until)
            .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
            .add_extension(
                x509.KeyUsage(
                    digital_signature=True,
                    key_cert_sign=True,
                    crl_sign=True,
                    encipher_only=False,
                    decipher_only=False,
                    **usage,
                ),
                critical=True,
            )
            .add_extension(
                x509.SubjectKeyIdentifier.from_public_key(ca_key.public_key()), critical=False
            )
            .sign(ca_key, hashes.SHA256())
        )
        files.append((base + CA_SECRET_SUFFIX, _private_pem(ca_key), 0o600))
    else:
        ca_cert, ca_key = _read_ca(ca_base)
    key = ec.generate_private_key(ec.SECP256R1())
    cert = (
        x509.CertificateBuilder()
        .subject_name(x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, name)]))
        .issuer_name(ca_cert.subject)
        .public_key(key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(since)
        .not_valid_after(until)
        .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
        .add_extension(x509.SubjectAlternativeName([x509.DNSName(_dns_name(name))]), False)
        .add_extension(
            x509.ExtendedKeyUsage(
                [ExtendedKeyUsageOID.SERVER_AUTH, ExtendedKeyUsageOID.CLIENT_AUTH]
            ),
            critical=False,
        )
        .add_extension(
            x509.AuthorityKeyIdentifier.from_issuer_public_key(ca_key.public_key()), False
        )
        .sign(ca_key, hashes.SHA256())
    )
    pem = serialization.Encoding.PEM
    files += [
        (base + CA_SUFFIX, ca_cert.public_bytes(pem).decode(), 0o644),
        (base + CERT_SUFFIX, cert.public_bytes(pem).decode(), 0o644),
        (secret_path, _private_pem(key), 0o600),
    ]
    install(files)
    return TlsFiles(base + CA_SUFFIX, base + CERT_SUFFIX, secret_path, name)


def _private_pem(key: Any) -> str:
    from cryptography.hazmat.primitives import serialization

    return key.private_bytes(  # type: ignore[no-any-return]
        serialization.Encoding.PEM,
        serialization.PrivateFormat.PKCS8,
        serialization.NoEncryption(),
    ).decode()


def _read_ca(ca_base: str) -> tuple[Any, Any]:
    """The CA certificate and private key of the key `ca_base`; UsageError, one line."""
    base = base_of(ca_base)
    cert = _load(f"--ca {ca_base}", base + CA_SUFFIX, "certificate")
    secret = base + CA_SECRET_SUFFIX
    problem = exposure(secret)
    if problem:
        if not os.path.exists(secret):
            problem = (
                f"no CA private key ({secret}): certificates are made where the fleet's CA was "
                "made (`miro keys new NAME`)"
            )
        raise UsageError(f"--ca {ca_base}: {problem}")
    key = _load(f"--ca {ca_base}", secret, "private key")
    if key.public_key().public_numbers() != cert.public_key().public_numbers():
        raise UsageError(f"--ca {ca_base}: {secret} is not the key of {base + CA_SUFFIX}")
    return cert, key


def _load(option: str, path: str, what: str) -> Any:
    """The PEM certificate or private key in `path`; UsageError naming `option`, one line."""
    from cryptography import x509
    from cryptography.hazmat.primitives import serialization

    try:
        with open(path, "rb") as f:
            data = f.read(1 << 20)
    except OSError as e:
        raise UsageError(f"{option}: cannot read {path}: {e.strerror or e}") from None
    try:
        if what == "certificate":
            return x509.load_pem_x509_certificate(data)
        return serialization.load_pem_private_key(data, password=None)
    except (ValueError, TypeError) as e:
        reason = str(e).splitlines()[0] if str(e) else type(e).__name__
        raise UsageError(f"{option}: {path} is not a PEM {what} ({reason})") from None


def read_tls(keys: str, option: str = "--keys") -> TlsFiles:
    """The TLS files of the key `keys` (NAME, or any of its files), checked: they exist, the
    private key is its owner's only, it is the certificate's key, and the CA signed the
    certificate and is valid now. UsageError, one line, naming `option`, otherwise."""
    _crypto()
    from cryptography import x509
    from cryptography.exceptions import InvalidSignature

    base = os.path.abspath(base_of(keys))  # (Zenoh reads them from its own threads)
    where = f"{option} {keys}"
    ca_path, cert_path, secret_path = (
        base + CA_SUFFIX,
        base + CERT_SUFFIX,
        base + CERT_SECRET_SUFFIX,
    )
    if not os.path.exists(cert_path):
        older = " (a key made before TLS: make it again with `miro keys new --force`)"
        raise UsageError(
            f"{where}: no TLS certificate {cert_path} beside it, which the Zenoh backbone needs "
            f"(`miro keys new` makes it){older if os.path.exists(base + KEY_SUFFIX) else ''}"
        )
    problem = exposure(secret_path)
    if problem:
        raise UsageError(f"{where}: {problem}")
    cert = _load(where, cert_path, "certificate")
    key = _load(where, secret_path, "private key")
    ca = _load(where, ca_path, "certificate")
    if key.public_key().public_numbers() != cert.public_key().public_numbers():
        raise UsageError(f"{where}: {secret_path} is not the key of {cert_path}")
    try:
        cert.verify_directly_issued_by(ca)
    except (ValueError, TypeError, InvalidSignature):
        raise UsageError(
            f"{where}: {cert_path} was not signed by the CA in {ca_path} (a certificate of "
            "another fleet? make it with `miro keys new NAME --ca FLEET`)"
        ) from None
    now = datetime.datetime.now(datetime.UTC)
    for path, c in ((cert_path, cert), (ca_path, ca)):
        if not c.not_valid_before_utc <= now <= c.not_valid_after_utc:
            raise UsageError(
                f"{where}: {path} is valid from {c.not_valid_before_utc:%Y-%m-%d} to "
                f"{c.not_valid_after_utc:%Y-%m-%d}, not now: make a new key"
            )
    names = cert.subject.get_attributes_for_oid(x509.oid.NameOID.COMMON_NAME)
    name = str(names[0].value) if names else os.path.basename(base)
    return TlsFiles(ca_path, cert_path, secret_path, name)
