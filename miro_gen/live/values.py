"""Values of generated types from plain data (what YAML and JSON give) and back.

The live tools read arguments from the shell (`miro call robot1/Arm move_to '{x: 1, y: 2}' 0.5`)
and print results readably. Both directions follow the generated classes' type hints, so they
work for any compiled type: structs and exceptions are mappings of their fields (or lists in
field order), unions a mapping of one branch, enums their enumerators' names (or numbers),
sequences and arrays lists, `sequence<octet>` a string or a list of numbers. A value that does
not fit raises `ValueError` naming where (`target.x: expected a number, not 'fast'`).
"""

from __future__ import annotations

import array
import dataclasses
import enum
import math
import types
import typing
from collections.abc import Callable
from typing import Any

from miro_gen.eventlog.show import summary
from miro_gen.live.show import flow
from miro_gen.runtime.cdr import IdlUnion
from miro_gen.runtime.rpc import Stub

# How an object reference given as text (a name in the naming service) becomes a stub.
Resolver = Callable[[str, type[Any]], Any]


def hints(obj: Any) -> dict[str, Any]:
    """The resolved type hints of a generated class or method."""
    return typing.get_type_hints(obj)


def from_text(hint: Any, text: str) -> Any:
    """A value of type `hint` from YAML or JSON text (`{data: hi}`); `-` reads the standard
    input. ValueError says what does not fit."""
    import sys

    import yaml

    if text == "-":
        text = sys.stdin.read()
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as e:
        raise ValueError(f"cannot read the value: {getattr(e, 'problem', e)}") from None
    return from_plain(hint, {} if data is None else data, "value")


def from_plain(hint: Any, data: Any, where: str = "value", resolve: Resolver | None = None) -> Any:
    """`data` (plain: numbers, strings, lists, mappings) as a value of type `hint`."""
    origin = typing.get_origin(hint)
    if hint is Any or hint is None or hint is type(None):
        return data
    if origin in (typing.Union, types.UnionType):
        options = [a for a in typing.get_args(hint) if a is not type(None)]
        if data is None:
            return None
        return from_plain(options[0], data, where, resolve)
    if origin is list or hint is list:
        (item,) = typing.get_args(hint) or (Any,)
        if not isinstance(data, list | tuple):
            raise ValueError(f"{where}: expected a list, not {_show(data)}")
        return [from_plain(item, v, f"{where}[{i}]", resolve) for i, v in enumerate(data)]
    if origin is tuple:
        return tuple(data)
    if not isinstance(hint, type):
        return data
    if hint is bool:
        if isinstance(data, bool):
            return data
        if isinstance(data, str) and data.lower() in ("true", "false"):
            return data.lower() == "true"
        raise ValueError(f"{where}: expected true or false, not {_show(data)}")
    if issubclass(hint, enum.Enum):
        return _enum(hint, data, where)
    if hint is float:
        if isinstance(data, int | float) and not isinstance(data, bool):
            return float(data)
        if isinstance(data, str):
            try:
                return float(data)
            except ValueError:
                pass
        raise ValueError(f"{where}: expected a number, not {_show(data)}")
    if hint is int:
        if isinstance(data, int) and not isinstance(data, bool):
            return data
        if isinstance(data, float) and data.is_integer():
            return int(data)
        raise ValueError(f"{where}: expected a whole number, not {_show(data)}")
    if hint is str:
        if isinstance(data, str):
            return data
        if isinstance(data, int | float) and not isinstance(data, bool):
            return str(data)  # YAML read `42` as a number: the user meant the text
        raise ValueError(f"{where}: expected a string, not {_show(data)}")
    if hint in (bytes, bytearray):
        if isinstance(data, str):
            return data.encode()
        if isinstance(data, list) and all(isinstance(b, int) and 0 <= b < 256 for b in data):
            return bytes(data)
        raise ValueError(f"{where}: expected a string or a list of bytes, not {_show(data)}")
    if issubclass(hint, array.array):
        return data
    if issubclass(hint, IdlUnion):
        return _union(hint, data, where, resolve)
    if dataclasses.is_dataclass(hint):
        return _struct(hint, data, where, resolve)
    if issubclass(hint, Stub):
        if isinstance(data, hint):
            return data
        if isinstance(data, str) and resolve is not None:
            return resolve(data, hint)
        raise ValueError(f"{where}: expected the name of a {hint._repo_id} object")
    return data


