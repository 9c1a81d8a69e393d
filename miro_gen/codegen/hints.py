"""Python type hints and default values of IDL-typed values, as spelled in a generated module.

`TypeHints.annotation` and `TypeHints.default` are the one place that decides how a shape
(`shapes.py`) looks in Python: `int`, `list[Miro.Pose]`, `_arrays.Array[float]`,
`_cdr.ObjectRef`; `0`, a default factory. A new mapping changes these two methods and the codec
steps (`codec.py`) for the same shapes.
"""

from __future__ import annotations

import math
from ast import literal_eval as ast_literal
from dataclasses import dataclass

from miro_gen.codegen import names
from miro_gen.codegen.contexts import ModuleContext
from miro_gen.codegen.scope import Scope
from miro_gen.codegen.shapes import DATA_KINDS, Shape
from miro_gen.idl import ast

# Names enum classes have that enumerators must not shadow.
_ENUM_RESERVED = frozenset(["name", "value", "mro"])


def enumerator_name(name: str) -> str:
    """The Python name of an enumerator (an attribute of its IntEnum)."""
    return names.py_name(name, _ENUM_RESERVED)


@dataclass(frozen=True)
class Default:
    """A default value: an expression (`value`), or a zero-argument callable making one."""

    value: str = ""
    factory: str = ""

    @property
    def zero(self) -> str:
        """A zero-argument callable making the value."""
        return self.factory or f"lambda: {self.value}"


