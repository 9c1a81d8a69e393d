"""CosNaming over the naming service's own table (`miro naming --iiop-endpoint`), in one
process over real IIOP connections: the operations Miro's C++ Client and Server and omniORB's
nameclt use, the BindingIterator, NotFound's reasons, and the owners' rules: a CORBA caller is
the user owning its end of the connection, and cannot replace or remove what another owner
holds (tests/corba/test_corba_notify.py drives it with nameclt and C++ peers)."""

from __future__ import annotations

import os
import time
from collections.abc import Iterator

import MiroNaming
import pytest

from miro_gen.corba.bodies import call
from miro_gen.corba.client import IIOPInvoker
from miro_gen.corba.ior import IOR, ref_from_ior
from miro_gen.corba.naming import (
    NAMING_CONTEXT_EXT,
    AlreadyBound,
    NamingContext,
    NotEmpty,
    NotFound,
    NotFoundReason,
)
from miro_gen.corba.server import IIOPServer
from miro_gen.exceptions import NO_IMPLEMENT, NO_PERMISSION
from miro_gen.runtime.cdr import ObjectRef
from miro_gen.runtime.cdrstream import CdrOutput
from miro_gen.transport.naming.cosnaming_door import SERVICE, serve_cosnaming
from miro_gen.transport.naming.service import Registry
from miro_gen.transport.naming.table import Table
from miro_gen.transport.rpc import caller


class Door:
    def __init__(self) -> None:
        self.table = Table(quota=100, max_names=1000, hold=60.0)
        self.registry = Registry(self.table)
        self.invoker = IIOPInvoker(None)
        self.server = IIOPServer(self.invoker)
        self.invoker.server = self.server
        self.names = serve_cosnaming(self.registry, self.server)
        root = ref_from_ior(self.server.ior(b"NameService", NAMING_CONTEXT_EXT))
        self.root = NamingContext(root, self.invoker)
        # Something to bind: the root's own reference will do (any IOR).
        self.thing = root

    def close(self) -> None:
        self.server.close()
        self.invoker.close()


@pytest.fixture
def door() -> Iterator[Door]:
    d = Door()
    try:
        yield d
    finally:
        d.close()


def name(path: str) -> list[tuple[str, str]]:
    return [(p, "") for p in path.split("/")]


def test_miros_client_and_server_calls(door: Door) -> None:
    robot = door.root.bind_new_context(name("robot1"))  # Miro::Client
    with pytest.raises(AlreadyBound):
        door.root.bind_new_context(name("robot1"))  # ... the next one resolves it
    robot = door.root.context(name("robot1"))
    robot.bind(name("Laser"), door.thing)  # Miro::Server::addToNameService
    with pytest.raises(AlreadyBound):
        robot.bind(name("Laser"), door.thing)
    robot.rebind(name("Laser"), door.thing)  # the same owner may
    assert door.root.resolve(name("robot1/Laser")).key == door.thing.key
    entry = door.registry.resolve("robot1/Laser")
    assert entry.endpoint.startswith("IOR:")
    holder = door.table.get("robot1/Laser").holder  # type: ignore[union-attr]
    assert (holder.principal, holder.service) == (f"uid:{os.getuid()}", SERVICE)
    robot.unbind(name("Laser"))  # Miro::Server at its end
    with pytest.raises(NotFound):
        door.root.resolve(name("robot1/Laser"))


def test_listing_follows_the_binding_iterator(door: Door) -> None:
    robot = door.root.bind_new_context(name("robot1"))
    for n in ("A", "B", "C", "D", "E"):
        robot.bind(name(n), door.thing)
    door.root.bind_new_context(name("robot1/sub"))
    found = robot.list(how_many=2)  # two at once, the rest through the iterator
    assert [(b.name[0][0], b.is_context) for b in found] == [
        ("A", False), ("B", False), ("C", False), ("D", False), ("E", False), ("sub", True),
    ]  # fmt: skip
    assert [(b.name, b.is_context) for b in door.root.list()] == [([("robot1", "")], True)]


def test_not_found_says_why(door: Door) -> None:
    robot = door.root.bind_new_context(name("robot1"))
    robot.bind(name("Laser"), door.thing)
    with pytest.raises(NotFound) as e:
        door.root.resolve(name("robot2/Laser"))
    assert e.value.why == NotFoundReason.missing_node
    assert e.value.rest_of_name == name("robot2/Laser")
    with pytest.raises(NotFound) as e:
        door.root.resolve(name("robot1/Laser/deeper"))
    assert e.value.why == NotFoundReason.not_context
    assert e.value.rest_of_name == name("deeper")
    with pytest.raises(NotFound):
        door.root.bind(name("robot3/Gps"), door.thing)  # no such context
    with pytest.raises(NotEmpty):
        robot.destroy()
    with pytest.raises(NO_IMPLEMENT):
        door.root.new_context()


