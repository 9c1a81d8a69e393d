"""The naming table's rules (transport/naming/table.py) and its log of owners
(transport/naming/owners_log.py), without processes: who may bind a name, live or kept, quotas that
give up kept names first, pages that fit a message, and a log that survives damage."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import MiroNaming
import pytest
from loopback import free_port, service_env

from miro_gen.exceptions import NO_RESOURCES
from miro_gen.transport.naming.owners_log import LogError, OwnersLog
from miro_gen.transport.naming.table import ENTRY_OVERHEAD, Holder, Table, entry_size

ME = Holder("uid:1000", "r/exampleA", "run1")
RESTART = Holder("uid:1000", "r/exampleA", "run2")
OTHER_SERVICE = Holder("uid:1000", "r/other", "run3")
STRANGER = Holder("uid:1001", "r/exampleA", "run4")


def entry(name: str, endpoint: str = "tcp://127.0.0.1:1") -> MiroNaming.Entry:
    return MiroNaming.Entry(name, "IDL:Miro/Example:1.0", endpoint, b"k", "")


def bind(table: Table, name: str, who: Holder, take_over: bool = False, mono: float = 0.0) -> str:
    return table.bind(entry(name), who, 3000, take_over, mono, 1000.0 + mono)[1]


def test_who_may_bind_a_live_name() -> None:
    table = Table(quota=10, max_names=10, hold=3600)
    assert bind(table, "r/A", ME) == "bound"
    assert bind(table, "r/A", ME) == "rebound"
    for who, holder in (
        (STRANGER, "another user or host (live)"),
        (OTHER_SERVICE, "r/exampleA, another service of yours"),
        (RESTART, "another run of r/exampleA"),
    ):
        with pytest.raises(MiroNaming.AlreadyBound) as refused:
            bind(table, "r/A", who)
        assert refused.value.holder == holder
    with pytest.raises(MiroNaming.AlreadyBound):
        bind(table, "r/A", STRANGER, take_over=True)
    assert bind(table, "r/A", RESTART, take_over=True) == "taken over"
    assert table.renew(ME, ["r/A"], 3000, 1.0, 1001.0) == ["r/A"]  # the old run lost it
    assert table.renew(RESTART, ["r/A"], 3000, 1.0, 1001.0) == []


def test_a_kept_name_is_its_services_until_freed() -> None:
    table = Table(quota=10, max_names=10, hold=3600)
    bind(table, "r/A", ME)
    lapsed, gone = table.lapse(mono=5.0, now=1005.0)  # the lease (3 s) ended
    assert (lapsed, gone) == (["r/A"], [])
    assert table.live("r/A", 5.0) is None and table.kept("r/A")
    for who in (STRANGER, OTHER_SERVICE):
        with pytest.raises(MiroNaming.AlreadyBound):
            bind(table, "r/A", who, take_over=True, mono=5.0)
    assert not table.unbind("r/A", STRANGER)
    assert bind(table, "r/A", RESTART, mono=5.0) == "taken back"  # no take_over needed
    table.lapse(mono=10.0, now=1010.0)
    assert table.unbind("r/A", OTHER_SERVICE)  # the same user frees it on purpose
    assert bind(table, "r/A", STRANGER, mono=10.0) == "bound"


def test_a_kept_name_goes_when_its_hold_ends() -> None:
    table = Table(quota=10, max_names=10, hold=60)
    bind(table, "r/A", ME)  # seen at 1000
    table.lapse(mono=5.0, now=1005.0)
    assert table.lapse(mono=6.0, now=1059.0) == ([], [])
    assert table.lapse(mono=7.0, now=1061.0) == ([], ["r/A"])
    assert table.get("r/A") is None


def test_quotas_count_per_principal_and_give_up_kept_names_first() -> None:
    table = Table(quota=3, max_names=5, hold=3600)
    for n in range(3):  # made-up services and runs: one principal
        table.bind(entry(f"a/{n}"), Holder("uid:7", f"s{n}", f"r{n}"), 3000, False, 0.0, 1000.0)
    with pytest.raises(NO_RESOURCES, match="already has 3 names"):
        table.bind(entry("a/3"), Holder("uid:7", "s3", "r3"), 3000, False, 0.0, 1000.0)
    bind(table, "b/0", ME)
    bind(table, "b/1", ME)
    with pytest.raises(NO_RESOURCES, match="full"):
        bind(table, "c/0", STRANGER)
    table.lapse(mono=5.0, now=1005.0)  # every lease ended: all kept
    _, _, given_up = table.bind(entry("a/3"), Holder("uid:7", "s3", "r3"), 3000, False, 5.0, 1005.0)
    assert given_up == ["a/0"]  # at its quota: its own oldest kept name
    assert table.count("uid:7") == 3 and len(table) == 5
    _, _, given_up = table.bind(entry("c/0"), STRANGER, 3000, False, 5.0, 1005.0)
    assert given_up == ["a/1"]  # the table full: its oldest kept name, whoever's


def test_pages_fit_a_message() -> None:
    table = Table(quota=100, max_names=100, hold=3600)
    for n in range(50):
        bind(table, f"p/{n:02d}", Holder("uid:1", "s", "r"))
    bind(table, "q/x", ME)
    size = entry_size(entry("p/00")) + ENTRY_OVERHEAD
    entries, more = table.page("p/", "", 500, 10 * size, 0.0)
    assert [e.name for e in entries] == [f"p/{n:02d}" for n in range(10)] and more
    entries, more = table.page("p/", "p/09", 20, 1 << 20, 0.0)
    assert [e.name for e in entries] == [f"p/{n:02d}" for n in range(10, 30)] and more
    entries, more = table.page("p/", "p/45", 20, 1 << 20, 0.0)
    assert [e.name for e in entries] == [f"p/{n:02d}" for n in range(46, 50)] and not more
    assert table.page("p/", "", 500, 1, 0.0)[0][0].name == "p/00"  # one, however small
    assert [e.name for e in table.page("", "", 500, 1 << 20, 100.0)[0]] == []  # all lapsed


def test_the_log_gives_every_name_its_owner_back(tmp_path: Path) -> None:
    path = str(tmp_path / "owners.log")
    table = Table(quota=10, max_names=10, hold=3600)
    log = OwnersLog(path, table)
    log.restore(mono=0.0, lease=3.0)
    for name in ("r/A", "r/B"):
        b, _, _ = table.bind(entry(name), ME, 3000, False, 0.0, 1000.0)
        log.bound(b)
    table.lapse(mono=5.0, now=1005.0)
    log.lapsed("r/B", 1000.0)
    b, _, _ = table.bind(entry("r/C"), ME, 3000, False, 5.0, 1005.0)
    log.bound(b)
    table.unbind("r/C", ME)
    log.freed("r/C")
    with pytest.raises(LogError, match="in use by another naming service"):
        OwnersLog(path, Table(10, 10, 3600))
    log._file.close()  # killed: no clean close
    os.close(log._lock)
    again = Table(quota=10, max_names=10, hold=1e12)
    restored = OwnersLog(path, again).restore(mono=100.0, lease=3.0)
    assert (restored.bindings, restored.kept, restored.skipped) == (1, 1, 0)
    assert again.live("r/A", 100.0) is not None and again.live("r/A", 104.0) is None
    assert again.kept("r/B") and again.get("r/C") is None
    with pytest.raises(MiroNaming.AlreadyBound):
        again.bind(entry("r/A"), STRANGER, 3000, True, 100.0, 2000.0)
    assert again.bind(entry("r/B"), RESTART, 3000, False, 100.0, 2000.0)[1] == "taken back"


def test_a_damaged_log_is_read_as_far_as_it_makes_sense(tmp_path: Path) -> None:
    """A full disk cuts a line; a hand edit breaks one; neither stops the naming service."""
    good = {
        "op": "bind", "name": "r/A", "repo_id": "IDL:x:1.0", "endpoint": "tcp://h:1",
        "key": "6b", "type_hash": "", "principal": "uid:1", "service": "r/a", "run": "1",
        "seen": 1e12, "lease_ms": 3000,
    }  # fmt: skip
    lines = [
        json.dumps({"miro-naming-log": 1}),
        json.dumps(good),
        json.dumps({**good, "name": "bad name//", "run": "2"}),  # not a valid name
        json.dumps({**good, "name": "r/B", "key": "zz"}),  # not hex
        "not json at all",
        json.dumps({"op": "explode", "name": "r/A"}),
        json.dumps({**good, "name": "r/C"})[:40],  # cut
    ]
    path = tmp_path / "owners.log"
    path.write_text("\n".join(lines))
    table = Table(quota=10, max_names=10, hold=3600)
    restored = OwnersLog(str(path), table).restore(mono=0.0, lease=3.0)
    assert (restored.bindings, restored.skipped) == (1, 5)
    assert table.live("r/A", 0.0) is not None and len(table) == 1
    assert path.read_text().splitlines()[0] == json.dumps({"miro-naming-log": 1})  # rewritten


def test_a_file_that_is_no_log_stops_the_naming_service_in_one_line(tmp_path: Path) -> None:
    path = tmp_path / "notes.txt"
    path.write_text("my notes\n")
    done = subprocess.run(
        [sys.executable, "-m", "miro_gen.cli.main", "naming", "--endpoint",
         f"tcp://127.0.0.1:{free_port()}", "--log-file", str(path)],
        capture_output=True, text=True, env=service_env(), timeout=60,
    )  # fmt: skip
    assert done.returncode == 1
    assert done.stderr.strip() == (
        f"miro naming: {path}:1: not a log of owners of a naming service"
    )
    assert path.read_text() == "my notes\n"  # untouched
