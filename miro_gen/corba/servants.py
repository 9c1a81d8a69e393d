"""Servants written by hand for the CORBA services miro-gen serves itself (CosNaming,
CosNotification): their requests read and their replies written with the CDR streams, without
generated skeletons (the services' IDL uses `any`, which generated code does not carry).

A `HandServant` subclass names its operations in `_operations`; each is a method of the same
name taking the request's arguments as a `CdrInput` and returning the reply's results as a
`CdrOutput` (None: nothing). `@rpc.nonblocking` works on them as on generated servants: mark
those that never wait (the IIOP server runs them on its connection thread). `_interfaces` lists
every repository id the object is (its interface and those it inherits), for `_is_a`, which
omniORB's `_narrow` asks.

User exceptions are `GiopUserException`s: their members are written where the GIOP reply puts
them, after the repository id (`bodies.user_exception_out` copies what follows it as it is).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, ClassVar

from miro_gen.corba.bodies import body_input
from miro_gen.exceptions import UserException
from miro_gen.runtime import rpc
from miro_gen.runtime.cdrstream import CdrInput, CdrOutput

HEADER = b"\x00\x01\x00\x00"  # the encapsulation header of a little-endian body
EMPTY = HEADER  # a reply without results
OBJECT = "IDL:omg.org/CORBA/Object:1.0"

Operation = Callable[[CdrInput], "CdrOutput | None"]


def results(out: CdrOutput | None) -> bytes:
    """The reply body of an operation's results (laid out from a multiple of 8)."""
    return EMPTY if out is None else HEADER + out.buf


class GiopUserException(UserException):
    """An IDL exception raised by a hand-written servant: its repository id, and its members
    written by `write_members` (nothing by default)."""

    def write_members(self, out: CdrOutput) -> None:
        """Write the members (override it when there are any)."""

    def serialize(self) -> bytes:
        # Laid out as the reply lays it out: after the repository id, from a multiple of 8.
        out = CdrOutput()
        out.string(self._repo_id, "exception id")
        start = len(out.buf)
        self.write_members(out)
        return HEADER + bytes(out.buf[start:])

    def __str__(self) -> str:
        return self._repo_id.rpartition("/")[2].partition(":")[0]


def _dispatcher(name: str) -> rpc.Dispatcher:
    def dispatch(servant: Any, body: bytes, invoker: rpc.Invoker) -> bytes:
        method: Operation = getattr(servant, name)
        return results(method(body_input(body)))

    return dispatch


class HandServant(rpc.Servant):
    """Base of the hand-written servants (see the module's documentation)."""

    _operations: ClassVar[tuple[str, ...]] = ()
    _interfaces: ClassVar[frozenset[str]] = frozenset()

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        names: dict[str, None] = {}
        for klass in reversed(cls.__mro__):
            names.update(dict.fromkeys(getattr(klass, "_operations", ())))
        table = {name: _dispatcher(name) for name in names}
        table["_is_a"] = _is_a
        cls._dispatch = table

    @rpc.nonblocking
    def _is_a(self, inp: CdrInput) -> CdrOutput:
        out = CdrOutput()
        out.boolean(inp.string("repository id") in self._interfaces | {self._repo_id, OBJECT})
        return out


def _is_a(servant: Any, body: bytes, invoker: rpc.Invoker) -> bytes:
    return results(servant._is_a(body_input(body)))