def test_names_of_other_owners_stay_theirs(door: Door) -> None:
    door.registry.keep(MiroNaming.Entry("robot1/EventChannel", "IDL:x:1.0", "tcp://a:1", b"k", ""))
    other = MiroNaming.Entry("robot1/Gps", "IDL:y:1.0", "tcp://b:2", b"k", "")
    with caller.serving(caller.Caller("uid:4242", True)):  # another user's Python service
        door.registry.bind_as(other, MiroNaming.Owner("robot1/gps", "run"), 10_000, False)
    robot = door.root.context(name("robot1"))  # implied by the names below it
    for taken in ("EventChannel", "Gps"):
        with pytest.raises(AlreadyBound):
            robot.bind(name(taken), door.thing)
        with pytest.raises(NO_PERMISSION):
            robot.rebind(name(taken), door.thing)
        with pytest.raises(NO_PERMISSION):
            robot.unbind(name(taken))
    assert door.registry.resolve("robot1/Gps").endpoint == "tcp://b:2"
    # A ZeroMQ entry resolves to miro-gen's profile, whose endpoint a miro-gen client reads.
    ref = door.root.resolve(name("robot1/Gps"))
    assert (ref.endpoint, ref.key) == ("tcp://b:2", b"k")


def test_names_bound_through_cosnaming_outlive_their_lease(door: Door) -> None:
    robot = door.root.bind_new_context(name("robot1"))
    robot.bind(name("Laser"), door.thing)
    binding = door.table.get("robot1/Laser")
    assert binding is not None
    binding.expires = time.monotonic() + 1  # its lease about to end
    door.names.renew()  # what miro naming's timer does, every third of a lease
    assert binding.expires > time.monotonic() + 30


def test_the_ext_operations(door: Door) -> None:
    door.root.bind_new_context(name("robot1"))
    door.root.context(name("robot1")).bind([("Gps", "v2")], door.thing)
    out = CdrOutput()
    out.ulong(2)
    for ident, kind in (("robot1", ""), ("Gps", "v2")):
        out.string(ident)
        out.string(kind)
    _, inp = call(door.invoker, door.root.ref, "to_string", out)
    assert inp.string() == "robot1/Gps.v2"
    out = CdrOutput()
    out.string("robot1/Gps.v2")
    _, inp = call(door.invoker, door.root.ref, "resolve_str", out)
    assert ref_from_ior(IOR.read(inp)).key == door.thing.key
    out = CdrOutput()
    out.string(":127.0.0.1:2809")
    out.string("robot1/Gps.v2")
    _, inp = call(door.invoker, door.root.ref, "to_url", out)
    assert inp.string() == "corbaname::127.0.0.1:2809#robot1/Gps.v2"
    assert isinstance(door.thing, ObjectRef)


def test_no_request_body_makes_the_naming_service_fail(door: Door) -> None:
    """Random bodies for every CosNaming operation: refused, never UNKNOWN (a defect)."""
    import random

    from miro_gen.exceptions import UNKNOWN, SystemException

    robot = door.root.bind_new_context(name("robot1"))
    robot.bind(name("Laser"), door.thing)
    rng = random.Random(27)
    servant = door.server._servant(b"NameService")
    assert servant is not None
    for op in sorted(servant._dispatch):
        if op == "destroy":
            continue
        for _ in range(30):
            out = CdrOutput()
            out.raw(rng.randbytes(rng.choice((0, 3, 8, 40, 200))))
            try:
                call(door.invoker, door.root.ref, op, out)
            except UNKNOWN as e:
                pytest.fail(f"{op}: {e}")
            except SystemException:
                pass
    assert door.root.resolve(name("robot1/Laser")).key == door.thing.key


def test_miro_naming_refuses_iiop_beyond_loopback_in_one_line() -> None:
    import subprocess
    import sys

    from loopback import free_port, service_env

    base = [sys.executable, "-m", "miro_gen.cli.main", "naming", "--endpoint",
            f"tcp://127.0.0.1:{free_port()}", "--log-file", "none"]  # fmt: skip
    done = subprocess.run(
        [*base, "--iiop-endpoint", f"0.0.0.0:{free_port()}"],
        capture_output=True, text=True, timeout=60, env=service_env(),
    )  # fmt: skip
    assert done.returncode == 2 and "give --insecure" in done.stderr, done.stderr
    assert "Traceback" not in done.stderr
    done = subprocess.run(
        [*base, "--iiop-endpoint", "no-such-host.invalid:2810"],
        capture_output=True, text=True, timeout=60, env=service_env(),
    )  # fmt: skip
    assert done.returncode == 1 and "Traceback" not in done.stderr, done.stderr
    assert done.stderr.count("\n") == 1 and "cannot listen for IIOP" in done.stderr
