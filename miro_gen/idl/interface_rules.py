"""Interfaces and value types in the resolver: forward declarations and their completion,
inheritance (bases, `supports`, clashes between what is inherited), operations, attributes,
factories and state members, and the rule that an unconstrained interface passes no local
type (CORBA 3.0 sections 3.8 and 3.9).

`InterfaceRules` is the resolver's fourth layer, on `TypeRules`; the bodies of interfaces and
value types are resolved by the resolver's `_definitions`."""

from __future__ import annotations

import re
from typing import Any

from miro_gen.diagnostics import Diagnostics, SourcePos
from miro_gen.idl import ast
from miro_gen.idl.scopes import Entry, Frame, Scope
from miro_gen.idl.type_queries import all_bases, article, completed, local_type, unalias
from miro_gen.idl.type_rules import TypeRules

_CONTEXT_ID = re.compile(r"[A-Za-z][A-Za-z0-9._]*\*?$")


class InterfaceRules(TypeRules):
    """Resolves forward declarations, interfaces and value types and what they contain."""

    def __init__(self, diag: Diagnostics, case_sensitive: bool = False) -> None:
        super().__init__(diag, case_sensitive)
        self._decl_scopes: dict[int, Scope] = {}  # id(interface/valuetype) -> its scope
        self._scope_owners: dict[int, Any] = {}  # id(scope) -> interface/valuetype
        self._inherited: dict[int, dict[str, tuple[str, Any, ast.Decl]]] = {}
        self.saw_local = False  # a local interface was declared (forward declarations too)

    def _definitions(self, defs: list[Any], scope: Scope, frame: Frame) -> None:
        """Resolve the definitions of a body (the resolver's)."""
        raise NotImplementedError  # pragma: no cover - miro_gen.idl.resolver.Resolver

    def _forward(self, f: ast.Forward, scope: Scope, frame: Frame) -> None:
        self._annotations(f.annotations, scope)
        self.saw_local |= f.local
        key = self._fold(f.name)
        existing = scope.entries.get(key)
        kind_word = {
            "interface": "interface",
            "struct": "struct",
            "union": "union",
            "valuetype": "valuetype",
        }[f.of]
        if existing is not None:
            node = existing.node
            if isinstance(node, ast.BaseType) and f.of == "interface" and existing.name == f.name:
                # TAO's ORB IDL forward-declares the pseudo-objects it uses (`interface
                # TypeCode;` in module CORBA): that names the built-in, which stays as it is.
                return
            compatible = (
                (isinstance(node, ast.Forward) and node.of == f.of)
                or (f.of == "interface" and isinstance(node, ast.Interface))
                or (f.of == "struct" and isinstance(node, ast.Struct))
                or (f.of == "union" and isinstance(node, ast.Union_))
                or (f.of == "valuetype" and isinstance(node, ast.ValueType))
            )
            if not compatible or existing.name != f.name:
                self._clash(f.pos, f"forward {kind_word}", f.name, existing)
                return
            if isinstance(node, ast.Forward):
                if (node.abstract, node.local) != (f.abstract, f.local):
                    self.diag.error(
                        f.pos, f"forward declaration of '{f.name}' does not match the earlier one"
                    )
                f.full = node.full
            else:
                f.full = node
                self._check_forward_flags(f, node)
            self._register(f, scope, frame)
            if f.full is None:
                self.forwards.append(f)
            return
        entry = self._declare(scope, f.name, f.pos, f"forward {kind_word}", f)
        self._register(f, scope, frame)
        if entry is not None:
            self.forwards.append(f)

    def _check_forward_flags(self, f: ast.Forward, full: ast.Decl) -> None:
        if isinstance(full, (ast.Interface, ast.ValueType)):
            local = getattr(full, "local", False)
            if f.abstract != full.abstract or f.local != local:
                qual = "abstract " if full.abstract else "local " if local else ""
                self.diag.error(
                    f.pos,
                    f"'{f.name}' is forward-declared differently from its definition "
                    f"({qual or 'plain '}{f.of})",
                )

    def _complete_forwards(self, scope: Scope, decl: ast.Decl, of: str) -> Entry | None:
        """Declare a full definition, completing earlier forward declarations of it."""
        key = self._fold(decl.name)
        existing = scope.entries.get(key)
        what = {
            "interface": "interface",
            "struct": "struct",
            "union": "union",
            "valuetype": "valuetype",
        }[of]
        if (
            existing is not None
            and isinstance(existing.node, ast.Forward)
            and existing.node.of == of
            and existing.node.full is None
        ):
            if existing.name != decl.name:
                self._clash(decl.pos, what, decl.name, existing)
                return None
            for fwd in self.forwards:
                if (
                    fwd.of == of
                    and fwd.full is None
                    and fwd.scope_path[:-1] == scope.path
                    and fwd.name == decl.name
                ):
                    fwd.full = decl
                    self._check_forward_flags(fwd, decl)
            entry = Entry(decl.name, what, decl.pos, decl)
            scope.entries[key] = entry
            return entry
        return self._declare(scope, decl.name, decl.pos, what, decl)

    def _interface(self, i: ast.Interface, scope: Scope, frame: Frame) -> None:
        self._annotations(i.annotations, scope)
        entry = self._complete_forwards(scope, i, "interface")
        self._register(i, scope, frame)
        inner = self._new_scope("interface", i.name, scope)
        if entry is not None:
            entry.scope = inner
        # Bases
        seen: set[int] = set()
        for bname in i.base_names:
            b = self.lookup(bname, scope)
            if b is None:
                continue
            node = self._aliased(b.node)
            if isinstance(node, ast.Forward) and node.of == "interface":
                if node.full is None:
                    self.diag.error(
                        bname.pos,
                        f"cannot inherit from '{bname}': "
                        "it is forward-declared but not yet defined",
                    )
                    continue
                node = node.full
            if not isinstance(node, ast.Interface):
                self.diag.error(bname.pos, f"'{bname}' is {article(b.what)}, not an interface")
                self.diag.note(b.pos, f"'{b.name}' declared here")
                continue
            if id(node) in seen:
                self.diag.error(
                    bname.pos, f"'{bname}' is listed more than once as a base of '{i.name}'"
                )
                continue
            if node is i:
                self.diag.error(bname.pos, f"interface '{i.name}' cannot inherit from itself")
                continue
            seen.add(id(node))
            if i.abstract and not node.abstract:
                self.diag.error(
                    bname.pos,
                    f"abstract interface '{i.name}' can only inherit from abstract interfaces",
                )
            if node.local and not i.local:
                self.diag.error(
                    bname.pos,
                    f"unconstrained interface '{i.name}' cannot inherit from "
                    f"local interface '{bname}'",
                )
            i.bases.append(node)
            i.base_refs.append(b.node)
            base_scope = self._scope_of(node)
            if base_scope is not None:
                inner.bases.append(base_scope)
        self._decl_scopes[id(i)] = inner
        self._scope_owners[id(inner)] = i
        self._check_inherited_clashes(i)
        sub = self._frame_for(inner, i, frame)
        self._definitions(i.body, inner, sub)
        if i.local:
            self.saw_local = True
        elif self.saw_local:  # most files have no local interfaces: nothing to check
            self._check_no_local_types(i)

    def _check_no_local_types(self, i: ast.Interface) -> None:
        """An unconstrained interface's operations cannot pass local types (CORBA 3.0 section
        3.8.6): they cannot be marshalled."""
        where = f"in unconstrained interface '{i.name}',"
        for a in i.attributes:
            if (local := local_type(a.type)) is not None:
                self.diag.error(a.pos, f"{where} attribute '{a.name}' has local type '{local}'")
        for op in i.operations:
            if (local := local_type(op.returns)) is not None:
                self.diag.error(
                    op.pos, f"{where} operation '{op.name}' has local return type '{local}'"
                )
            for p in op.params:
                if (local := local_type(p.type)) is not None:
                    self.diag.error(
                        p.pos,
                        f"{where} parameter '{p.name}' of operation '{op.name}' has local "
                        f"type '{local}'",
                    )
            for e in op.raises:
                if (local := local_type(e)) is not None:
                    self.diag.error(
                        op.pos, f"{where} operation '{op.name}' raises local exception '{local}'"
                    )

    def _aliased(self, node: Any) -> Any:
        """What a base or `supports` name denotes through typedefs (`typedef I J;
        interface K : J {};` inherits I, as omniidl accepts)."""
        if isinstance(node, ast.Typedef) and not node.dims:
            target = unalias(node)
            if isinstance(target, (ast.Interface, ast.ValueType, ast.Forward)):
                return target
        return node

    def _scope_of(self, decl: ast.Decl) -> Scope | None:
        return self._decl_scopes.get(id(decl))

    def _all_callables(
        self, iface: ast.Interface | ast.ValueType
    ) -> list[tuple[str, Any, ast.Decl]]:
        """Operations and attributes of `iface` and all its bases: (name, node, owner)."""
        out: list[tuple[str, Any, ast.Decl]] = []
        seen: set[int] = set()
        todo: list[Any] = [iface]
        while todo:
            x = todo.pop(0)
            if id(x) in seen:
                continue
            seen.add(id(x))
            for op in x.operations:
                out.append((op.name, op, x))
            for at in x.attributes:
                out.append((at.name, at, x))
            todo.extend(x.bases)
            if isinstance(x, ast.ValueType):
                todo.extend(x.supports)
        return out

    def _check_inherited_clashes(self, i: ast.Interface | ast.ValueType) -> None:
        names: dict[str, tuple[str, Any, ast.Decl]] = {}
        for b in [*i.bases, *(i.supports if isinstance(i, ast.ValueType) else [])]:
            for name, node, owner in self._all_callables(b):
                key = self._fold(name)
                prev = names.get(key)
                if prev is not None and prev[1] is not node:
                    self.diag.error(
                        i.pos,
                        f"'{i.name}' inherits '{prev[0]}' from '{prev[2].scoped_name}' and "
                        f"'{name}' from '{owner.scoped_name}'; inherited operations and attributes "
                        "may not clash",
                    )
                    continue
                names[key] = (name, node, owner)
        self._inherited[id(i)] = names

    def _check_not_inherited(self, owner: Any, name: str, pos: SourcePos, what: str) -> None:
        inherited = self._inherited.get(id(owner), {})
        prev = inherited.get(self._fold(name))
        if prev is not None:
            self.diag.error(
                pos,
                f"{what} '{name}' clashes with '{prev[0]}' inherited from '{prev[2].scoped_name}'",
            )

    def _operation(self, op: ast.Operation, scope: Scope, frame: Frame) -> None:
        owner = self._owner(scope)
        self._annotations(op.annotations, scope)
        self._declare(scope, op.name, op.pos, "operation", op)
        self._check_not_inherited(owner, op.name, op.pos, "operation")
        op_scope = self._new_scope("operation", op.name, scope)
        if op.returns is not None:
            op.returns = self._type(op.returns, scope, "return type")
        for p in op.params:
            self._annotations(p.annotations, op_scope)
            p.type = self._type(p.type, op_scope, "parameter type")
            self._declare(op_scope, p.name, p.pos, "parameter", p)
        op.raises = self._exceptions(op.raises_names, scope)
        for ctx in op.contexts:
            if not _CONTEXT_ID.match(ctx):
                self.diag.error(op.pos, f"invalid context identifier '{ctx}'")
        if op.oneway:
            if op.returns is not None:
                self.diag.error(op.pos, f"oneway operation '{op.name}' must return void")
            for p in op.params:
                if p.mode != "in":
                    self.diag.error(
                        p.pos,
                        f"oneway operation '{op.name}' cannot have {p.mode} parameter '{p.name}'",
                    )
            if op.raises_names:
                self.diag.error(op.pos, f"oneway operation '{op.name}' cannot raise exceptions")
        if owner is not None:
            owner.operations.append(op)

    def _owner(self, scope: Scope) -> Any:
        return self._scope_owners.get(id(scope))

    def _attribute_group(self, g: ast.AttributeGroup, scope: Scope, frame: Frame) -> None:
        owner = self._owner(scope)
        self._annotations(g.annotations, scope)
        typ = self._type(g.type, scope, "attribute type")
        get_raises = self._exceptions(g.get_raises_names, scope)
        set_raises = self._exceptions(g.set_raises_names, scope)
        for i, (name, pos) in enumerate(g.names):
            attr = ast.Attribute(
                name,
                pos,
                typ,
                g.readonly,
                g.get_raises_names,
                g.set_raises_names,
                annotations=g.annotations,
                doc=g.doc if i == 0 else None,
                get_raises=get_raises,
                set_raises=set_raises,
            )
            self._declare(scope, name, pos, "attribute", attr)
            self._check_not_inherited(owner, name, pos, "attribute")
            if owner is not None:
                owner.attributes.append(attr)

    def _exceptions(self, names: list[ast.ScopedName], scope: Scope) -> list[ast.Exception_]:
        out: list[ast.Exception_] = []
        for n in names:
            e = self.lookup(n, scope)
            if e is None:
                continue
            if not isinstance(e.node, ast.Exception_):
                self.diag.error(n.pos, f"'{n}' is {article(e.what)}, not an exception")
                continue
            out.append(e.node)
        return out

    def _valuetype(self, v: ast.ValueType, scope: Scope, frame: Frame) -> None:
        self._annotations(v.annotations, scope)
        entry = self._complete_forwards(scope, v, "valuetype")
        self._register(v, scope, frame)
        inner = self._new_scope("valuetype", v.name, scope)
        if entry is not None:
            entry.scope = inner
        for k, bname in enumerate(v.base_names):
            b = self.lookup(bname, scope)
            if b is None:
                continue
            node = completed(self._aliased(b.node))
            if not isinstance(node, ast.ValueType):
                self.diag.error(bname.pos, f"'{bname}' is {article(b.what)}, not a value type")
                continue
            if k > 0 and not node.abstract:
                self.diag.error(
                    bname.pos, f"only the first base of '{v.name}' may be a concrete value type"
                )
            if v.abstract and not node.abstract:
                self.diag.error(
                    bname.pos,
                    f"abstract value type '{v.name}' can only inherit abstract value types",
                )
            v.bases.append(node)
            v.base_refs.append(b.node)
            s = self._scope_of(node)
            if s is not None:
                inner.bases.append(s)
        if v.truncatable and (not v.bases or v.bases[0].abstract):
            self.diag.error(v.pos, f"'{v.name}' is truncatable but has no concrete base value type")
        if v.truncatable and v.custom:
            self.diag.error(v.pos, f"custom value type '{v.name}' cannot be truncatable")
        if not v.custom and not v.abstract:
            for base in v.bases:
                if base.custom:
                    self.diag.error(
                        v.pos,
                        f"value type '{v.name}' is not custom but inherits custom value type "
                        f"'{base.scoped_name}'",
                    )
        for sname in v.supports_names:
            s_entry = self.lookup(sname, scope)
            if s_entry is None:
                continue
            node = completed(self._aliased(s_entry.node))
            if not isinstance(node, ast.Interface):
                self.diag.error(
                    sname.pos, f"'{sname}' is {article(s_entry.what)}, not an interface"
                )
                continue
            if not node.abstract and v.supports:
                self.diag.error(
                    sname.pos,
                    f"value type '{v.name}' cannot support '{sname}' here: a value type supports "
                    "at most one non-abstract interface, and it comes first",
                )
                continue
            if not node.abstract:
                self._check_supported_derives(v, node, sname.pos)
            v.supports.append(node)
            v.supports_refs.append(s_entry.node)
            s = self._scope_of(node)
            if s is not None:
                inner.bases.append(s)
        self._decl_scopes[id(v)] = inner
        self._scope_owners[id(inner)] = v
        self._check_inherited_clashes(v)
        sub = self._frame_for(inner, v, frame)
        self._definitions(v.body, inner, sub)

    def _check_supported_derives(
        self, v: ast.ValueType, iface: ast.Interface, pos: SourcePos
    ) -> None:
        """The non-abstract interface a value type supports must derive from the one its base
        value types support (CORBA 3.0 section 3.9.1.4), as omniidl checks."""
        for base in v.bases:
            b: ast.ValueType | None = base
            while b is not None and not b.supports:
                b = b.bases[0] if b.bases else None
            if b is None or b.supports[0].abstract:
                continue
            inherited = b.supports[0]
            if inherited is not iface and inherited not in all_bases(iface):
                self.diag.error(
                    pos,
                    f"value type '{v.name}' supports '{iface.scoped_name}', which does not "
                    f"derive from '{inherited.scoped_name}', supported by its base "
                    f"'{base.scoped_name}'",
                )

    def _state_members(self, g: ast.StateMemberGroup, scope: Scope, frame: Frame) -> None:
        owner = self._owner(scope)
        self._annotations(g.annotations, scope)
        typ = self._type(g.type, scope, "state member type", frame=frame)
        for i, (name, pos, dims) in enumerate(g.declarators):
            m = ast.Member(
                name,
                typ,
                dims,
                pos,
                list(g.annotations),
                doc=g.doc if i == 0 else None,
                public=g.public,
            )
            m.dims = self._dims(dims, scope)
            if self.saw_local and (local := local_type(typ)) is not None:
                self.diag.error(pos, f"state member '{name}' has local type '{local}'")
            self._declare(scope, name, pos, "state member", m)
            if owner is not None:
                owner.members.append(m)

    def _factory(self, f: ast.Factory, scope: Scope, frame: Frame) -> None:
        owner = self._owner(scope)
        self._annotations(f.annotations, scope)
        self._declare(scope, f.name, f.pos, "factory", f)
        f_scope = self._new_scope("operation", f.name, scope)
        for p in f.params:
            p.type = self._type(p.type, f_scope, "parameter type")
            self._declare(f_scope, p.name, p.pos, "parameter", p)
        f.raises = self._exceptions(f.raises_names, scope)
        if owner is not None:
            owner.factories.append(f)

    def _valuebox(self, v: ast.ValueBox, scope: Scope, frame: Frame) -> None:
        self._annotations(v.annotations, scope)
        self._declare(scope, v.name, v.pos, "value box", v)
        self._register(v, scope, frame)
        v.type = self._type(v.type, scope, "boxed type", frame=frame)
        target = unalias(v.type)
        if isinstance(target, (ast.ValueType, ast.ValueBox)):
            self.diag.error(v.pos, f"value box '{v.name}' cannot box a value type")
