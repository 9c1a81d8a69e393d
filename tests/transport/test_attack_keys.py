"""Key files and `--insecure` under attack (issue 33): `miro keys new` never writes the secret
through a link planted in its place nor leaves it readable by others; a secret that others may
read is refused, as ssh refuses such a key; `--insecure` says what it opens, in every process
that uses it. Real processes where a user would see the difference."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
from loopback import NamingProcess, run_miro, service_env
from miro_cli import REPO
from zmq.auth.certs import load_certificate

from miro_gen.service.options import UsageError
from miro_gen.transport import sockets


@pytest.fixture(autouse=True)
def no_default_key(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    monkeypatch.delenv("MIRO_KEYS", raising=False)


# What `miro keys new NAME` writes: the CURVE pair and the TLS files (transport.tlsfiles)
SUFFIXES = sorted(
    [".key", ".key_secret", ".ca.pem", ".ca_secret.pem", ".cert.pem", ".cert_secret.pem"]
)


def mode(path: Path) -> int:
    return path.lstat().st_mode & 0o777


def new_key(base: Path, *args: str) -> subprocess.CompletedProcess[str]:
    return run_miro("keys", "new", *args, str(base))


# ---- writing ------------------------------------------------------------------------------------


def test_force_replaces_a_planted_link_and_never_writes_through_it(tmp_path: Path) -> None:
    """An attacker who can write the key's folder plants links to files of the user's, open
    to everyone: `--force` replaces the links with new files, 0600 and 0644, and the files
    the links pointed to are untouched."""
    keys = tmp_path / "keys"
    keys.mkdir()
    victim = tmp_path / "notes.txt"  # a file of the user's that others may read
    victim.write_text("my notes\n")
    victim.chmod(0o644)
    other = tmp_path / "other.txt"
    other.write_text("other\n")
    (keys / "fleet.key_secret").symlink_to(victim)
    (keys / "fleet.key").symlink_to(other)
    (keys / "fleet.cert_secret.pem").symlink_to(victim)  # (the TLS key: the same)

    made = new_key(keys / "fleet", "--force")
    assert made.returncode == 0, made.stderr
    assert victim.read_text() == "my notes\n" and mode(victim) == 0o644
    assert other.read_text() == "other\n"
    secret, public = keys / "fleet.key_secret", keys / "fleet.key"
    assert not secret.is_symlink() and not public.is_symlink()
    assert mode(secret) == 0o600 and mode(public) == 0o644
    assert secret.stat().st_uid == os.getuid()
    pub, sec = load_certificate(secret)
    assert sec is not None and len(sec) == 40
    assert load_certificate(public) == (pub, None)
    assert sorted(p.name for p in keys.iterdir()) == [f"fleet{s}" for s in SUFFIXES]
    tls = keys / "fleet.cert_secret.pem"
    assert (
        not tls.is_symlink() and mode(tls) == 0o600 and mode(keys / "fleet.ca_secret.pem") == 0o600
    )
    assert sockets.read_keys(str(secret)).public == pub  # and it is accepted


def test_force_over_a_world_readable_secret_leaves_a_private_one(tmp_path: Path) -> None:
    """The old key file was 0644 (copied carelessly): the new one is 0600, not the old file
    written over with its old mode."""
    secret = tmp_path / "fleet.key_secret"
    secret.write_text("old\n")
    secret.chmod(0o644)
    made = new_key(tmp_path / "fleet", "--force")
    assert made.returncode == 0, made.stderr
    assert mode(secret) == 0o600


def test_without_force_even_a_dangling_link_is_not_followed(tmp_path: Path) -> None:
    target = tmp_path / "elsewhere" / "stolen"
    target.parent.mkdir()
    (tmp_path / "fleet.key_secret").symlink_to(target)
    made = new_key(tmp_path / "fleet")
    assert made.returncode == 2
    assert (
        made.stderr.strip()
        .splitlines()[-1]
        .endswith(
            "fleet.key_secret exists (use --force to replace it: processes holding the old key "
            "can then no longer connect)"
        )
    )
    assert not target.exists()


def test_the_suffix_may_be_given(tmp_path: Path) -> None:
    made = new_key(tmp_path / "robot.key_secret")
    assert made.returncode == 0, made.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == [f"robot{s}" for s in SUFFIXES]


# ---- reading ------------------------------------------------------------------------------------


@pytest.fixture
def key(tmp_path: Path) -> Path:
    made = new_key(tmp_path / "fleet")
    assert made.returncode == 0, made.stderr
    return tmp_path / "fleet.key_secret"


@pytest.mark.parametrize("bits", [0o644, 0o640, 0o604, 0o620, 0o660])
def test_a_secret_others_may_read_or_change_is_refused(key: Path, bits: int) -> None:
    key.chmod(bits)
    with pytest.raises(UsageError) as refused:
        sockets.policy_for(keys=str(key), insecure=False, max_message_size=None)
    assert str(refused.value) == (
        f"--keys {key}: {key} is open to others (mode {bits:04o}), so the secret key is "
        f"refused, as ssh refuses such a key: make it the owner's only: chmod 600 {key}"
    )
    key.chmod(0o600)
    assert sockets.policy_for(keys=str(key), insecure=False, max_message_size=None).secure


def test_a_secret_of_another_user_is_refused(key: Path) -> None:
    if os.geteuid() != 0:
        pytest.skip("only root can give a file to another user")
    os.chown(key, 65534, -1)
    with pytest.raises(UsageError, match=r"belongs to another user \(uid 65534\)"):
        sockets.read_keys(str(key))


def test_the_default_key_is_checked_too(tmp_path: Path) -> None:
    made = new_key(tmp_path / "home" / ".config" / "miro" / "fleet")
    assert made.returncode == 0, made.stderr
    default = tmp_path / "home" / ".config" / "miro" / "fleet.key_secret"
    default.chmod(0o644)
    with pytest.raises(UsageError, match="is open to others"):
        sockets.policy_for(keys=None, insecure=False, max_message_size=None, binds="0.0.0.0")


def test_processes_refuse_it_with_one_line(key: Path) -> None:
    """A service given the key by MIRO_KEYS, and `miro naming --keys`: one line, status 2,
    before anything is bound."""
    key.chmod(0o644)
    service = subprocess.run(
        [sys.executable, str(REPO / "services" / "exampleA.py"), "--naming", "tcp://127.0.0.1:9"],
        capture_output=True,
        text=True,
        env=service_env(MIRO_KEYS=str(key)),
        timeout=60,
    )
    assert service.returncode == 2, service.stderr
    assert service.stderr.strip().splitlines() == [
        f"exampleA: --keys {key}: {key} is open to others (mode 0644), so the secret key is "
        f"refused, as ssh refuses such a key: make it the owner's only: chmod 600 {key}"
    ]
    naming = run_miro("naming", "--endpoint", "tcp://127.0.0.1:0", "--keys", str(key))
    assert naming.returncode == 2
    assert "Traceback" not in naming.stderr
    assert f"--keys {key}: {key} is open to others (mode 0644)" in naming.stderr


# ---- --insecure ---------------------------------------------------------------------------------


def test_insecure_says_what_it_opens() -> None:
    assert sockets.insecure_exposure(None, None, None) == []  # loopback only: nothing
    assert sockets.insecure_exposure("/k/fleet.key_secret", None, None) == [
        "--insecure: the key /k/fleet.key_secret is not used"
    ]
    (serving,) = sockets.insecure_exposure(None, "0.0.0.0", None)
    assert serving.startswith(
        "--insecure: serving on every interface (0.0.0.0) with neither key nor encryption: "
        "anyone who can reach this machine may call its objects, and subscribe to or publish "
        "its events"
    )
    (talking,) = sockets.insecure_exposure(None, None, "10.0.0.1")
    assert talking.startswith("--insecure: talking to the naming service at 10.0.0.1")


def test_a_server_started_insecure_beyond_loopback_says_so(key: Path) -> None:
    """It used to print nothing. With the fleet's key in MIRO_KEYS and --insecure, it also
    says that the key is not used."""
    naming = NamingProcess()
    try:
        proc = subprocess.Popen(
            [sys.executable, "-u", str(REPO / "services" / "exampleA.py"), "--naming",
             naming.endpoint, "--insecure", "--bind", "0.0.0.0"],
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            env=service_env(MIRO_KEYS=str(key)),
        )  # fmt: skip
        assert proc.stdout is not None
        lines = []
        for line in proc.stdout:
            lines.append(line.rstrip("\n"))
            if "ExampleA is ready" in line:
                break
        proc.terminate()
        proc.wait(30)
    finally:
        naming.stop()
    assert f"[WARNING MIRO] --insecure: the key {key} is not used" in lines
    assert any(
        line.startswith(
            "[WARNING MIRO] --insecure: serving on every interface (0.0.0.0) with neither key "
            "nor encryption: anyone who can reach this machine may call its objects"
        )
        for line in lines
    ), lines
    assert sum("serving on" in line for line in lines) == 1  # once, not per socket
