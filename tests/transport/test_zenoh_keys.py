"""The Zenoh backbone's keys on one machine (issue 26): `miro keys new` makes the TLS files
(a CA and a certificate, or a robot's certificate of a fleet's CA); a wrong, missing or
exposed key file is one line at start-up; loopback is open without keys, and a router given a
key lets in only sessions holding a certificate of its CA, even on loopback. Real `miro
naming --zenoh` processes and real sessions; across hosts: test_zenoh_security.py."""

from __future__ import annotations

import shutil
from collections.abc import Iterator
from pathlib import Path

import pytest
from loopback import NamingProcess, run_miro

pytest.importorskip("zenoh")
pytest.importorskip("cryptography")

from miro_gen.transport.tlsfiles import read_tls
from miro_gen.transport.usage import UsageError
from miro_gen.transport.zenoh.security import tls_for


@pytest.fixture(autouse=True)
def no_default_key(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    monkeypatch.delenv("MIRO_KEYS", raising=False)


@pytest.fixture(scope="module")
def keys(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A fleet's key, a robot's certificate of the fleet's CA, and another fleet's key."""
    folder = tmp_path_factory.mktemp("keys")
    for args in (["fleet"], ["robot1", "--ca", str(folder / "fleet")], ["other"]):
        made = run_miro("keys", "new", str(folder / args[0]), *args[1:])
        assert made.returncode == 0, made.stderr
        if len(args) > 1:
            assert made.stdout.startswith(f"certificate: {folder / 'robot1.cert.pem'}")
    return folder


def one_line(done: object) -> str:
    """The last line a command wrote to stderr (argparse puts its usage before)."""
    return str(getattr(done, "stderr", "")).strip().splitlines()[-1]


def test_a_robots_certificate_is_of_the_fleets_ca(keys: Path) -> None:
    robot = read_tls(str(keys / "robot1"))
    assert robot.name == "robot1"
    assert (keys / "robot1.ca.pem").read_bytes() == (keys / "fleet.ca.pem").read_bytes()
    assert not (keys / "robot1.ca_secret.pem").exists()  # only the fleet makes certificates
    assert (keys / "robot1.cert_secret.pem").stat().st_mode & 0o777 == 0o600
    assert read_tls(str(keys / "fleet.key_secret")).name == "fleet"  # the CURVE file names it


def test_wrong_missing_or_exposed_key_files_are_one_line(keys: Path, tmp_path: Path) -> None:
    with pytest.raises(UsageError, match=r"no TLS certificate .*nothing\.cert\.pem beside it"):
        read_tls(str(tmp_path / "nothing"))
    for suffix in (".key_secret", ".key"):  # a CURVE key made before TLS
        shutil.copy(keys / f"fleet{suffix}", tmp_path / f"old{suffix}")
    with pytest.raises(UsageError, match=r"a key made before TLS: .*miro keys new --force"):
        read_tls(str(tmp_path / "old.key_secret"))
    mixed = tmp_path / "mixed"  # robot1's certificate and key, another fleet's CA
    for suffix in (".cert.pem", ".cert_secret.pem"):
        shutil.copy(keys / f"robot1{suffix}", tmp_path / f"mixed{suffix}")
    shutil.copy(keys / "other.ca.pem", tmp_path / "mixed.ca.pem")
    with pytest.raises(UsageError, match=r"was not signed by the CA in .*mixed\.ca\.pem"):
        read_tls(str(mixed))
    shutil.copy(keys / "other.cert_secret.pem", tmp_path / "mixed.cert_secret.pem")
    shutil.copy(keys / "other.ca.pem", tmp_path / "mixed.ca.pem")
    with pytest.raises(UsageError, match=r"mixed\.cert_secret\.pem is not the key of"):
        read_tls(str(mixed))
    (tmp_path / "mixed.cert_secret.pem").write_text("-----BEGIN PRIVATE KEY-----\nxx\n")
    with pytest.raises(UsageError, match=r"is not a PEM private key"):
        read_tls(str(mixed))
    shutil.copy(keys / "robot1.cert_secret.pem", tmp_path / "mixed.cert_secret.pem")
    (tmp_path / "mixed.cert_secret.pem").chmod(0o644)
    with pytest.raises(UsageError, match=r"is open to others \(mode 0644\)"):
        read_tls(str(mixed))


def test_beyond_loopback_a_key_or_insecure(keys: Path) -> None:
    with pytest.raises(UsageError, match=r"talks to 10\.0\.0\.1, beyond .*--keys.*--insecure"):
        tls_for(keys=None, insecure=False, talks_to="10.0.0.1")
    assert tls_for(keys=None, insecure=True, talks_to="10.0.0.1") is None
    assert tls_for(keys=None, insecure=False, talks_to="127.0.0.1") is None  # loopback: open
    assert tls_for(keys=str(keys / "robot1"), insecure=False, talks_to="127.0.0.1") is not None
    refused = run_miro("naming", "--zenoh", "--endpoint", "tcp://0.0.0.0:1", "--log-file", "none")
    assert refused.returncode == 2
    assert one_line(refused).startswith(
        "miro naming: error: this process listens on 0.0.0.0, beyond this machine, over Zenoh: "
        "give the robot's or fleet's key with --keys FILE"
    )
    assert "Traceback" not in refused.stderr


@pytest.fixture
def keyed_router(keys: Path) -> Iterator[NamingProcess]:
    router = NamingProcess(options=("--zenoh", "--keys", str(keys / "fleet")))
    yield router
    router.stop()


def test_loopback_is_open_without_keys() -> None:
    router = NamingProcess(options=("--zenoh",))
    try:
        listed = run_miro("nslist", "--transport", "zenoh", "--naming", router.endpoint)
        assert listed.returncode == 0, listed.stderr
        assert listed.stdout.strip() == "(no names bound)"
    finally:
        router.stop()


def test_a_keyed_router_lets_in_only_its_cas_certificates(
    keys: Path, keyed_router: NamingProcess
) -> None:
    """Even on loopback: a key given is used, as CURVE is (no key, another fleet's key: no
    entry, one line and status 1)."""
    nslist = ("nslist", "--transport", "zenoh", "--naming", keyed_router.endpoint)
    for key in ("robot1", "fleet.key_secret"):
        listed = run_miro(*nslist, "--keys", str(keys / key))
        assert listed.returncode == 0, listed.stderr
    for refused in (run_miro(*nslist), run_miro(*nslist, "--keys", str(keys / "other"))):
        assert refused.returncode == 1
        assert one_line(refused).startswith("miro nslist: cannot reach the Zenoh router at ")
        assert "Traceback" not in refused.stderr
    assert "give --keys FILE" in one_line(run_miro(*nslist))
