"""How a process decides its sockets' policy from its options: CURVE beyond loopback, keys,
`--insecure`, `--bind`, `--max-message-size`."""

from __future__ import annotations

import socket
from pathlib import Path

import pytest
from loopback import run_miro

from miro_gen.service.options import UsageError, parse_common_options
from miro_gen.transport import sockets
from miro_gen.transport.addresses import server_addresses


@pytest.fixture
def key(tmp_path: Path) -> str:
    made = run_miro("keys", "new", str(tmp_path / "fleet"))
    assert made.returncode == 0, made.stderr
    return str(tmp_path / "fleet.key_secret")


@pytest.fixture(autouse=True)
def no_default_key(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("HOME", str(tmp_path / "home"))


def policy(**kw: object) -> sockets.SocketPolicy:
    args: dict[str, object] = {"keys": None, "insecure": False, "max_message_size": None}
    args.update(kw)
    return sockets.policy_for(**args)  # type: ignore[arg-type]


def test_loopback_is_plain_and_anything_wider_needs_a_key(key: str) -> None:
    assert not policy(binds="127.0.0.1", talks_to="127.0.0.1").secure
    assert not policy(binds="127.0.0.1", talks_to="0.0.0.0").secure  # reaches this machine
    assert not policy(talks_to=socket.gethostname()).secure  # Debian: 127.0.1.1
    for wide in ({"binds": "0.0.0.0"}, {"binds": "10.1.2.3"}, {"talks_to": "10.1.2.3"}):
        with pytest.raises(UsageError, match=r"--keys FILE .* or --insecure"):
            policy(**wide)
        assert not policy(insecure=True, **wide).secure
        secure = policy(keys=key, **wide)
        assert secure.keys is not None and secure.keys.path == key
    assert policy(keys=key).secure  # asked for on loopback too
    assert policy(keys=key.removesuffix(".key_secret")).secure  # the name alone does


def test_the_default_key_is_used_beyond_loopback(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    home = tmp_path / "home2"
    monkeypatch.setenv("HOME", str(home))
    made = run_miro("keys", "new", str(home / ".config" / "miro" / "fleet"))
    assert made.returncode == 0, made.stderr
    assert policy(binds="0.0.0.0").secure
    assert not policy(binds="127.0.0.1").secure


def test_a_public_key_or_junk_is_not_a_key(key: str, tmp_path: Path) -> None:
    with pytest.raises(UsageError, match="not a secret key file"):
        policy(keys=key.replace(".key_secret", ".key"))
    junk = tmp_path / "junk.key_secret"
    junk.write_text("not a certificate\n")
    with pytest.raises(UsageError, match=r"cannot read a key pair|not a secret key file"):
        policy(keys=str(junk))


def test_common_options_for_security_and_limits() -> None:
    opts, rest = parse_common_options(
        ["--keys", "/k", "--insecure", "--bind=lo", "--max-message-size", "512K", "x"], {}
    )
    assert (opts.keys, opts.insecure, opts.bind, opts.max_message_size) == (
        "/k",
        True,
        "lo",
        512 << 10,
    )
    assert rest == ["x"]
    env, _ = parse_common_options([], {"MIRO_KEYS": "/e", "MIRO_MAX_MESSAGE_SIZE": "2M"})
    assert env.keys == "/e" and env.max_message_size == 2 << 20
    for bad in ("0", "12", "3T", "huge", "4G"):
        with pytest.raises(UsageError, match="--max-message-size takes a size"):
            parse_common_options(["--max-message-size", bad], {})


def test_bind_chooses_one_interface() -> None:
    naming = "tcp://127.0.0.1:2809"
    assert server_addresses(naming, None, "lo").bind == "127.0.0.1"
    assert server_addresses(naming, None, "127.0.0.1").advertise == "127.0.0.1"
    assert server_addresses(naming, None, "*").bind == "0.0.0.0"
    with pytest.raises(UsageError, match="not an address of this machine"):
        server_addresses(naming, None, "192.0.2.77")
    with pytest.raises(UsageError, match="cannot resolve"):
        server_addresses(naming, None, "no-such-interface-or-host.invalid")
