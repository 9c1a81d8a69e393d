"""The robot's objects as Foxglove services: one service per operation (`NAME/OPERATION`,
NAME the object's name in the naming service), called through the object's stub as `miro call`
calls it.

Requests and responses are JSON (the encoding Foxglove's Service Call panel writes): the
request is a mapping of the operation's in and inout parameters by name, the response a
mapping of what it returns (`return`, then out and inout parameters by name). A user exception
the operation raises, a system exception (the object is gone, the call timed out) and a request
that does not fit come back to the client as a failed call with the reason, never as a
response.
"""

from __future__ import annotations

import json
import threading
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import foxglove
import MiroNaming

from miro_gen.exceptions import SystemException, UserException
from miro_gen.live.remote import LiveError, Robot
from miro_gen.live.show import Signature, signatures
from miro_gen.live.values import from_plain, hints, to_plain
from miro_gen.log import logger

_log = logger("MIRO")
ENCODING = "json"


class CallFailed(Exception):
    """A call a client made that did not return: said to the client as the call's failure."""


@dataclass(frozen=True)
class _Operation:
    service: str
    object_name: str
    repo_id: str
    endpoint: str
    signature: Signature


def _py_name(stub: Any, name: str) -> str:
    return name if hasattr(stub, name) else f"_{name}"


class Services:
    """Foxglove services for the objects bound in the naming service (`update` from the
    discovery thread); their handlers run on the Foxglove server's threads."""

    def __init__(self, robot: Robot, server: Callable[[], Any]) -> None:
        self.robot = robot
        self.server = server  # the foxglove WebSocketServer, once started
        self._lock = threading.Lock()
        self._objects: dict[tuple[str, str], list[str]] = {}  # (name, endpoint) -> services
        self._stubs: dict[tuple[str, str], Any] = {}

    def update(self, entries: list[MiroNaming.Entry]) -> None:
        """Add the services of objects new in `entries`, remove those of objects gone."""
        current = {(e.name, e.endpoint): e for e in entries}
        with self._lock:
            gone = [k for k in self._objects if k not in current]
        for key in gone:
            with self._lock:
                names = self._objects.pop(key, [])
                self._stubs.pop(key, None)
            if names:
                self.server().remove_services(names)
        for key, entry in sorted(current.items()):
            with self._lock:
                if key in self._objects:
                    continue
            try:
                stub, compiled = self.robot.stub(entry)
            except LiveError as e:
                _log.debug("foxglove: no services for %s: %s", entry.name, e)
                with self._lock:
                    self._objects[key] = []  # not asked again while it stays bound
                continue
            services = []
            for sig in signatures(compiled, entry.repo_id):
                if sig.oneway:
                    continue
                op = _Operation(
                    f"{entry.name}/{sig.name}", entry.name, entry.repo_id, entry.endpoint, sig
                )
                services.append(self._service(op, stub))
            with self._lock:
                self._objects[key] = [s.name for s in services]
                self._stubs[key] = stub
            if services:
                self.server().add_services(services)
                _log.info("foxglove: %d services of %s", len(services), entry.name)

    def names(self) -> list[str]:
        with self._lock:
            return sorted(n for names in self._objects.values() for n in names)

    def _service(self, op: _Operation, stub: Any) -> foxglove.Service:
        def handle(request: foxglove.ServiceRequest) -> bytes:
            try:
                return call(op, stub, request.payload)
            except CallFailed:
                raise
            except Exception as e:  # a defect here is the client's failed call, not a crash
                _log.error("foxglove: %s: %s: %s", op.service, type(e).__name__, e)
                raise CallFailed(f"{type(e).__name__}: {e}") from None

        schema = foxglove.ServiceSchema(op.signature.text())
        return foxglove.Service(op.service, schema=schema, handler=handle)


def call(op: _Operation, stub: Any, payload: bytes) -> bytes:
    """Call `op` with the JSON request `payload`; its JSON response."""
    sig = op.signature
    try:
        given = json.loads(payload.decode() or "{}") if payload.strip() else {}
    except (UnicodeDecodeError, json.JSONDecodeError) as e:
        raise CallFailed(f"the request is not JSON: {e}") from None
    names = [p["name"] for p in sig.inputs]
    if not isinstance(given, dict):
        raise CallFailed(f"the request is a JSON object of {', '.join(names) or 'nothing'}")
    unknown = sorted(set(given) - set(names))
    missing = [n for n in names if n not in given]
    if unknown or missing:
        raise CallFailed(
            f"{sig.name} takes {{{', '.join(names)}}}"
            + (f": no parameter {unknown[0]}" if unknown else f": {missing[0]} missing")
        )
    method = getattr(stub, _py_name(stub, sig.name))
    types = hints(method)
    try:
        args = [from_plain(types.get(n if n in types else f"_{n}"), given[n], n) for n in names]
    except ValueError as e:
        raise CallFailed(f"{sig.name}: {e}") from None
    try:
        result = method(*args)
    except UserException as e:
        raised = to_plain(e)
        raise CallFailed(
            f"{op.object_name} {sig.name} raised {e._repo_id}"
            + (f": {json.dumps(raised)}" if raised else "")
        ) from None
    except SystemException as e:
        raise CallFailed(f"{op.object_name} {sig.name}: {e}") from None
    results = sig.results
    values = [result] if len(results) == 1 else list(result) if results else []
    return json.dumps(
        {n: to_plain(v) for n, v in zip(results, values, strict=True)}, default=str
    ).encode()
