"""IDL name resolution: scopes, lookup, forward declarations, checks and repository ids.

Walks the parsed definitions once, in source order (IDL requires declaration before use), and
completes the AST in place: scoped names, repository ids, references from names to declarations,
constant values, array and sequence bounds, union labels. Follows the CORBA 3.0 rules (chapter 3.20,
"Names and Scoping"):

* Unqualified names are looked up in the current scope, then in the scopes it inherits (interfaces
  and value types), then outward; `::A` starts at the global scope.
* Identifiers collide ignoring case; a name that differs only in case from the one it resolves to
  is an error.
* Using an unqualified name introduces its first identifier into the scope of use and into the
  enclosing scopes up to, but excluding, the scope where it was found; enclosing modules are not
  affected (as omniidl interprets the rule). Declaring that name afterwards in one of those
  scopes is an error.
* Prefix pragmas apply to the rest of the scope they appear in, within the same file; a module
  opened afterwards derives its prefix from it.

The resolver is built in layers, each a module with one job: `scopes.Scopes` (the scope tree,
declaring and looking up names), `repository_ids.RepositoryIds` (pragmas and repository ids),
`type_rules.TypeRules` (type specs, constants, annotations), `interface_rules.InterfaceRules`
(forward declarations, interfaces, value types), and `Resolver` here: the walk over the
definitions, modules, and the data types (structs, unions, enums, exceptions, typedefs,
constants, natives). `type_queries` holds the questions they ask of AST nodes.
"""

from __future__ import annotations

from typing import Any

from miro_gen.diagnostics import Diagnostics, SourcePos
from miro_gen.idl import ast
from miro_gen.idl.constants import INT_RANGES, Target
from miro_gen.idl.interface_rules import InterfaceRules
from miro_gen.idl.scopes import BUILTIN_POS as BUILTIN_POS
from miro_gen.idl.scopes import BUILTIN_TYPES as BUILTIN_TYPES
from miro_gen.idl.scopes import Entry as Entry
from miro_gen.idl.scopes import Frame, Scope, join
from miro_gen.idl.type_queries import all_struct_members, article, completed, label_text, unalias
from miro_gen.idl.type_rules import KNOWN_ANNOTATIONS as KNOWN_ANNOTATIONS

_DISCRIMINATOR_BASES = frozenset([*INT_RANGES, "char", "wchar", "boolean"])


