"""What the generated stubs' and skeletons' tests share beside their fixtures (conftest.py):
the test IDL, an invoker that counts what it is asked to send, and running one request
through a servant's skeleton."""

from __future__ import annotations

from typing import Any

from miro_gen.exceptions import CompletionStatus
from miro_gen.runtime.cdr import ObjectRef
from miro_gen.runtime.rpc import LocalInvoker, Reply

IDL = "tests/rpc/Rpc.idl"
PACKAGES = ("Rpc", "Rpc__POA")
HEADER = b"\x00\x01\x00\x00"  # CDR little-endian encapsulation

YES, NO, MAYBE = CompletionStatus.YES, CompletionStatus.NO, CompletionStatus.MAYBE


class CountingInvoker(LocalInvoker):
    """A LocalInvoker that counts and records the requests it is asked to send."""

    def __init__(self) -> None:
        super().__init__()
        self.sent: list[tuple[str, bytes, bool]] = []

    def invoke(
        self,
        ref: ObjectRef,
        operation: str,
        body: bytes,
        *,
        oneway: bool = False,
        timeout: float | None = None,
    ) -> Reply | None:
        self.sent.append((operation, bytes(body), oneway))
        return super().invoke(ref, operation, body, oneway=oneway, timeout=timeout)


def reply_of(servant: Any, op: str, body: bytes, inv: Any) -> Reply | BaseException:
    try:
        return servant._invoke(op, body, inv)
    except BaseException as exc:
        return exc
