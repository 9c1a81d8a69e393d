"""Builds the Python back end's model (`model.py`) from a resolved IDL specification."""

from __future__ import annotations

import itertools
import re
from collections.abc import Callable, Iterator
from typing import Any

from miro_gen.codegen import names
from miro_gen.codegen.interface_schema import NoInterfaceSchema, interface_schema
from miro_gen.codegen.model import (
    Field,
    Item,
    Operation,
    Param,
    PyModule,
    Shape,
    Step,
    Unsupported,
    all_members,
    completed,
    const_literal,
    data_schema,
    min_size,
    shape_of,
    type_hash,
)
from miro_gen.diagnostics import SourcePos
from miro_gen.idl import ast
from miro_gen.runtime.cdr import default_discriminator

XCDR2_ANNOTATIONS = {"appendable", "mutable", "optional", "external"}


class Place:
    """Where a declaration lives in Python: module, class name, nesting."""

    __slots__ = ("cls", "idl_module", "module", "nesting", "poa_module")

    def __init__(self, idl_module: tuple[str, ...], nesting: int, decl: ast.Decl) -> None:
        self.idl_module = idl_module
        self.nesting = nesting
        stem = names.module_stem(decl.pos.path)
        self.module = f"{names.package_name(idl_module)}.{stem}"
        self.poa_module = f"{names.poa_package_name(idl_module)}.{stem}"
        self.cls = names.class_name(decl, nesting)


