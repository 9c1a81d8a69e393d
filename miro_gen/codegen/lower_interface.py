"""Lowering of interfaces into a client stub and a skeleton, each with its operations."""

from __future__ import annotations

from dataclasses import dataclass

from miro_gen.codegen import names
from miro_gen.codegen.codec import CodecPlanner, Encoded
from miro_gen.codegen.contexts import (
    ModuleContext,
    OperationContext,
    ParamContext,
    SkeletonContext,
    StubContext,
)
from miro_gen.codegen.hints import TypeHints
from miro_gen.codegen.interface_schema import InterfaceSchemas, NoInterfaceSchema
from miro_gen.codegen.python_limits import python_bases
from miro_gen.codegen.scope import Scope
from miro_gen.codegen.shapes import Shape, shape_of
from miro_gen.codegen.steps import Assign, DecodeStep
from miro_gen.diagnostics import SourcePos
from miro_gen.idl import ast


@dataclass
class _Signature:
    """An operation, or an attribute's accessor, as both sides see it."""

    name: str  # the Python method name (not yet checked for ambiguity)
    wire: str
    doc: str | None
    oneway: bool
    params: list[ast.Param]
    returns: ast.TypeSpec | None
    raises: list[ast.Exception_]
    what: str
    pos: SourcePos


class InterfaceLowering:
    """Stub and skeleton contexts of interfaces, written into the module contexts passed in."""

    def __init__(self, scope: Scope, hints: TypeHints, declarations: list[ast.Decl]) -> None:
        self.scope = scope
        self.hints = hints
        self.schemas = InterfaceSchemas(declarations)
        self._schemas: dict[int, str] = {}
        self._shapes: dict[int, Shape] = {}  # by IDL type: the stub and the skeleton both ask

    def _shape(self, t: ast.TypeSpec, pos: SourcePos) -> Shape:
        shape = self._shapes.get(id(t))
        if shape is None:
            shape = self._shapes[id(t)] = shape_of(t, pos)
        return shape

    def schema(self, d: ast.Interface) -> str:
        """The interface schema of `d` ('' when it cannot have one), made once for both."""
        text = self._schemas.get(id(d))
        if text is None:
            try:
                text = self.schemas.of(d)
            except NoInterfaceSchema:  # its service object cannot describe it to callers
                text = ""
            self._schemas[id(d)] = text
        return text

    def stub(
        self, d: ast.Interface, m: ModuleContext, nested: list[tuple[str, str]]
    ) -> StubContext:
        if not d.bases:
            m.use("rpc")
        if d.operations or d.attributes:
            m.use("cdr")
        return StubContext(
            name=self.scope.place(d).cls,
            scoped_name=d.scoped_name,
            doc=d.doc,
            repo_id=d.repo_id,
            bases=[self.scope.ref(b, m) for b in python_bases(d.bases)] or ["_rpc.Stub"],
            operations=self._operations(d, m, in_stub=True),
            schema=self.schema(d),
            nested=nested,
        )

    def skeleton(self, d: ast.Interface, m: ModuleContext) -> SkeletonContext:
        m.use("rpc")
        if d.operations or d.attributes:
            m.use("cdr", "abc")
        return SkeletonContext(
            name=self.scope.place(d).cls,
            scoped_name=d.scoped_name,
            doc=d.doc,
            repo_id=d.repo_id,
            bases=[self.scope.ref(b, m, poa=True) for b in python_bases(d.bases)]
            or ["_rpc.Servant"],
            operations=self._operations(d, m, in_stub=False),
            schema=self.schema(d),
        )

    def _operations(
        self, d: ast.Interface, m: ModuleContext, in_stub: bool
    ) -> list[OperationContext]:
        return [self._operation(s, m, in_stub) for s in _signatures(d, m)]

    def _operation(self, sig: _Signature, m: ModuleContext, in_stub: bool) -> OperationContext:
        """One method. The stub sends the arguments and receives the results; the skeleton
        the reverse. Both plan all four codecs (their locals are numbered in one sequence)."""
        inv = "self._invoker" if in_stub else "_inv"
        params: list[ParamContext] = []
        ins: list[Encoded] = []
        outs: list[Encoded] = []
        result_annotations: list[str] = []
        results: list[str] = []
        if sig.returns is not None:
            shape = self._shape(sig.returns, sig.pos)
            outs.append((shape, "_r", f"{sig.what} result"))
            results.append("_r")
            hint = self.hints.annotation(shape, m, in_op=True, sending=not in_stub)
            result_annotations.append(hint)
        for p in sig.params:
            shape = self._shape(p.type, p.pos)
            py = m.ambiguous(names.py_name(p.name, names.PARAMETER_NAMES), "E741")
            hint = self.hints.annotation(shape, m, in_op=True, sending=in_stub)
            params.append(ParamContext(py, hint, p.mode))
            if p.mode in ("in", "inout"):
                ins.append((shape, py, f"{sig.what}({p.name})"))
            if p.mode in ("out", "inout"):
                outs.append((shape, f"_o_{py}", f"{sig.what}({p.name})"))
                results.append(f"_o_{py}")
                hint = self.hints.annotation(shape, m, in_op=True, sending=not in_stub)
                result_annotations.append(hint)
        if not result_annotations:
            returns = "None"
        elif len(result_annotations) == 1:
            returns = result_annotations[0]
        else:
            returns = f"tuple[{', '.join(result_annotations)}]"
        planner = CodecPlanner(self.scope, self.hints, m)
        encode_in = planner.encode_members(ins, inv=inv)
        decode_in = _decode_into(planner, ins, inv)
        encode_out = planner.encode_members(outs, inv=inv)
        single = result_annotations[0] if len(outs) == 1 else ""
        decode_out = _decode_into(planner, outs, inv, single)
        return OperationContext(
            name=sig.name,
            wire=sig.wire,
            doc=sig.doc,
            oneway=sig.oneway,
            params=params,
            returns=returns,
            results=results,
            encode_in=encode_in,
            decode_in=decode_in,
            encode_out=encode_out,
            decode_out=decode_out,
            raises=[self.scope.ref(e, m) for e in sig.raises] if in_stub else [],
            what=sig.what,
        )


def _signatures(d: ast.Interface, m: ModuleContext) -> list[_Signature]:
    """The operations of an interface, then `_get_`/`_set_` accessors of its attributes."""
    out = []
    for op in d.operations:
        name = m.ambiguous(names.py_name(op.name, names.CLASS_BODY), "E743")
        what = f"{d.scoped_name}::{op.name}"
        out.append(
            _Signature(
                name, op.name, op.doc, op.oneway, op.params, op.returns, op.raises, what, op.pos
            )
        )
    for a in d.attributes:
        what = f"{d.scoped_name}::{a.name}"
        get, put = f"_get_{a.name}", f"_set_{a.name}"
        out.append(_Signature(get, get, a.doc, False, [], a.type, a.get_raises, what, a.pos))
        if not a.readonly:
            value = ast.Param("in", a.type, "value", a.pos)
            out.append(_Signature(put, put, a.doc, False, [value], None, a.set_raises, what, a.pos))
    return out


def _decode_into(
    planner: CodecPlanner, entries: list[Encoded], inv: str, annotation: str = ""
) -> list[DecodeStep]:
    """Decode values into the named variables (operation arguments and results); a single
    result gets its declared type (unpacked values are untyped)."""
    steps, values = planner.decode_members([(s, w) for s, _, w in entries], inv=inv)
    for (_, var, _), value in zip(entries, values, strict=True):
        steps.append(Assign(var=var, expr=value, annotation=annotation))
    return steps
