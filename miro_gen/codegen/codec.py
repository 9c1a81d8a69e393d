"""The codec planner: the steps (`steps.py`) that encode and decode values of given shapes.

Runs of consecutive fixed-size values whose padding is static are packed with one precompiled
`struct.Struct` of the module; sequences of numeric primitives, of enumerators and of structs
whose members are all one numeric primitive move in bulk; strings, octets and object
references are one runtime call; nested data types call their own `_enc_`/`_dec_` functions;
the rest loops. One `CodecPlanner` plans the functions that share local names (a type's encoder
and decoder, or the four codecs of an operation): its `Temps` numbers their variables.
"""

from __future__ import annotations

import itertools
import re

from miro_gen.codegen import names
from miro_gen.codegen.contexts import ModuleContext
from miro_gen.codegen.hints import TypeHints
from miro_gen.codegen.scope import Scope
from miro_gen.codegen.shapes import Shape, member_shape
from miro_gen.codegen.steps import (
    Assign,
    DecodeNested,
    DecodeStep,
    EncodeNested,
    EncodeStep,
    GetArray,
    GetBooleans,
    GetChars,
    GetEnums,
    GetFlat,
    GetNumberArray,
    GetNumbers,
    GetObject,
    GetOctets,
    GetSequence,
    GetString,
    GetWString,
    Pack,
    PackCheck,
    PutArray,
    PutBooleans,
    PutChars,
    PutEnums,
    PutFlat,
    PutNumberArray,
    PutNumbers,
    PutObject,
    PutOctets,
    PutSequence,
    PutString,
    PutWString,
    Unpack,
)
from miro_gen.idl import ast

# A temporary of an enclosing loop in a packed value: its check is exempt from ruff's B023.
_LOOP_VARIABLE = re.compile(r"\b_x\d+\b").search

# A value to encode: its shape, the expression giving it, and what error messages call it.
Encoded = tuple[Shape, str, str]
# A value to decode: its shape and what error messages call it.
Decoded = tuple[Shape, str]


class Temps:
    """Fresh local variable names for one group of generated functions (`_x0`, `_t1`, ...)."""

    def __init__(self) -> None:
        self._numbers = itertools.count()

    def name(self, prefix: str) -> str:
        return f"_{prefix}{next(self._numbers)}"

    def number(self) -> int:
        return next(self._numbers)