class Builder:
    """The generated modules of one IDL file (`main_file`) of a resolved specification."""

    def __init__(self, spec: ast.Specification, main_file: str, source: str) -> None:
        self.spec = spec
        self.main_file = main_file
        self.source = source
        module_paths = {d.scope_path for d in spec.declarations if isinstance(d, ast.Module)}
        self.places: dict[int, Place] = {}
        for d in spec.declarations:
            outer = d.scope_path[:-1]
            while outer and outer not in module_paths:
                outer = outer[:-1]
            self.places[id(d)] = Place(outer, len(d.scope_path) - 1 - len(outer), d)
        self.by_path = {
            d.scope_path: d for d in spec.declarations if not isinstance(d, ast.Forward)
        }
        self.modules: dict[str, PyModule] = {}
        self.m: PyModule = PyModule("", "", source, "")
        self._temps: Iterator[int] = itertools.count()
        # Class attributes each container gets for what is nested in it: (name, value).
        self.nested: dict[int, list[tuple[str, str]]] = {}
        self._in_stub = True

    # =========================================================================================
    def build(self) -> list[PyModule]:
        mine = [
            d
            for d in self.spec.declarations
            if d.pos.path == self.main_file and not isinstance(d, (ast.Module, ast.Forward))
        ]
        for d in self._nested_first(mine):
            self._declare(d)
        return sorted(self.modules.values(), key=lambda m: (m.package, m.stem))

    def _nested_first(self, decls: list[ast.Decl]) -> list[ast.Decl]:
        """Source order, except that declarations nested in an interface, struct or union come
        before their container (whose class refers to them)."""
        children: dict[tuple[str, ...], list[ast.Decl]] = {}
        top: list[ast.Decl] = []
        for d in decls:
            if self.places[id(d)].nesting and d.scope_path[:-1] in self.by_path:
                children.setdefault(d.scope_path[:-1], []).append(d)
            else:
                top.append(d)
        out: list[ast.Decl] = []

        def visit(d: ast.Decl) -> None:
            for c in children.get(d.scope_path, []):
                visit(c)
            out.append(d)

        for d in top:
            visit(d)
        return out

    def _ambiguous(self, name: str, code: str) -> str:
        """Note a name pycodestyle calls ambiguous (l, O, I): the module exempts itself from that
        rule (E741 variables, E742 classes, E743 functions) rather than rename IDL names."""
        if name in ("l", "O", "I"):
            self.m.noqa.add(code)
        return name

    def _module(self, place: Place, poa: bool = False) -> PyModule:
        name = place.poa_module if poa else place.module
        m = self.modules.get(name)
        if m is None:
            package, stem = name.rsplit(".", 1)
            m = PyModule(package, stem, self.source, "::".join(place.idl_module), poa=poa)
            self.modules[name] = m
        return m

    def _declare(self, d: ast.Decl) -> None:
        place = self.places[id(d)]
        self.m = self._module(place)
        handlers: dict[type, Callable[[Any], None]] = {
            ast.Enum: self._enum,
            ast.Struct: self._struct,
            ast.Union_: self._union,
            ast.Exception_: self._exception,
            ast.Typedef: self._typedef,
            ast.Const: self._const,
            ast.Interface: self._interface,
        }
        handler = handlers.get(type(d))
        if handler is None:
            what = {
                ast.Native: "native type",
                ast.ValueType: "value type",
                ast.ValueBox: "value box",
                ast.AnnotationDecl: None,
            }.get(type(d), d.kind)
            if what is None:
                return
            raise Unsupported(d.pos, f"{what} '{d.scoped_name}' cannot be generated for Python")
        handler(d)
        if place.nesting:
            self._nest(d, place)

    def _nest(self, d: ast.Decl, place: Place) -> None:
        """Make a nested declaration reachable as an attribute of its container class
        (containers are generated after what they contain)."""
        container = self.by_path.get(d.scope_path[:-1])
        if container is not None:
            self.nested.setdefault(id(container), []).append((names.py_name(d.name), place.cls))

    def _add(self, item: Item) -> Item:
        self._ambiguous(item.name, "E741" if item.kind in ("typedef", "const") else "E742")
        item.nested = self.nested.pop(id(item.decl), [])
        self.m.items.append(item)
        self.m.exports.append(item.name)
        return item

    # =========================================================================================
    # references
    # =========================================================================================
    def ref(self, decl: Any, poa: bool = False) -> str:
        """The Python expression for a declaration's class, from the current module."""
        decl = completed(decl)
        place = self.places.get(id(decl))
        if place is None:  # pragma: no cover - every declaration has a place
            raise Unsupported(decl.pos, f"no Python name for {decl.scoped_name}")
        module = place.poa_module if poa else place.module
        if module == self.m.name:
            return place.cls
        alias = names.module_alias(module)
        self.m.imports[module] = alias
        return f"{alias}.{place.cls}"

    def codec_ref(self, decl: Any, prefix: str) -> str:
        """`_enc_X` / `_dec_X` of a struct, union or exception (in the module of its class)."""
        cls_ref = self.ref(decl)
        head, _, tail = cls_ref.rpartition(".")
        return f"{head}.{prefix}{tail}" if head else f"{prefix}{tail}"

    def annotation(
        self, shape: Shape, use_alias: bool = True, in_op: bool = False, sending: bool = False
    ) -> str:
        """The type hint of a value. Object references inside an operation's arguments and
        results arrive as stubs, but as `ObjectRef` inside data types; so a typedef holding
        references is spelled out there rather than named (its alias says `ObjectRef`). What is
        being sent (a stub's arguments, a servant's results) may be any sequence, and for an
        object reference a local servant."""
        if use_alias and shape.alias is not None and not (in_op and _holds_object(shape)):
            return self.ref(shape.alias)
        k = shape.kind
        if k == "prim":
            return shape.prim.py  # type: ignore[union-attr]
        if k == "string":
            return "str"
        if k == "octets":
            return "bytes"
        if k in ("seq", "array"):
            inner = shape.elem if k == "seq" else _sub_array(shape)
            inner_ann = self.annotation(inner, in_op=in_op, sending=sending)  # type: ignore[arg-type]
            if sending:  # any sequence will do, and a list of stubs is one of stubs-or-servants
                self.m.uses.add("typing")
                return f"_t.Sequence[{inner_ann}]"
            return f"list[{inner_ann}]"
        if k in ("enum", "struct", "union", "exception"):
            return self.ref(shape.decl)
        if k == "object":
            if in_op:
                stub = self._stub_ref(shape)
                if sending:
                    self.m.uses.add("rpc")
                    return f"{stub} | _rpc.Servant | None"
                return f"{stub} | None"
            self.m.uses.add("cdr")
            return "_cdr.ObjectRef"
        raise AssertionError(k)  # pragma: no cover

    def _stub_ref(self, shape: Shape) -> str:
        decl = completed(shape.decl)
        if isinstance(decl, ast.Interface):
            return self.ref(decl)
        self.m.uses.add("rpc")
        return "_rpc.Stub"

    def default(self, shape: Shape) -> str:
        k = shape.kind
        if k == "prim":
            return f"= {shape.prim.default}"  # type: ignore[union-attr]
        if k == "string":
            return '= ""'
        if k == "octets":
            return '= b""'
        if k == "enum":
            first = shape.decl.enumerators[0]
            return f"= {self.ref(shape.decl)}.{_enumerator_name(first.name)}"
        if k in ("struct", "union", "exception"):
            return f"= _dc.field(default_factory={self.ref(shape.decl)})"
        if k == "seq":
            return "= _dc.field(default_factory=list)"
        if k == "array":
            return f"= _dc.field(default_factory=lambda: {self._array_value(shape)})"
        if k == "object":
            self.m.uses.add("cdr")
            return "= _cdr.ObjectRef()"
        raise AssertionError(k)  # pragma: no cover

    def _array_value(self, shape: Shape) -> str:
        elem = shape.elem
        assert elem is not None
        inner = _sub_array(shape)
        if inner.kind == "array":
            return f"[{self._array_value(inner)} for _ in range({shape.dims[0]})]"
        if elem.kind == "prim":
            return f"[{elem.prim.default}] * {shape.dims[0]}"  # type: ignore[union-attr]
        if elem.kind in ("string", "octets", "enum", "object"):
            return f"[{self.default(elem)[2:]}] * {shape.dims[0]}"
        if elem.kind == "seq":
            return f"[[] for _ in range({shape.dims[0]})]"
        return f"[{self.ref(elem.decl)}() for _ in range({shape.dims[0]})]"

    # =========================================================================================
    # declarations
    # =========================================================================================
    def _enum(self, d: ast.Enum) -> None:
        self.m.uses.add("enum")
        item = Item(
            "enum",
            self.places[id(d)].cls,
            d,
            doc=d.doc,
            repo_id=d.repo_id,
            scoped_name=d.scoped_name,
            enumerators=[
                (self._ambiguous(_enumerator_name(e.name), "E741"), e.ordinal, e.doc)
                for e in d.enumerators
            ],
        )
        self._add(item)
        # Enumerators belong to the scope enclosing the enum (CORBA): module constants, or
        # attributes of the enclosing interface/struct.
        place = self.places[id(d)]
        container = self.by_path.get(d.scope_path[:-1]) if place.nesting else None
        for name, _, _ in item.enumerators:
            if container is not None:
                self.nested.setdefault(id(container), []).append((name, f"{item.name}.{name}"))
            elif not place.nesting:
                self.m.exports.append(name)
                self.m.uses.add("typing")  # the module constant is `_t.Final`

    def _check_xcdr1(self, d: Any, members: list[Any]) -> None:
        for a in d.annotations:
            n = a.short_name
            value = a.params.get("value")
            if n in ("appendable", "mutable") or (
                n == "extensibility" and str(value).upper() in ("APPENDABLE", "MUTABLE")
            ):
                raise Unsupported(
                    a.pos,
                    f"'{d.scoped_name}' is @{n if n != 'extensibility' else str(value).lower()}: "
                    "XCDR2 encoding is not supported yet; only final (XCDR1) types",
                )
        for m in members:
            for a in m.annotations:
                if a.short_name in XCDR2_ANNOTATIONS and a.params.get("value", True) is not False:
                    raise Unsupported(
                        a.pos,
                        f"member '{m.name}' of '{d.scoped_name}' is @{a.short_name}: "
                        "XCDR2 encoding is not supported yet",
                    )

    def _fields(self, members: list[ast.Member], reserved: frozenset[str]) -> list[Field]:
        out = []
        for m in members:
            shape = shape_of(m.type, m.pos, m.dims)
            ann = self.annotation(shape) if not m.dims else self.annotation(shape, use_alias=False)
            name = self._ambiguous(names.py_name(m.name, reserved), "E741")
            out.append(Field(name, ann, self.default(shape), m.doc))
        return out

    def _struct(self, d: ast.Struct) -> None:
        self.m.uses.update(("dc", "cdr"))
        members = all_members(d)
        self._check_xcdr1(d, members)
        cls = self.places[id(d)].cls
        item = Item(
            "struct",
            cls,
            d,
            doc=d.doc,
            repo_id=d.repo_id,
            scoped_name=d.scoped_name,
            fields=self._fields(d.members, names.STRUCT_ATTRIBUTES),
            bases=[self.ref(d.base)] if d.base is not None else [],
        )
        self._codec(item, members, names.STRUCT_ATTRIBUTES)
        self._add(item)

    def _exception(self, d: ast.Exception_) -> None:
        self.m.uses.update(("dc", "cdr", "exc"))
        self._check_xcdr1(d, d.members)
        item = Item(
            "exception",
            self.places[id(d)].cls,
            d,
            doc=d.doc,
            repo_id=d.repo_id,
            scoped_name=d.scoped_name,
            fields=self._fields(d.members, names.EXCEPTION_ATTRIBUTES),
        )
        self._codec(item, d.members, names.EXCEPTION_ATTRIBUTES)
        self._add(item)

    def _codec(self, item: Item, members: list[ast.Member], reserved: frozenset[str]) -> None:
        self._temps = itertools.count()
        entries = [
            (
                shape_of(m.type, m.pos, m.dims),
                f"_v.{names.py_name(m.name, reserved)}",
                f"{item.scoped_name}.{m.name}",
            )
            for m in members
        ]
        item.encode = self.encode_members(entries)
        steps, values = self.decode_members([(s, w) for s, _, w in entries])
        item.decode = steps
        item.decode_call = item.name
        item.decode_args = self._construct(steps, values)
        item.schema = data_schema(item.decl)
        item.type_hash = type_hash(item.schema)

    def _construct(self, steps: list[Step], values: list[str]) -> list[str]:
        """The constructor arguments of a decoded value; one run of unconverted scalars is
        passed straight as the unpacked tuple."""
        if (
            len(steps) == 1
            and steps[0].kind == "unpack"
            and values == [f"{steps[0].var}[{i}]" for i in range(len(values))]
            and steps[0].count == len(values)
        ):
            return [f"*{steps[0].var}"]
        return values

    def _union(self, d: ast.Union_) -> None:
        self.m.uses.update(("cdr", "typing"))
        self._check_xcdr1(d, [])
        cls = self.places[id(d)].cls
        disc = shape_of(d.switch_type, d.pos)
        labels_of: dict[str, list[Any]] = {}
        branches: list[dict[str, Any]] = []
        default_branch = None
        used: set[Any] = set()
        for case in d.cases:
            name = self._ambiguous(names.py_name(case.name, names.STRUCT_ATTRIBUTES), "E743")
            shape = shape_of(case.type, case.pos, case.dims)
            values = [v for v in case.labels if v is not None]
            used.update(v.ordinal if isinstance(v, ast.EnumValue) else v for v in values)
            if None in case.labels:
                default_branch = name
            labels_of[name] = values
            branches.append(
                {
                    "name": name,
                    "annotation": self.annotation(shape)
                    if not case.dims
                    else self.annotation(shape, use_alias=False),
                    "labels": [self._label(v) for v in values],
                    "default": None in case.labels,
                    "zero": self._zero(shape),
                    "shape": shape,
                    "doc": case.doc,
                    "idl_name": case.name,
                }
            )
        # The discriminator the default branch gets, chosen as Cyclone DDS chooses it.
        default_d = "None"
        if default_branch is not None:
            if disc.kind == "enum":
                enumerators = disc.decl.enumerators
                i = default_discriminator("enum", used, len(enumerators))
                if i < len(enumerators):
                    default_d = f"{self.ref(disc.decl)}.{_enumerator_name(enumerators[i].name)}"
            else:
                default_d = repr(default_discriminator(disc.prim.idl, used))  # type: ignore[union-attr]
        item = Item("union", cls, d, doc=d.doc, repo_id=d.repo_id, scoped_name=d.scoped_name)
        item.union = {
            "branches": branches,
            "default_branch": default_branch,
            "default_discriminator": default_d,
            "discriminator": self.annotation(disc),
        }
        # codec
        self._temps = itertools.count()
        what = d.scoped_name
        enc: list[Step] = self.encode_members([(disc, "_v._d", f"{what} discriminator")])
        dec_steps, (disc_value,) = self.decode_members([(disc, f"{what} discriminator")])
        enc_branches: list[tuple[str, list[Step]]] = []
        dec_branches: list[tuple[str, list[Step]]] = []
        default_enc: list[Step] = []
        default_dec: list[Step] = []
        for b in branches:
            bwhat = f"{what}.{b['idl_name']}"
            e_steps = self.encode_value(b["shape"], "_v._v", bwhat, 1)
            d_steps = self.decode_value(b["shape"], "_x", bwhat, 1)
            if b["default"]:
                default_enc, default_dec = e_steps, d_steps
            if b["labels"]:
                cond = f"_d in ({', '.join(b['labels'])},)"
                enc_branches.append((cond, e_steps))
                dec_branches.append((cond, d_steps))
        item.encode = [
            *enc,
            Step(
                "union_branches",
                expr="_v._d",
                labels=enc_branches,
                body=default_enc,
                var="enc",
                what=what,
            ),
        ]
        item.decode = [
            *dec_steps,
            Step("assign", var="_d", expr=disc_value),
            Step("union_branches", labels=dec_branches, body=default_dec, var="dec"),
        ]
        item.decode_call = cls
        item.decode_args = ["_d", "_x"]
        item.schema = data_schema(d)
        item.type_hash = type_hash(item.schema)
        self._add(item)

    def _label(self, v: Any) -> str:
        if isinstance(v, ast.EnumValue):
            return f"{self.ref(v.enum)}.{_enumerator_name(v.name)}"
        return repr(v)

    def _zero(self, shape: Shape) -> str:
        default = self.default(shape)
        if "default_factory=" in default:
            return default.split("default_factory=", 1)[1][:-1]
        return f"lambda: {default[2:]}"

    def _typedef(self, d: ast.Typedef) -> None:
        shape = shape_of(d.type, d.pos, d.dims)
        target = self.annotation(shape, use_alias=not d.dims)
        later = self._refers_to_later(shape, d)
        self.m.uses.add("typing")
        self._add(
            Item(
                "typedef",
                self.places[id(d)].cls,
                d,
                doc=d.doc,
                value=target,
                quoted=later,
                scoped_name=d.scoped_name,
            )
        )

    def _refers_to_later(self, shape: Shape, d: ast.Decl) -> bool:
        """Whether a typedef names a class of its own module that is defined after it
        (recursive types through forward declarations): the alias must then be a string."""
        s: Shape | None = shape
        while s is not None and s.kind in ("seq", "array"):
            s = s.elem
        if s is None or s.kind not in ("struct", "union", "exception", "enum"):
            return False
        target = completed(s.decl)
        if self.places.get(id(target)) is None or self.places[id(target)].module != self.m.name:
            return False
        return all(item.decl is not target for item in self.m.items)

    def _const(self, d: ast.Const) -> None:
        self.m.uses.add("typing")
        v = d.value
        if isinstance(v, ast.EnumValue):
            value = f"{self.ref(v.enum)}.{_enumerator_name(v.name)}"
        else:
            value = const_literal(v)
            if "_decimal." in value:
                self.m.uses.add("decimal")
        self._add(
            Item(
                "const",
                self.places[id(d)].cls,
                d,
                doc=d.doc,
                value=value,
                scoped_name=d.scoped_name,
            )
        )

    # =========================================================================================
    # interfaces
    # =========================================================================================
    def _interface(self, d: ast.Interface) -> None:
        if not d.bases:
            self.m.uses.add("rpc")
        if d.operations or d.attributes:
            self.m.uses.add("cdr")
        place = self.places[id(d)]
        stub = Item(
            "stub",
            place.cls,
            d,
            doc=d.doc,
            repo_id=d.repo_id,
            scoped_name=d.scoped_name,
            bases=[self.ref(b) for b in d.bases] or ["_rpc.Stub"],
        )
        stub.operations = self._operations(d, in_stub=True)
        try:
            stub.schema = interface_schema(d, self.spec.declarations)
            stub.type_hash = type_hash(stub.schema)
        except NoInterfaceSchema:  # the service object cannot describe it to callers
            pass
        self._add(stub)
        # The skeleton, in the __POA package.
        main = self.m
        self.m = self._module(place, poa=True)
        self.m.uses.add("rpc")
        if d.operations or d.attributes:
            self.m.uses.update(("cdr", "abc"))
        skel = Item(
            "skeleton",
            place.cls,
            d,
            doc=d.doc,
            repo_id=d.repo_id,
            scoped_name=d.scoped_name,
            bases=[self.ref(b, poa=True) for b in d.bases] or ["_rpc.Servant"],
        )
        skel.operations = self._operations(d, in_stub=False)
        skel.schema, skel.type_hash = stub.schema, stub.type_hash
        self._add(skel)
        self.m = main

    def _operations(self, d: ast.Interface, in_stub: bool) -> list[Operation]:
        ops: list[Operation] = []
        inv = "self._invoker" if in_stub else "_inv"
        self._in_stub = in_stub
        for op in d.operations:
            ops.append(
                self._operation(
                    self._ambiguous(names.py_name(op.name, names.CLASS_BODY), "E743"),
                    op.name,
                    op.doc,
                    op.oneway,
                    [(p.mode, p.name, p.type, p.pos) for p in op.params],
                    op.returns,
                    op.raises,
                    f"{d.scoped_name}::{op.name}",
                    op.pos,
                    inv,
                )
            )
        for a in d.attributes:
            ops.append(
                self._operation(
                    f"_get_{a.name}",
                    f"_get_{a.name}",
                    a.doc,
                    False,
                    [],
                    a.type,
                    a.get_raises,
                    f"{d.scoped_name}::{a.name}",
                    a.pos,
                    inv,
                )
            )
            if not a.readonly:
                ops.append(
                    self._operation(
                        f"_set_{a.name}",
                        f"_set_{a.name}",
                        a.doc,
                        False,
                        [("in", "value", a.type, a.pos)],
                        None,
                        a.set_raises,
                        f"{d.scoped_name}::{a.name}",
                        a.pos,
                        inv,
                    )
                )
        return ops

    def _operation(
        self,
        name: str,
        wire: str,
        doc: str | None,
        oneway: bool,
        params: list[tuple[str, str, Any, SourcePos]],
        returns: Any,
        raises: list[ast.Exception_],
        what: str,
        pos: SourcePos,
        inv: str,
    ) -> Operation:
        self._temps = itertools.count()
        py_params: list[Param] = []
        ins: list[tuple[Shape, str, str]] = []
        outs: list[tuple[Shape, str, str]] = []
        result_annotations: list[str] = []
        results: list[str] = []
        if returns is not None:
            shape = shape_of(returns, pos)
            outs.append((shape, "_r", f"{what} result"))
            results.append("_r")
            result_annotations.append(self.annotation(shape, in_op=True, sending=not self._in_stub))
        for mode, pname, ptype, ppos in params:
            shape = shape_of(ptype, ppos)
            py = self._ambiguous(names.py_name(pname, names.PARAMETER_NAMES), "E741")
            ann = self.annotation(shape, in_op=True, sending=self._in_stub)
            py_params.append(Param(py, ann, mode))
            if mode in ("in", "inout"):
                ins.append((shape, py, f"{what}({pname})"))
            if mode in ("out", "inout"):
                outs.append((shape, f"_o_{py}", f"{what}({pname})"))
                results.append(f"_o_{py}")
                result_annotations.append(
                    self.annotation(shape, in_op=True, sending=not self._in_stub)
                )
        if not result_annotations:
            ret = "None"
        elif len(result_annotations) == 1:
            ret = result_annotations[0]
        else:
            ret = f"tuple[{', '.join(result_annotations)}]"
        return Operation(
            name=name,
            wire=wire,
            doc=doc,
            oneway=oneway,
            params=py_params,
            returns=ret,
            results=results,
            encode_in=self.encode_members(ins, inv=inv),
            decode_in=self._decode_into(ins, inv),
            encode_out=self.encode_members(outs, inv=inv),
            decode_out=self._decode_into(
                outs, inv, result_annotations[0] if len(outs) == 1 else ""
            ),
            raises=[self.ref(e) for e in raises] if self._in_stub else [],
            what=what,
        )

    def _decode_into(
        self, entries: list[tuple[Shape, str, str]], inv: str, annotation: str = ""
    ) -> list[Step]:
        """Decode values into the named variables (operation arguments and results); a single
        result gets its declared type (unpacked values are untyped)."""
        steps, values = self.decode_members([(s, w) for s, _, w in entries], inv=inv)
        for (_, var, _), value in zip(entries, values, strict=True):
            steps.append(Step("assign", var=var, expr=value, annotation=annotation))
        return steps

    # =========================================================================================
    # codecs
    # =========================================================================================
    def _temp(self, prefix: str) -> str:
        return f"_{prefix}{next(self._temps)}"

    def _struct_var(self, fmt: str) -> str:
        var = self.m.structs.get(fmt)
        if var is None:
            var = f"_S{len(self.m.structs)}"
            self.m.structs[fmt] = var
        return var

    def _runs(self, shapes: list[Shape]) -> list[tuple[int, ...] | int]:
        """Group consecutive fixed-size values into runs whose internal padding is static:
        a run starts aligned to its first value, and takes only values aligned no stricter."""
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

    def _layout(self, shapes: list[Shape]) -> tuple[str, int, list[tuple[int, int]]]:
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

    def encode_members(
        self, entries: list[tuple[Shape, str, str]], inv: str | None = None
    ) -> list[Step]:
        """Encode `(shape, expression, what)` values in order."""
        steps: list[Step] = []
        for group in self._runs([s for s, _, _ in entries]):
            if isinstance(group, int):
                shape, expr, what = entries[group]
                steps += self.encode_value(shape, expr, what, 1, inv)
                continue
            shapes = [entries[i][0] for i in group]
            fmt, size, _ = self._layout(shapes)
            items = [self._pack_expr(*entries[i]) for i in group]
            checks = [
                (entries[i][2], _item_format(entries[i][0]), _thunk(item))
                for i, item in zip(group, items, strict=True)
            ]
            steps.append(
                Step(
                    "pack",
                    align=shapes[0].unit.size,
                    codec=self._struct_var(fmt)[2:],
                    items=items,
                    size=size,
                    what=entries[group[0]][2],
                    checks=checks,
                )
            )
        return steps

    def _pack_expr(self, shape: Shape, expr: str, what: str) -> str:
        if shape.kind == "enum":
            return f"{self._enum_wire(shape.decl)}[{expr}]"
        if shape.kind != "array":
            return f"{shape.prim.to_wire}({expr})" if shape.prim and shape.prim.to_wire else expr
        elem = shape.elem
        assert elem is not None
        if elem.kind == "enum":
            to_wire: str | None = f"{self._enum_wire(elem.decl)}.__getitem__"
        else:
            to_wire = elem.prim.to_wire if elem.prim else None
        if len(shape.dims) == 1 and not to_wire:
            return f"*{expr}"
        conv = f", {to_wire}" if to_wire else ""
        return f"*_cdr.flatten({expr}, {shape.dims}, {what!r}{conv})"

    def decode_members(
        self, entries: list[tuple[Shape, str]], inv: str | None = None
    ) -> tuple[list[Step], list[str]]:
        """Decode `(shape, what)` values in order; the steps and an expression for each."""
        steps: list[Step] = []
        values: list[str] = [""] * len(entries)
        for group in self._runs([s for s, _ in entries]):
            if isinstance(group, int):
                shape, what = entries[group]
                var = self._temp("f")
                steps += self.decode_value(shape, var, what, 1, inv)
                values[group] = var
                continue
            shapes = [entries[i][0] for i in group]
            fmt, size, positions = self._layout(shapes)
            tup = self._temp("t")
            steps.append(
                Step(
                    "unpack",
                    var=tup,
                    align=shapes[0].unit.size,
                    codec=self._struct_var(fmt)[2:],
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
                part = f"_cdr.enums({self._enum_table(elem.decl)}, {part}, {what!r})"
            elif elem.prim is not None and elem.prim.from_wire:
                part = f"list(map({elem.prim.from_wire}, {part}))"
            else:
                part = f"list({part})"
            if len(shape.dims) > 1:
                return f"_cdr.reshape({part}, {shape.dims})"
            return part
        value = f"{tup}[{first}]"
        if shape.kind == "enum":
            return f"_cdr.enum_value({self._enum_table(shape.decl)}, {value}, {what!r})"
        if shape.prim is not None and shape.prim.from_wire:
            return f"{shape.prim.from_wire}({value})"
        return value

    def _enum_table(self, decl: Any, suffix: str = "T") -> str:
        """The tuple of an enum's members by ordinal (`_E_T`), or with suffix "W" the dict that
        checks a value is one of its ordinals before it is encoded (`_E_W`)."""
        cls = self.ref(decl)
        head, _, tail = cls.rpartition(".")
        return f"{head}._{tail}_{suffix}" if head else f"_{tail}_{suffix}"

    def _enum_wire(self, decl: Any) -> str:
        return self._enum_table(decl, "W")

    def _flat(self, shape: Shape) -> tuple[str, str, int, int] | None:
        """A struct whose members are all one numeric primitive: sequences of it move in bulk.
        (getter variable, array code, element size, members per element)"""
        if shape.kind != "struct":
            return None
        members = all_members(shape.decl)
        if not members:
            return None
        prims = set()
        for m in members:
            s = shape_of(m.type, m.pos, m.dims)
            if s.kind != "prim" or s.prim is None or s.prim.array is None:
                return None
            prims.add(s.prim.code)
        if len(prims) != 1:
            return None
        prim = shape_of(members[0].type, members[0].pos).prim
        assert prim is not None and prim.array is not None
        attrs = tuple(names.py_name(m.name, names.STRUCT_ATTRIBUTES) for m in members)
        var = f"_G_{self.ref(shape.decl).replace('.', '_')}"
        self.m.getters[var] = attrs
        self.m.uses.add("operator")
        return var, prim.array, prim.size, len(members)

    def encode_value(
        self, shape: Shape, expr: str, what: str, depth: int, inv: str | None = None
    ) -> list[Step]:
        k = shape.kind
        if shape.fixed:
            return self.encode_members([(shape, expr, what)])
        if k == "string":
            return [Step("put_string", expr=expr, bound=shape.bound, what=what)]
        if k == "octets":
            return [Step("put_octets", expr=expr, bound=shape.bound, what=what)]
        if k == "object":
            value = f"_rpc.to_ref({expr}, {inv})" if inv else expr
            if inv:
                self.m.uses.add("rpc")
            return [Step("put_object", expr=value, what=what)]
        if k in ("struct", "union", "exception"):
            codec = self.codec_ref(shape.decl, "_enc_")
            return [Step("call_enc", expr=expr, codec=codec, what=what)]
        if k == "seq":
            elem = shape.elem
            assert elem is not None
            if elem.kind == "enum":
                return [
                    Step(
                        "put_enums",
                        expr=expr,
                        codec=self._enum_wire(elem.decl),
                        bound=shape.bound,
                        what=what,
                    )
                ]
            if elem.kind == "prim" and elem.prim and elem.prim.array:
                u = elem.unit
                return [
                    Step(
                        "put_prims",
                        expr=expr,
                        code=u.array or "I",
                        size=u.size,
                        bound=shape.bound,
                        what=what,
                    )
                ]
            if elem.kind == "prim" and elem.prim is not None:
                kind = "put_booleans" if elem.prim.idl == "boolean" else "put_chars"
                return [Step(kind, expr=expr, bound=shape.bound, what=what)]
            flat = self._flat(elem)
            if flat is not None:
                getter, code, size, count = flat
                return [
                    Step(
                        "put_flat",
                        expr=expr,
                        codec=getter,
                        code=code,
                        size=size,
                        count=count,
                        bound=shape.bound,
                        what=what,
                    )
                ]
            var = self._temp("x")
            return [
                Step(
                    "put_seq",
                    expr=expr,
                    bound=shape.bound,
                    what=what,
                    var=var,
                    body=self.encode_value(elem, var, what, depth + 1, inv),
                )
            ]
        if k == "array":
            var = self._temp("x")
            inner = _sub_array(shape)
            return [
                Step(
                    "put_array",
                    expr=expr,
                    count=shape.dims[0],
                    what=what,
                    var=var,
                    body=self.encode_value(inner, var, what, depth + 1, inv),
                )
            ]
        raise AssertionError(k)  # pragma: no cover

    def decode_value(
        self, shape: Shape, var: str, what: str, depth: int, inv: str | None = None
    ) -> list[Step]:
        k = shape.kind
        if shape.fixed:
            steps, (value,) = self.decode_members([(shape, what)])
            return [*steps, Step("assign", var=var, expr=value)]
        if k == "string":
            return [Step("get_string", var=var, bound=shape.bound, what=what)]
        if k == "octets":
            return [Step("get_octets", var=var, bound=shape.bound, what=what)]
        if k == "object":
            steps = [Step("get_object", var=var, what=what)]
            if inv:
                self.m.uses.add("rpc")
                stub = self._stub_ref(shape)
                steps.append(Step("assign", var=var, expr=f"_rpc.make_stub({stub}, {var}, {inv})"))
            return steps
        if k in ("struct", "union", "exception"):
            return [Step("call_dec", var=var, codec=self.codec_ref(shape.decl, "_dec_"))]
        if k == "seq":
            elem = shape.elem
            assert elem is not None
            if elem.kind == "enum":
                return [
                    Step("get_prims", var=var, code="I", size=4, bound=shape.bound, what=what),
                    Step(
                        "assign",
                        var=var,
                        expr=f"_cdr.enums({self._enum_table(elem.decl)}, {var}, {what!r})",
                    ),
                ]
            if elem.kind == "prim" and elem.prim and elem.prim.array:
                return [
                    Step(
                        "get_prims",
                        var=var,
                        code=elem.prim.array,
                        size=elem.prim.size,
                        bound=shape.bound,
                        what=what,
                    )
                ]
            if elem.kind == "prim" and elem.prim is not None:
                kind = "get_booleans" if elem.prim.idl == "boolean" else "get_chars"
                return [Step(kind, var=var, bound=shape.bound, what=what)]
            flat = self._flat(elem)
            if flat is not None:
                _, code, size, count = flat
                return [
                    Step(
                        "get_flat",
                        var=var,
                        codec=self.ref(elem.decl),
                        code=code,
                        size=size,
                        count=count,
                        bound=shape.bound,
                        what=what,
                    )
                ]
            item = self._temp("x")
            return [
                Step(
                    "get_seq",
                    var=var,
                    bound=shape.bound,
                    size=min_size(elem),
                    what=what,
                    expr=item,
                    count=next(self._temps),
                    body=self.decode_value(elem, item, what, depth + 1, inv),
                )
            ]
        if k == "array":
            item = self._temp("x")
            inner = _sub_array(shape)
            return [
                Step(
                    "get_array",
                    var=var,
                    count=shape.dims[0],
                    expr=item,
                    what=what,
                    body=self.decode_value(inner, item, what, depth + 1, inv),
                )
            ]
        raise AssertionError(k)  # pragma: no cover


def _thunk(expr: str) -> str:
    """A lambda giving the wire values of a packed expression. It is called at once, so the
    late binding of loop variables that ruff's B023 warns about cannot bite."""
    noqa = "  # noqa: B023" if re.search(r"\b_x\d+\b", expr) else ""
    return f"lambda: ({expr},)),{noqa}"


def _item_format(shape: Shape) -> str:
    """The struct format of one packed value ("h", "3i")."""
    n = shape.count if shape.kind == "array" else 1
    return f"{n}{shape.unit.code}" if n > 1 else shape.unit.code


def _holds_object(shape: Shape) -> bool:
    """Whether a value of this shape is, or is a list of, object references."""
    s: Shape | None = shape
    while s is not None and s.kind in ("seq", "array"):
        s = s.elem
    return s is not None and s.kind == "object"


def _sub_array(shape: Shape) -> Shape:
    """The element of an array's first dimension (a smaller array, or the element type)."""
    assert shape.elem is not None
    if len(shape.dims) > 1:
        return Shape("array", elem=shape.elem, dims=shape.dims[1:])
    return shape.elem


_ENUM_RESERVED = frozenset(["name", "value", "mro"])


def _enumerator_name(name: str) -> str:
    return names.py_name(name, _ENUM_RESERVED)