class Resolver(InterfaceRules):
    """Resolves the parsed definitions of one file (`resolve`), completing the AST in place."""

    def __init__(self, diag: Diagnostics, case_sensitive: bool = False) -> None:
        super().__init__(diag, case_sensitive)
        self.last_pos: SourcePos | None = None

    def resolve(self, definitions: list[Any]) -> list[ast.Decl]:
        frame = Frame(self.global_scope, "", 0)
        self._definitions(definitions, self.global_scope, frame)
        for fwd in self.forwards:
            if fwd.full is None:
                what = f"forward-declared {fwd.of} '{fwd.scoped_name}' is never defined"
                if fwd.of in ("struct", "union"):
                    self.diag.error(fwd.pos, what)
                else:
                    self.diag.warning(fwd.pos, what)
        self._finish_repo_ids()
        return self.declarations

    def _definitions(self, defs: list[Any], scope: Scope, frame: Frame) -> None:
        prev = self._scope
        self._scope = scope
        for d in defs:
            self._definition(d, scope, frame)
        self._scope = prev

    def _definition(self, d: Any, scope: Scope, frame: Frame) -> None:
        self.last_pos = getattr(d, "pos", self.last_pos)  # for failures without a position
        handler = self._handlers.get(type(d))
        if handler is None:  # pragma: no cover - the grammar produces nothing else
            raise TypeError(f"unexpected definition {type(d).__name__}")
        handler(self, d, scope, frame)

    def _module(self, m: ast.Module, scope: Scope, frame: Frame) -> None:
        self._annotations(m.annotations, scope)
        key = self._fold(m.name)
        existing = scope.entries.get(key)
        if existing is not None and existing.what == "module" and existing.scope is not None:
            if existing.name != m.name:
                self._clash(m.pos, "module", m.name, existing)
            inner = existing.scope
        else:
            entry = self._declare(scope, m.name, m.pos, "module", m)
            inner = self._new_scope("module", m.name, scope)
            if entry is not None:
                entry.scope = inner
        self._register(m, scope, frame)
        sub = Frame(inner, join(frame.prefix(m.instance), m.name), m.instance)
        self._definitions(m.definitions, inner, sub)

    def _struct(self, s: ast.Struct, scope: Scope, frame: Frame) -> None:
        self._annotations(s.annotations, scope)
        entry = self._complete_forwards(scope, s, "struct")
        self._register(s, scope, frame)
        inner = self._new_scope("struct", s.name, scope)
        if entry is not None:
            entry.scope = inner
        if s.base_name is not None:
            b = self.lookup(s.base_name, scope)
            if b is not None:
                node = completed(b.node)
                node = unalias(node) if isinstance(node, ast.Typedef) else node
                if not isinstance(node, ast.Struct):
                    self.diag.error(
                        s.base_name.pos, f"'{s.base_name}' is {article(b.what)}, not a struct"
                    )
                else:
                    s.base = node
        sub = self._frame_for(inner, s, frame)
        self.defining.append(s)
        self._members(s.members, inner, sub, "member")
        self.defining.pop()
        self._body_pragmas(s, inner, sub)
        if s.base is not None:
            inherited = {self._fold(m.name): m for m in all_struct_members(s.base)}
            for m in s.members:
                if self._fold(m.name) in inherited:
                    self.diag.error(
                        m.pos,
                        f"member '{m.name}' clashes with a member of base struct "
                        f"'{s.base.scoped_name}'",
                    )

    def _members(self, members: list[ast.Member], scope: Scope, frame: Frame, what: str) -> None:
        last_type: Any = None
        resolved: Any = None
        for m in members:
            self._annotations(m.annotations, scope)
            # Declarators of one member line share their type node: resolve it once.
            if m.type is not last_type:
                last_type = m.type
                resolved = self._type(m.type, scope, f"{what} type", frame=frame)
            m.type = resolved
            m.dims = self._dims(m.dims_expr, scope)
            self._declare(scope, m.name, m.pos, what, m)

    def _exception(self, e: ast.Exception_, scope: Scope, frame: Frame) -> None:
        self._annotations(e.annotations, scope)
        entry = self._declare(scope, e.name, e.pos, "exception", e)
        self._register(e, scope, frame)
        inner = self._new_scope("exception", e.name, scope)
        if entry is not None:
            entry.scope = inner
        sub = self._frame_for(inner, e, frame)
        self._members(e.members, inner, sub, "member")
        self._body_pragmas(e, inner, sub)

    def _enum(self, en: ast.Enum, scope: Scope, frame: Frame) -> None:
        self._annotations(en.annotations, scope)
        self._declare(scope, en.name, en.pos, "enum", en)
        self._register(en, scope, frame)
        # Enumerators belong to the enclosing scope (CORBA), with the enum's repository-id prefix.
        prefix = join(frame.prefix(en.instance), en.name)
        for e in en.enumerators:
            self._annotations(e.annotations, scope)
            self._declare(scope, e.name, e.pos, "enumerator", e)
            e.scope_path = (*scope.path, e.name)
            self.repo_parts[id(e)] = (join(prefix, e.name), "1.0")
        self._body_pragmas(en, scope, frame)

    def _union(self, u: ast.Union_, scope: Scope, frame: Frame) -> None:
        self._annotations(u.annotations, scope)
        entry = self._complete_forwards(scope, u, "union")
        self._register(u, scope, frame)
        inner = self._new_scope("union", u.name, scope)
        if entry is not None:
            entry.scope = inner
        sub = self._frame_for(inner, u, frame)
        # The union's scope starts at the '(' after `switch` (CORBA 3.0 section 3.20.2): an enum
        # defined there belongs to the union.
        self._annotations(u.switch_annotations, inner)
        u.switch_type = self._type(u.switch_type, inner, "discriminator type", frame=sub)
        disc = unalias(u.switch_type)
        target: Target | None
        if isinstance(disc, ast.Enum):
            target = Target("enum", disc.scoped_name, enum=disc)
        elif isinstance(disc, ast.BaseType) and disc.name in _DISCRIMINATOR_BASES:
            target = self._const_target(disc, u.pos)
        else:
            self.diag.error(
                u.pos,
                f"union '{u.name}' has an invalid discriminator type; use an integer, char, wchar, "
                "boolean, octet or enum type",
            )
            target = None
        self.defining.append(u)
        seen: dict[Any, SourcePos] = {}
        has_default = False
        default_pos = u.pos
        last_type: Any = None
        resolved: Any = None
        for case in u.cases:
            self._annotations(case.annotations, inner)
            for label_expr in case.labels_expr:
                if label_expr is None:
                    if has_default:
                        self.diag.error(
                            case.pos, f"union '{u.name}' has more than one default label"
                        )
                    has_default = True
                    default_pos = case.pos
                    case.labels.append(None)
                    continue
                if target is None:
                    continue
                value = self._eval(label_expr, target, inner)
                if value is None:
                    continue
                key = value.ordinal if isinstance(value, ast.EnumValue) else value
                if key in seen:
                    self.diag.error(
                        label_expr.pos,
                        f"union '{u.name}' repeats the case label {label_text(value)}",
                    )
                    self.diag.note(seen[key], "first used here")
                else:
                    seen[key] = label_expr.pos
                case.labels.append(value)
            if case.type is not last_type:
                last_type = case.type
                resolved = self._type(case.type, inner, "union member type", frame=sub)
            case.type = resolved
            case.dims = self._dims(case.dims_expr, inner)
            self._declare(inner, case.name, case.pos, "union member", case)
        self.defining.pop()
        self._body_pragmas(u, inner, sub)
        if has_default and target is not None:
            total = None
            if target.kind == "enum" and target.enum is not None:
                total = len(target.enum.enumerators)
            elif target.kind == "bool":
                total = 2
            if total is not None and len(seen) >= total:
                self.diag.error(
                    default_pos,
                    f"union '{u.name}' has a default label although every value of its "
                    "discriminator has a case",
                )

    def _typedef_group(self, g: ast.TypedefGroup, scope: Scope, frame: Frame) -> None:
        self._annotations(g.annotations, scope)
        self.in_typedef += 1
        typ = self._type(g.type, scope, "typedef type", frame=frame)
        self.in_typedef -= 1
        for i, (name, pos, dims_expr) in enumerate(g.declarators):
            t = ast.Typedef(
                name,
                pos,
                type=typ,
                dims_expr=dims_expr,
                doc=g.doc if i == 0 else None,
                annotations=list(g.annotations),
                instance=g.instance,
            )
            t.dims = self._dims(dims_expr, scope)
            self._declare(scope, name, pos, "typedef", t)
            self._register(t, scope, frame)

    def _const(self, c: ast.Const, scope: Scope, frame: Frame) -> None:
        self._annotations(c.annotations, scope)
        c.type = self._type(c.type, scope, "constant type", allow_bare_fixed=True)
        target = self._const_target(c.type, c.pos)
        self._declare(scope, c.name, c.pos, "constant", c)
        self._register(c, scope, frame)
        if target is not None and c.expr is not None:
            c.value = self._eval(c.expr, target, scope)

    def _native(self, n: ast.Native, scope: Scope, frame: Frame) -> None:
        self._annotations(n.annotations, scope)
        self._declare(scope, n.name, n.pos, "native type", n)
        self._register(n, scope, frame)

    def _annotation_decl(self, a: ast.AnnotationDecl, scope: Scope, frame: Frame) -> None:
        self.user_annotations.add(a.name)

    _handlers: dict[type, Any] = {}


Resolver._handlers = {
    ast.Module: Resolver._module,
    ast.Interface: Resolver._interface,
    ast.Forward: Resolver._forward,
    ast.Struct: Resolver._struct,
    ast.Union_: Resolver._union,
    ast.Enum: Resolver._enum,
    ast.TypedefGroup: Resolver._typedef_group,
    ast.Const: Resolver._const,
    ast.Exception_: Resolver._exception,
    ast.Native: Resolver._native,
    ast.ValueType: Resolver._valuetype,
    ast.ValueBox: Resolver._valuebox,
    ast.AnnotationDecl: Resolver._annotation_decl,
    ast.Pragma: Resolver._pragma,
    ast.TypeIdDcl: Resolver._typeid,
    ast.Operation: Resolver._operation,
    ast.AttributeGroup: Resolver._attribute_group,
    ast.StateMemberGroup: Resolver._state_members,
    ast.Factory: Resolver._factory,
}