class CodecPlanner:
    """Plans the codecs of one group of functions of module `m`."""

    def __init__(self, scope: Scope, hints: TypeHints, m: ModuleContext) -> None:
        self.scope = scope
        self.hints = hints
        self.m = m
        self.temps = Temps()

    # ---- runs of fixed-size values ---------------------------------------------------------
    @staticmethod
    def runs(shapes: list[Shape]) -> list[tuple[int, ...] | int]:
        """Group consecutive fixed-size values into runs whose internal padding is static:
        a run starts aligned to its first value, and takes only values aligned no stricter.
        Values that are not fixed-size stand alone (their index)."""
        out: list[tuple[int, ...] | int] = []
        run: list[int] = []
        a0 = 0
        for i, s in enumerate(shapes):
            if s.fixed:
                a = s.unit.size
                if run and a <= a0:
                    run.append(i)
                    continue
                if run:
                    out.append(tuple(run))
                run, a0 = [i], a
            else:
                if run:
                    out.append(tuple(run))
                    run = []
                out.append(i)
        if run:
            out.append(tuple(run))
        return out

    @staticmethod
    def layout(shapes: list[Shape]) -> tuple[str, int, list[tuple[int, int]]]:
        """Struct format, size and (first value index, value count) of each item of a run."""
        fmt = ""
        size = 0
        positions: list[tuple[int, int]] = []
        nvalues = 0
        for s in shapes:
            u = s.unit
            pad = -size % u.size
            if pad:
                fmt += f"{pad}x"
                size += pad
            n = s.count if s.kind == "array" else 1
            fmt += f"{n}{u.code}" if n > 1 else u.code
            size += n * u.size
            positions.append((nvalues, n))
            nvalues += n
        return fmt, size, positions

    # ---- encoding --------------------------------------------------------------------------
    def encode_members(self, entries: list[Encoded], inv: str | None = None) -> list[EncodeStep]:
        """Encode `(shape, expression, what)` values in order; `inv` is the invoker that
        turns servants into references (operations only)."""
        steps: list[EncodeStep] = []
        for group in self.runs([s for s, _, _ in entries]):
            if isinstance(group, int):
                steps += self.encode_value(*entries[group], inv)
                continue
            shapes = [entries[i][0] for i in group]
            fmt, _, _ = self.layout(shapes)
            values = [self._pack_expr(*entries[i]) for i in group]
            checks = [
                PackCheck(
                    entries[i][2],
                    entries[i][0].packed_format,
                    value,
                    _LOOP_VARIABLE(value) is not None,
                )
                for i, value in zip(group, values, strict=True)
            ]
            steps.append(
                Pack(
                    align=shapes[0].unit.size,
                    codec=self.m.struct_codec(fmt),
                    values=values,
                    checks=checks,
                )
            )
        return steps

    def _pack_expr(self, shape: Shape, expr: str, what: str) -> str:
        if shape.kind == "enum":
            return f"{self._enum_table(shape.enum, 'W')}[{expr}]"
        if shape.kind != "array":
            prim = shape.prim
            return f"{prim.to_wire}({expr})" if prim and prim.to_wire else expr
        elem = shape.elem
        assert elem is not None
        if elem.kind == "enum":
            to_wire: str | None = f"{self._enum_table(elem.enum, 'W')}.__getitem__"
        else:
            to_wire = elem.prim.to_wire if elem.prim else None
        if len(shape.dims) == 1 and not to_wire:
            return f"*{expr}"
        conv = f", {to_wire}" if to_wire else ""
        return f"*_cdr.flatten({expr}, {shape.dims}, {what!r}{conv})"

    def encode_value(
        self, shape: Shape, expr: str, what: str, inv: str | None = None
    ) -> list[EncodeStep]:
        """Encode one value of `shape` given by `expr`."""
        if shape.fixed:
            return self.encode_members([(shape, expr, what)])
        match shape.kind:
            case "string":
                return [PutString(bound=shape.bound, expr=expr, what=what)]
            case "wstring":
                return [PutWString(bound=shape.bound, expr=expr, what=what)]
            case "octets":
                return [PutOctets(bound=shape.bound, expr=expr, what=what)]
            case "object":
                if inv:
                    self.m.use("rpc")
                    expr = f"_rpc.to_ref({expr}, {inv})"
                return [PutObject(expr=expr, what=what)]
            case "struct" | "union" | "exception":
                assert shape.decl is not None
                function = self.scope.ref(shape.decl, self.m, fmt="_enc_{}")
                return [EncodeNested(expr=expr, function=function, what=what)]
            case "seq":
                return [self._encode_sequence(shape, expr, what, inv)]
            case "array":
                numbers = shape.numbers
                if numbers is not None:
                    self.m.use("arrays")
                    code, size = numbers.code, numbers.size
                    count = shape.dims[0]
                    return [PutNumberArray(expr, code, size, count, what)]
                var = self.temps.name("x")
                body = self.encode_value(shape.row, var, what, inv)
                return [PutArray(expr=expr, count=shape.dims[0], what=what, var=var, body=body)]
        raise AssertionError(shape.kind)  # pragma: no cover

    def _encode_sequence(self, shape: Shape, expr: str, what: str, inv: str | None) -> EncodeStep:
        elem = shape.elem
        assert elem is not None
        bound = shape.bound
        if elem.kind == "enum":
            table = self._enum_table(elem.enum, "W")
            return PutEnums(bound=bound, expr=expr, table=table, what=what)
        numbers = shape.numbers
        if numbers is not None:
            self.m.use("arrays")
            return PutNumbers(bound, expr, numbers.code, numbers.size, what)
        if elem.prim is not None:
            if elem.prim.idl == "boolean":
                return PutBooleans(bound=bound, expr=expr, what=what)
            return PutChars(bound=bound, expr=expr, what=what)
        flat = self._flat(elem)
        if flat is not None:
            getter, code, size, count = flat
            return PutFlat(
                bound=bound,
                expr=expr,
                getter=getter,
                count=count,
                code=code,
                size=size,
                what=what,
            )
        var = self.temps.name("x")
        body = self.encode_value(elem, var, what, inv)
        return PutSequence(bound=bound, expr=expr, what=what, var=var, body=body)

    # ---- decoding --------------------------------------------------------------------------
    def decode_members(
        self, entries: list[Decoded], inv: str | None = None
    ) -> tuple[list[DecodeStep], list[str]]:
        """Decode `(shape, what)` values in order; the steps and an expression for each."""
        steps: list[DecodeStep] = []
        values: list[str] = [""] * len(entries)
        for group in self.runs([s for s, _ in entries]):
            if isinstance(group, int):
                shape, what = entries[group]
                var = self.temps.name("f")
                steps += self.decode_value(shape, var, what, inv)
                values[group] = var
                continue
            shapes = [entries[i][0] for i in group]
            fmt, size, positions = self.layout(shapes)
            tup = self.temps.name("t")
            steps.append(
                Unpack(
                    align=shapes[0].unit.size,
                    var=tup,
                    codec=self.m.struct_codec(fmt),
                    size=size,
                    count=positions[-1][0] + positions[-1][1],
                )
            )
            for i, (first, n) in zip(group, positions, strict=True):
                values[i] = self._unpacked_expr(entries[i][0], tup, first, n, entries[i][1])
        return steps, values

    def _unpacked_expr(self, shape: Shape, tup: str, first: int, n: int, what: str) -> str:
        if shape.kind == "array":
            elem = shape.elem
            assert elem is not None
            part = f"{tup}[{first}:{first + n}]"
            if elem.kind == "enum":
                part = f"_cdr.enums({self._enum_table(elem.enum, 'T')}, {part}, {what!r})"
            elif elem.prim is not None and elem.prim.number:
                self.m.use("arrays")
                code = f'"{elem.prim.number}"'
                if len(shape.dims) > 1:
                    return f"_arrays.to_rows({code}, {part}, {shape.dims})"
                return f"_arrays.to_array({code}, {part})"
            elif elem.prim is not None and elem.prim.from_wire:
                part = f"list(map({elem.prim.from_wire}, {part}))"
            else:
                part = f"list({part})"
            if len(shape.dims) > 1:
                return f"_cdr.reshape({part}, {shape.dims})"
            return part
        value = f"{tup}[{first}]"
        if shape.kind == "enum":
            return f"_cdr.enum_value({self._enum_table(shape.enum, 'T')}, {value}, {what!r})"
        if shape.prim is not None and shape.prim.from_wire:
            return f"{shape.prim.from_wire}({value})"
        return value

    def decode_value(
        self, shape: Shape, var: str, what: str, inv: str | None = None
    ) -> list[DecodeStep]:
        """Decode one value of `shape` into variable `var`."""
        if shape.fixed:
            steps, (value,) = self.decode_members([(shape, what)])
            return [*steps, Assign(var=var, expr=value)]
        match shape.kind:
            case "string":
                return [GetString(bound=shape.bound, var=var, what=what)]
            case "wstring":
                return [GetWString(bound=shape.bound, var=var, what=what)]
            case "octets":
                return [GetOctets(bound=shape.bound, var=var, what=what)]
            case "object":
                obj: list[DecodeStep] = [GetObject(var=var, what=what)]
                if inv:
                    self.m.use("rpc")
                    stub = self.hints.stub(shape, self.m)
                    obj.append(Assign(var=var, expr=f"_rpc.make_stub({stub}, {var}, {inv})"))
                return obj
            case "struct" | "union" | "exception":
                assert shape.decl is not None
                function = self.scope.ref(shape.decl, self.m, fmt="_dec_{}")
                return [DecodeNested(var=var, function=function)]
            case "seq":
                return self._decode_sequence(shape, var, what, inv)
            case "array":
                numbers = shape.numbers
                if numbers is not None:
                    self.m.use("arrays")
                    code, size = numbers.code, numbers.size
                    return [GetNumberArray(var, code, size, shape.dims[0], what)]
                item = self.temps.name("x")
                body = self.decode_value(shape.row, item, what, inv)
                return [GetArray(var=var, count=shape.dims[0], item=item, body=body)]
        raise AssertionError(shape.kind)  # pragma: no cover

    def _decode_sequence(
        self, shape: Shape, var: str, what: str, inv: str | None
    ) -> list[DecodeStep]:
        elem = shape.elem
        assert elem is not None
        bound = shape.bound
        if elem.kind == "enum":
            table = self._enum_table(elem.enum, "T")
            return [GetEnums(bound=bound, var=var, table=table, what=what)]
        numbers = shape.numbers
        if numbers is not None:
            self.m.use("arrays")
            return [GetNumbers(bound, var, numbers.code, numbers.size, what)]
        if elem.prim is not None:
            if elem.prim.idl == "boolean":
                return [GetBooleans(bound=bound, var=var, what=what)]
            return [GetChars(bound=bound, var=var, what=what)]
        flat = self._flat(elem)
        if flat is not None:
            assert elem.decl is not None
            _, code, size, count = flat
            cls = self.scope.ref(elem.decl, self.m)
            return [
                GetFlat(
                    bound=bound,
                    var=var,
                    cls=cls,
                    count=count,
                    code=code,
                    size=size,
                    what=what,
                )
            ]
        item = self.temps.name("x")
        counter = self.temps.number()
        return [
            GetSequence(
                bound=bound,
                var=var,
                min_size=elem.min_size,
                what=what,
                item=item,
                counter=counter,
                body=self.decode_value(elem, item, what, inv),
            )
        ]

    # ---- helpers ---------------------------------------------------------------------------
    def _enum_table(self, enum: ast.Enum, suffix: str) -> str:
        """The tuple of an enum's members by ordinal (`_E_T`), or with suffix "W" the dict that
        checks a value is one of its ordinals before it is encoded (`_E_W`)."""
        return self.scope.ref(enum, self.m, fmt="_{}_" + suffix)

    def _flat(self, shape: Shape) -> tuple[str, str, int, int] | None:
        """A struct whose members are all one numeric primitive: sequences of it move in bulk.
        (getter variable, array code, element size, members per element)"""
        if shape.kind != "struct" or not isinstance(shape.decl, ast.Struct):
            return None
        members = shape.decl.all_members
        if not members:
            return None
        codes = set()
        for m in members:
            s = member_shape(m)
            if s.prim is None or s.prim.array is None:
                return None
            codes.add(s.prim.code)
        if len(codes) != 1:
            return None
        prim = member_shape(members[0]).unit
        assert prim.array is not None
        attrs = tuple(names.py_name(m.name, names.STRUCT_ATTRIBUTES) for m in members)
        var = f"_G_{self.scope.ref(shape.decl, self.m).replace('.', '_')}"
        return self.m.getter(var, attrs), prim.array, prim.size, len(members)


def single_unpack(steps: list[DecodeStep], values: list[str]) -> str | None:
    """The tuple variable when decoded values are exactly one run of unconverted scalars, in
    order: they are then passed on as the unpacked tuple (`*_t0`)."""
    first = steps[0] if len(steps) == 1 else None
    if (
        isinstance(first, Unpack)
        and first.count == len(values)
        and values == [f"{first.var}[{i}]" for i in range(len(values))]
    ):
        return first.var
    return None
