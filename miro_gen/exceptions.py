"""Exceptions of remote calls, named and shaped as CORBA's, which Miro users know.

`UserException` is the base of every exception declared in IDL (`exception ETimeOut {...};`).
`SystemException` and its subclasses report what went wrong in the middleware itself, each with
`completed`: whether the operation ran (`YES`), did not run (`NO`), or may have run (`MAYBE`).
"""

from __future__ import annotations

import enum
from typing import ClassVar


class CompletionStatus(enum.IntEnum):
    """Whether the remote operation had completed when a system exception happened."""

    YES = 0
    NO = 1
    MAYBE = 2


class UserException(Exception):
    """Base of the exceptions declared in IDL; generated subclasses carry the IDL fields."""

    _repo_id: ClassVar[str] = "IDL:omg.org/CORBA/UserException:1.0"


class SystemException(Exception):
    """A failure of the middleware, not of the servant's code."""

    _repo_id: ClassVar[str] = "IDL:omg.org/CORBA/SystemException:1.0"

    def __init__(
        self,
        message: str = "",
        minor: int = 0,
        completed: CompletionStatus = CompletionStatus.NO,
    ) -> None:
        super().__init__(message)
        self.message = message
        self.minor = minor
        self.completed = CompletionStatus(completed)

    def __str__(self) -> str:
        name = type(self).__name__
        done = {0: "yes", 1: "no", 2: "maybe"}[int(self.completed)]
        text = f": {self.message}" if self.message else ""
        return f"{name}{text} (completed: {done})"

    def __repr__(self) -> str:
        return (
            f"{type(self).__name__}({self.message!r}, minor={self.minor}, "
            f"completed=CompletionStatus.{self.completed.name})"
        )


class TRANSIENT(SystemException):
    """The server could not be reached (it may work if tried again)."""

    _repo_id = "IDL:omg.org/CORBA/TRANSIENT:1.0"


class COMM_FAILURE(SystemException):
    """The connection to the server was lost during the call."""

    _repo_id = "IDL:omg.org/CORBA/COMM_FAILURE:1.0"


class TIMEOUT(SystemException):
    """The call did not complete within its timeout."""

    _repo_id = "IDL:omg.org/CORBA/TIMEOUT:1.0"


class MARSHAL(SystemException):
    """Data could not be decoded: truncated, malformed, or of another type."""

    _repo_id = "IDL:omg.org/CORBA/MARSHAL:1.0"


class OBJECT_NOT_EXIST(SystemException):
    """The target object does not exist (any more) on the server."""

    _repo_id = "IDL:omg.org/CORBA/OBJECT_NOT_EXIST:1.0"


class BAD_OPERATION(SystemException):
    """The target object has no such operation."""

    _repo_id = "IDL:omg.org/CORBA/BAD_OPERATION:1.0"


class BAD_PARAM(SystemException):
    """A value does not fit its IDL type (out of range, over a bound, wrong kind)."""

    _repo_id = "IDL:omg.org/CORBA/BAD_PARAM:1.0"


class NO_IMPLEMENT(SystemException):
    """The servant does not implement the operation."""

    _repo_id = "IDL:omg.org/CORBA/NO_IMPLEMENT:1.0"


class NO_RESOURCES(SystemException):
    """The server has run out of a resource it limits (a quota, a table's size)."""

    _repo_id = "IDL:omg.org/CORBA/NO_RESOURCES:1.0"


class NO_PERMISSION(SystemException):
    """The caller may not do this (the naming service: an owner's call it cannot check)."""

    _repo_id = "IDL:omg.org/CORBA/NO_PERMISSION:1.0"


class UNKNOWN(SystemException):
    """The servant raised an exception that is not declared in IDL."""

    _repo_id = "IDL:omg.org/CORBA/UNKNOWN:1.0"


SYSTEM_EXCEPTIONS: dict[str, type[SystemException]] = {
    cls._repo_id: cls
    for cls in (
        TRANSIENT,
        COMM_FAILURE,
        TIMEOUT,
        MARSHAL,
        OBJECT_NOT_EXIST,
        BAD_OPERATION,
        BAD_PARAM,
        NO_IMPLEMENT,
        NO_RESOURCES,
        NO_PERMISSION,
        UNKNOWN,
    )
}

__all__ = [
    "BAD_OPERATION",
    "BAD_PARAM",
    "COMM_FAILURE",
    "MARSHAL",
    "NO_IMPLEMENT",
    "NO_PERMISSION",
    "NO_RESOURCES",
    "OBJECT_NOT_EXIST",
    "SYSTEM_EXCEPTIONS",
    "TIMEOUT",
    "TRANSIENT",
    "UNKNOWN",
    "CompletionStatus",
    "SystemException",
    "UserException",
]