def _enum(cls: type[enum.Enum], data: Any, where: str) -> Any:
    if isinstance(data, str):
        name = data.rsplit("::", 1)[-1]
        if name in cls.__members__:
            return cls.__members__[name]
    elif isinstance(data, int) and not isinstance(data, bool):
        try:
            return cls(data)
        except ValueError:
            pass
    names = ", ".join(cls.__members__)
    raise ValueError(f"{where}: expected one of {names}, not {_show(data)}")


def _struct(cls: type[Any], data: Any, where: str, resolve: Resolver | None) -> Any:
    fields = [f for f in dataclasses.fields(cls) if f.init]
    types_ = hints(cls)
    if isinstance(data, list | tuple):
        if len(data) > len(fields):
            raise ValueError(f"{where}: {cls.__name__} has {len(fields)} fields, not {len(data)}")
        data = {f.name: v for f, v in zip(fields, data, strict=False)}
    if not isinstance(data, dict):
        names = ", ".join(f.name for f in fields)
        raise ValueError(f"{where}: expected a mapping of {names}, not {_show(data)}")
    known = {f.name for f in fields}
    unknown = [k for k in data if k not in known]
    if unknown:
        names = ", ".join(f.name for f in fields)
        raise ValueError(f"{where}: {cls.__name__} has no field {unknown[0]!r} (it has {names})")
    args = {k: from_plain(types_.get(k, Any), v, f"{where}.{k}", resolve) for k, v in data.items()}
    return cls(**args)


def _union(cls: type[IdlUnion], data: Any, where: str, resolve: Resolver | None) -> Any:
    names = ", ".join(cls._branches)
    if not (isinstance(data, dict) and len(data) == 1):
        raise ValueError(f"{where}: expected one branch ({names}) and its value, {{branch: value}}")
    ((branch, value),) = data.items()
    if branch not in cls._branches:
        raise ValueError(f"{where}: {cls.__name__} has no branch {branch!r} (it has {names})")
    prop = getattr(cls, branch)
    hint = hints(prop.fget).get("return", Any) if isinstance(prop, property) else Any
    return cls(**{branch: from_plain(hint, value, f"{where}.{branch}", resolve)})


def to_plain(value: Any, limit: int | None = None) -> Any:
    """A value of a generated type as plain data (for YAML and JSON); with `limit`, a sequence
    or byte string of more elements as a text of its length and first ones."""
    if limit is not None:
        short = summary(value, limit, lambda v: flow(to_plain(v, limit)))
        if short is not None:
            return short
    if value is None or isinstance(value, bool | str):
        return value
    if isinstance(value, enum.Enum):
        return value.name
    if isinstance(value, int):
        return value
    if isinstance(value, float):
        return value if math.isfinite(value) else str(value)
    if isinstance(value, bytes | bytearray):
        text = bytes(value).decode("utf-8", "replace")
        return text if text.isprintable() else list(value)
    if isinstance(value, IdlUnion):
        branch = value._branch()
        return {branch or "_d": to_plain(value._v if branch else value._d, limit)}
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {f.name: to_plain(getattr(value, f.name), limit) for f in dataclasses.fields(value)}
    if isinstance(value, list | tuple | array.array):
        return [to_plain(v, limit) for v in value]
    if isinstance(value, Stub):
        ref = value._ref
        return f"{ref.repo_id} at {ref.endpoint} (key {ref.key.decode('latin-1')})"
    return str(value)


def _show(data: Any) -> str:
    text = repr(data)
    return text if len(text) <= 60 else text[:57] + "..."