class TypeHints:
    """Annotations and defaults of values, with the references they need recorded in the
    module they are written in."""

    def __init__(self, scope: Scope) -> None:
        self.scope = scope

    def annotation(
        self,
        shape: Shape,
        m: ModuleContext,
        use_alias: bool = True,
        in_op: bool = False,
        sending: bool = False,
    ) -> str:
        """The type hint of a value. Object references inside an operation's arguments and
        results arrive as stubs, but as `ObjectRef` inside data types; so a typedef holding
        references is spelled out there rather than named (its alias says `ObjectRef`). What is
        being sent (a stub's arguments, a servant's results) may be any sequence, and for an
        object reference a local servant; numbers, any sequence or buffer of them."""
        numbers = shape.numbers
        if numbers is not None and sending:  # any sequence or buffer of numbers, typedef'd too
            m.use("arrays", "typing")
            return f"_t.Sequence[{numbers.py}] | _arrays.NumberBuffer"
        if (
            use_alias
            and shape.alias is not None
            and not (in_op and shape.innermost.kind == "object")
        ):
            return self.scope.ref(shape.alias, m)
        if numbers is not None:  # what arrives: an array.array
            m.use("arrays")
            return f"_arrays.Array[{numbers.py}]"
        match shape.kind:
            case "prim":
                assert shape.prim is not None
                return shape.prim.py
            case "string" | "wstring":
                return "str"
            case "octets":
                return "bytes"
            case "seq" | "array":
                inner = shape.elem if shape.kind == "seq" else shape.row
                assert inner is not None
                inner_ann = self.annotation(inner, m, in_op=in_op, sending=sending)
                if sending:  # any sequence will do, and a list of stubs is one of stubs-or-servants
                    m.use("typing")
                    return f"_t.Sequence[{inner_ann}]"
                return f"list[{inner_ann}]"
            case "enum" | "struct" | "union" | "exception":
                assert shape.decl is not None
                return self.scope.ref(shape.decl, m)
            case "object":
                if not in_op:
                    m.use("cdr")
                    return "_cdr.ObjectRef"
                stub = self.stub(shape, m)
                if sending:
                    m.use("rpc")
                    return f"{stub} | _rpc.Servant | None"
                return f"{stub} | None"
        raise AssertionError(shape.kind)  # pragma: no cover

    def stub(self, shape: Shape, m: ModuleContext) -> str:
        """The stub class of an object reference (`_rpc.Stub` for `Object`)."""
        decl = shape.decl.resolved if shape.decl is not None else None
        if isinstance(decl, ast.Interface):
            return self.scope.ref(decl, m)
        m.use("rpc")
        return "_rpc.Stub"

    def default(self, shape: Shape, m: ModuleContext) -> Default:
        """The default value of a field or union branch of this shape."""
        match shape.kind:
            case "prim":
                assert shape.prim is not None
                return Default(shape.prim.default)
            case "string" | "wstring":
                return Default('""')
            case "octets":
                return Default('b""')
            case "enum":
                return Default(self.enumerator(shape.enum, shape.enum.enumerators[0].name, m))
            case "struct" | "union" | "exception":
                assert shape.decl is not None
                return Default(factory=self.scope.ref(shape.decl, m))
            case "seq" if shape.numbers is not None:
                return Default(factory=f"lambda: {self._zeros(shape, m)}")
            case "seq":
                return Default(factory="list")
            case "array":
                return Default(factory=f"lambda: {self._array_value(shape, m)}")
            case "object":  # a factory, not a call in the class body (ruff's RUF009)
                m.use("cdr")
                return Default(factory="_cdr.ObjectRef")
        raise AssertionError(shape.kind)  # pragma: no cover

    def given(self, shape: Shape, value: ast.ConstValue, m: ModuleContext) -> Default:
        """The default a ROS 2 interface gives a field (its `@default`, which
        rosidl_generator_py makes the field's default in Python): a number, boolean or string,
        or for a sequence or array the text of a Python tuple of them, as rosidl writes it."""
        match shape.kind:
            case "prim":
                assert shape.prim is not None
                return Default(_literal(shape.prim.py, value))
            case "string" | "wstring":
                return Default(repr(str(value)))
            case "octets":
                return Default(repr(bytes(int(v) for v in _items(value))))
            case "seq" | "array" if shape.elem is not None:
                items = [self.given(shape.elem, v, m).value for v in _items(value)]
                if shape.numbers is not None:
                    m.use("arrays")
                    code = shape.numbers.code
                    return Default(
                        factory=f'lambda: _arrays.to_array("{code}", [{", ".join(items)}])'
                    )
                return Default(factory=f"lambda: [{', '.join(items)}]")
        raise AssertionError(f"no @default for a {shape.kind}")  # pragma: no cover

    def _array_value(self, shape: Shape, m: ModuleContext) -> str:
        elem = shape.elem
        assert elem is not None
        n = shape.dims[0]
        if shape.numbers is not None:
            return self._zeros(shape, m)
        if shape.row.kind == "array":
            return f"[{self._array_value(shape.row, m)} for _ in range({n})]"
        if elem.kind == "object":
            m.use("cdr")
            return f"[_cdr.ObjectRef()] * {n}"
        if elem.kind in ("prim", "string", "wstring", "octets", "enum"):
            return f"[{self.default(elem, m).value}] * {n}"
        if elem.kind == "seq":
            fresh = self._zeros(elem, m) if elem.numbers is not None else "[]"
            return f"[{fresh} for _ in range({n})]"
        assert elem.kind in DATA_KINDS and elem.decl is not None
        return f"[{self.scope.ref(elem.decl, m)}() for _ in range({n})]"

    def _zeros(self, shape: Shape, m: ModuleContext) -> str:
        """A new value of a sequence (empty) or an array (zeros) of numbers."""
        assert shape.numbers is not None
        m.use("arrays")
        n = f", {shape.dims[0]}" if shape.kind == "array" else ""
        return f'_arrays.zeros("{shape.numbers.code}"{n})'

    def enumerator(self, enum: ast.Enum, name: str, m: ModuleContext) -> str:
        """An enumerator as a value: `Color.RED`, through the enum's class."""
        return f"{self.scope.ref(enum, m)}.{enumerator_name(name)}"


def _items(value: ast.ConstValue) -> list[bool | int | float | str]:
    """The elements of a sequence's or array's `@default`: rosidl writes the text of a tuple."""
    items = ast_literal(value) if isinstance(value, str) else None
    assert isinstance(items, tuple), value
    return list(items)


def _literal(py: str, value: ast.ConstValue) -> str:
    """A number or boolean default as a Python expression of the field's annotation `py`."""
    assert isinstance(value, bool | int | float), value
    if py == "bool":
        return "True" if value else "False"
    if py == "float":
        f = float(value)
        return repr(f) if math.isfinite(f) else f'float("{f}")'
    return repr(int(value))
