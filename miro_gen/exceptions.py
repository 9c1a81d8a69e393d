"""Exceptions of remote calls, named and shaped as CORBA's, which Miro users know; and the
base of the failures a user can act on.

`UserException` is the base of every exception declared in IDL (`exception ETimeOut {...};`).
`SystemException` and its subclasses report what went wrong in the middleware itself, each with
`completed`: whether the operation ran (`YES`), did not run (`NO`), or may have run (`MAYBE`).

`ActionableError` is the base of the failures that are the user's to fix, not defects: a bad
command-line option, a name nobody bound, a document that does not fit. `miro_gen.lifecycle`
prints them as one line (`user_message`). Each floor derives its own errors from it; a class it
cannot derive (generated from IDL, such as `MiroNaming.NotFound`, or a library's, such as
pyzmq's `ZMQError`) is made actionable by the floor that raises it, with `actionable`.
"""

from __future__ import annotations

import enum
from collections.abc import Callable
from typing import ClassVar, TypeVar

E = TypeVar("E", bound=BaseException)


class ActionableError(Exception):
    """A failure the user can act on: `one_line()` says what failed and what to do, and a
    command exits with `exit_status` (2 for a bad command line), without a traceback."""

    exit_status: ClassVar[int] = 1

    def one_line(self) -> str:
        return str(self)


# Classes a floor cannot derive from ActionableError -> (their message, exit status)
_ACTIONABLE: dict[type[BaseException], tuple[Callable[[BaseException], str], int]] = {}


def actionable(cls: type[E], message: Callable[[E], str], exit_status: int = 1) -> None:
    """Have `cls` and its subclasses (an IDL exception, a library's error) told as one line,
    `message(exc)`, as an ActionableError is: called by the floor that raises them, when it is
    imported."""
    _ACTIONABLE[cls] = (message, exit_status)  # type: ignore[assignment]


def user_message(exc: BaseException) -> tuple[str, int] | None:
    """The one line and exit status of a failure the user can act on; None for a defect."""
    if isinstance(exc, ActionableError):
        return exc.one_line(), exc.exit_status
    for cls in type(exc).__mro__:
        found = _ACTIONABLE.get(cls)
        if found is not None:
            return found[0](exc), found[1]
    return None


class CompletionStatus(enum.IntEnum):
    """Whether the remote operation had completed when a system exception happened."""

    YES = 0
    NO = 1
    MAYBE = 2


class UserException(Exception):
    """Base of the exceptions declared in IDL; generated subclasses carry the IDL fields."""

    _repo_id: ClassVar[str] = "IDL:omg.org/CORBA/UserException:1.0"


class SystemException(ActionableError):
    """A failure of the middleware, not of the servant's code (a user acts on it: a server not
    running, a call that timed out)."""

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

    def one_line(self) -> str:
        return self.message or str(self)

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
    "ActionableError",
    "CompletionStatus",
    "SystemException",
    "UserException",
    "actionable",
    "user_message",
]
