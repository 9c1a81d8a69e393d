"""What a scaffold needs to know of an IDL interface: its operations, read from the generated
skeleton class, with Python spellings of their types and a default value for each result."""

from __future__ import annotations

import array
import dataclasses
import enum
import importlib
import types
import typing
from dataclasses import dataclass

from miro_gen.runtime.arrays import NumberBuffer

_NUMBER_BUFFERS = frozenset(typing.get_args(NumberBuffer))


@dataclass
class Param:
    name: str
    annotation: str
    default: str  # a value of that type, for calls in tests


WIDTH = 88  # columns of the code scaffolds lay out: ruff's default, so both settings agree


@dataclass
class Operation:
    name: str
    doc: str
    params: list[Param]
    returns: str
    result: str  # the default result, or "" for None

    def definition(self, indent: int) -> str:
        """Its `def` line, as ruff would format it: one line, or one parameter a line with
        a trailing comma (which keeps it so at any line length)."""
        params = ["self", *(f"{p.name}: {p.annotation}" for p in self.params)]
        return _laid_out(f"def {self.name}(", params, f") -> {self.returns}:", indent)

    def check(self, stub: str, indent: int) -> str:
        """Test lines that call it through `stub` with plain arguments and compare the
        result with the servant's default."""
        args = [p.default for p in self.params]
        call = _laid_out(f"{stub}.{self.name}(", args, ")", indent)
        if not self.result:
            return call
        if "\n" not in call and indent + len(f"assert {call} == {self.result}") <= WIDTH:
            return f"assert {call} == {self.result}"
        pad = "\n" + " " * indent
        return _laid_out(f"got = {stub}.{self.name}(", args, ")", indent) + (
            f"{pad}assert got == {self.result}"
        )


@dataclass
class Interface:
    scoped: str  # Miro::Example
    package: str  # Miro
    poa_package: str  # Miro__POA
    cls: str  # Example
    operations: list[Operation]
    packages: list[str]  # what the annotations use, to import

    @property
    def package_imports(self) -> list[str]:
        """`import X` for each package the annotations use."""
        return [f"import {p}" for p in self.packages]

    @property
    def getter(self) -> Operation | None:
        """The first operation that takes nothing and returns something: what a client polls."""
        return next((op for op in self.operations if not op.params and op.result), None)


class InterfaceError(LookupError):
    """The interface is not there or not usable."""


def load_interface(scoped: str) -> Interface:
    """The interface `scoped` (`Module::Name`), from its generated skeleton."""
    parts = scoped.split("::")
    if len(parts) < 2 or not all(p.isidentifier() for p in parts):
        raise InterfaceError(f"{scoped!r} is not a scoped interface name such as Miro::Example")
    package, cls = parts[0], ".".join(parts[1:])
    try:
        poa = importlib.import_module(package + "__POA")
        stub_pkg = importlib.import_module(package)
        skeleton = poa
        stub: object = stub_pkg
        for part in parts[1:]:
            skeleton = getattr(skeleton, part)
            stub = getattr(stub, part)
    except (ImportError, AttributeError):
        raise InterfaceError(
            f"no generated code for interface {scoped}: compile its IDL with miro-idl first "
            "(miro new --idl FILE does)"
        ) from None
    if not isinstance(skeleton, type):
        raise InterfaceError(f"{scoped} is not an interface")
    used: set[str] = {package}
    operations = []
    for name in sorted(getattr(skeleton, "__abstractmethods__", ())):
        method = getattr(skeleton, name)
        hints = typing.get_type_hints(method)
        returns = hints.pop("return", type(None))
        params = [
            Param(p, _spell(hints[p], used), _default(hints[p], used))
            for p in method.__code__.co_varnames[1 : method.__code__.co_argcount]
        ]
        result = _default(returns, used) if returns is not type(None) else ""
        doc = (method.__doc__ or "").strip().splitlines()
        operations.append(
            Operation(name, doc[0] if doc else name, params, _spell(returns, used), result)
        )
    order = {n: i for i, n in enumerate(vars(skeleton))}  # declaration order where known
    operations.sort(key=lambda op: order.get(op.name, len(order)))
    return Interface(scoped, package, package + "__POA", cls, operations, sorted(used))


def _spell(t: object, used: set[str]) -> str:
    """`t` as user code writes it (`Miro.ExampleStructIDL`, `list[float]`)."""
    if t is type(None) or t is None:
        return "None"
    origin, args = typing.get_origin(t), typing.get_args(t)
    if origin in (typing.Union, types.UnionType):
        # Numbers are sent as any sequence or buffer: a scaffold returns a list.
        kept = [a for a in args if a not in _NUMBER_BUFFERS]
        return " | ".join(_spell(a, used) for a in kept)
    if origin is array.array:  # numbers arrive as arrays
        used.add("array")
        return f"array.array[{', '.join(_spell(a, used) for a in args)}]"
    if origin is not None:
        name = "list" if origin is list else "tuple" if origin is tuple else "list"
        return f"{name}[{', '.join(_spell(a, used) for a in args)}]"
    if isinstance(t, type):
        if t.__module__ == "builtins":
            return t.__name__
        top = t.__module__.split(".")[0]
        used.add(top)
        return f"{top}.{t.__qualname__}"
    return "typing.Any"  # pragma: no cover - generated hints are all of the above


def _default(t: object, used: set[str]) -> str:
    """A Python expression for a plain value of type `t`."""
    origin, args = typing.get_origin(t), typing.get_args(t)
    if origin in (typing.Union, types.UnionType):
        return "None" if type(None) in args else _default(args[0], used)
    if origin is tuple:
        items = [_default(a, used) for a in args]
        return f"({', '.join(items)}{',' if len(items) == 1 else ''})"
    if origin is array.array:
        used.add("array")
        return f'array.array("{"d" if args == (float,) else "q"}")'
    if origin is not None:
        return "[]"
    simple = {int: "0", float: "0.0", bool: "False", str: '""', bytes: 'b""'}
    if t in simple:
        return simple[t]
    if isinstance(t, type) and issubclass(t, enum.Enum):
        return f"{_spell(t, used)}.{next(iter(t)).name}"
    if isinstance(t, type) and (dataclasses.is_dataclass(t) or hasattr(t, "serialize")):
        return f"{_spell(t, used)}()"
    return "None"


def _laid_out(head: str, items: list[str], tail: str, indent: int) -> str:
    """`head items tail` on one line if it fits in WIDTH, else one item a line."""
    one = f"{head}{', '.join(items)}{tail}"
    if indent + len(one) <= WIDTH or not items:
        return one
    inner = " " * (indent + 4)
    lines = [head, *(f"{inner}{item}," for item in items), " " * indent + tail]
    return "\n".join(lines)
