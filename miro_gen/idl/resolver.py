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
"""

from __future__ import annotations

import re
from typing import Any

from miro_gen.diagnostics import Diagnostics, SourcePos
from miro_gen.idl import ast
from miro_gen.idl.constants import (
    ANY,
    ARRAY_BOUND_MAX,
    FLOAT_TYPES,
    INT_RANGES,
    EvalError,
    Evaluator,
    Target,
)

KNOWN_ANNOTATIONS = frozenset(
    [
        "id",
        "autoid",
        "optional",
        "position",
        "value",
        "extensibility",
        "final",
        "appendable",
        "mutable",
        "key",
        "must_understand",
        "default_literal",
        "default",
        "range",
        "min",
        "max",
        "unit",
        "bit_bound",
        "external",
        "nested",
        "verbatim",
        "service",
        "oneway",
        "ami",
        "hashid",
        "topic",
        "data_representation",
        "non_serialized",
        "ignore_literal_names",
        "try_construct",
        "choice",
        "empty",
    ]
)
# Integer-valued annotations and their ranges (DDS-XTypes 1.3: member ids have 28 bits).
_ANNOTATION_LIMITS = {"id": 0x0FFFFFFF, "position": 0xFFFF, "bit_bound": 64}
# CORBA's pseudo-objects in the built-in module CORBA, as base types of the same names.
BUILTIN_TYPES = ("TypeCode", "Principal", "Object", "ValueBase")
BUILTIN_POS = SourcePos("<built in>", 1, 0)
_CONTEXT_ID = re.compile(r"[A-Za-z][A-Za-z0-9._]*\*?$")
_DISCRIMINATOR_BASES = frozenset([*INT_RANGES, "char", "wchar", "boolean"])


class Entry:
    """A name declared in a scope."""

    __slots__ = ("name", "node", "pos", "scope", "what")

    def __init__(self, name: str, what: str, pos: SourcePos, node: Any) -> None:
        self.name = name
        self.what = what  # for messages: "struct", "module", "member", "operation", ...
        self.pos = pos
        self.node = node
        self.scope: Scope | None = None  # the scope this declaration opens, if any


class Scope:
    """A naming scope: global, module, interface, valuetype, struct, union, exception, operation."""

    __slots__ = ("bases", "entries", "kind", "name", "parent", "path", "used")

    def __init__(self, kind: str, name: str, parent: Scope | None, path: tuple[str, ...]) -> None:
        self.kind = kind
        self.name = name
        self.parent = parent
        self.path = path
        self.entries: dict[str, Entry] = {}
        self.used: dict[str, tuple[str, SourcePos]] = {}
        self.bases: list[Scope] = []  # inherited scopes (interfaces, value types)


class Frame:
    """Repository-id prefix state for one opening of a scope."""

    __slots__ = ("base", "explicit", "instance", "scope")

    def __init__(self, scope: Scope, base: str, instance: int) -> None:
        self.scope = scope
        self.base = base
        self.instance = instance
        self.explicit: dict[int, str] = {}

    def prefix(self, instance: int) -> str:
        p = self.explicit.get(instance)
        if p is not None:
            return p
        if instance != self.instance and self.scope.kind == "global":
            return ""
        return self.base


def _join(prefix: str, name: str) -> str:
    return f"{prefix}/{name}" if prefix else name


class Resolver:
    def __init__(self, diag: Diagnostics, case_sensitive: bool = False) -> None:
        self.diag = diag
        # The key of a name in a scope: CORBA folds case (identifiers that differ only in case
        # collide); under --case-sensitive (DDS and ROS 2 files, like idlc -f case-sensitive)
        # they are distinct, and a use does not reserve its name.
        self.case_sensitive = case_sensitive
        self._fold: Any = str if case_sensitive else str.lower
        self.global_scope = Scope("global", "", None, ())
        self.declarations: list[ast.Decl] = []
        self.defining: list[ast.Decl] = []  # structs/unions whose bodies are being resolved
        self.in_typedef = 0
        self.repo_parts: dict[int, tuple[str, str]] = {}  # id(decl) -> (prefix path, version)
        self.explicit_ids: dict[int, tuple[str, SourcePos]] = {}
        self.versions: dict[int, tuple[str, SourcePos]] = {}
        self.forwards: list[ast.Forward] = []
        self.user_annotations: set[str] = set()
        self.evaluator = Evaluator(self._lookup_constant, diag)
        self.last_pos: SourcePos | None = None
        self._scope: Scope = self.global_scope
        self.type_prefixes: list[tuple[tuple[str, ...], str]] = []  # (scope path, prefix)
        self._decl_scopes: dict[int, Scope] = {}  # id(interface/valuetype) -> its scope
        self._scope_owners: dict[int, Any] = {}  # id(scope) -> interface/valuetype
        self._inherited: dict[int, dict[str, tuple[str, Any, ast.Decl]]] = {}
        self.saw_local = False  # a local interface was declared (forward declarations too)
        self._declare_builtins()

    def _declare_builtins(self) -> None:
        """Module CORBA and its pseudo-objects, known without any include (as omniidl knows
        `CORBA::TypeCode` and `CORBA::Principal`); `CORBA::Object` and `CORBA::ValueBase` are
        the keywords `Object` and `ValueBase`. Files that open `module CORBA` (the ORB's
        orb.idl, ir.idl) reopen this module."""
        corba = Entry("CORBA", "module", BUILTIN_POS, None)
        corba.scope = self._new_scope("module", "CORBA", self.global_scope)
        self.global_scope.entries[self._fold("CORBA")] = corba
        for name in BUILTIN_TYPES:
            corba.scope.entries[self._fold(name)] = Entry(
                name, "built-in type", BUILTIN_POS, ast.BaseType(name)
            )

    # =========================================================================================
    # entry point
    # =========================================================================================
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

    # =========================================================================================
    # scopes and declarations
    # =========================================================================================
    def _declare(
        self, scope: Scope, name: str, pos: SourcePos, what: str, node: Any
    ) -> Entry | None:
        """Enter `name` into `scope`, reporting clashes; returns the entry (None on a clash)."""
        key = self._fold(name)
        if scope.kind not in ("global", "operation") and key == self._fold(scope.name):
            self.diag.error(
                pos, f"{what} '{name}' clashes with the name of its enclosing scope '{scope.name}'"
            )
            return None
        existing = scope.entries.get(key)
        if existing is not None:
            self._clash(pos, what, name, existing)
            return None
        used = scope.used.get(key)
        if used is not None:
            self.diag.error(
                pos,
                f"declaration of {what} '{name}' clashes with the earlier use of '{used[0]}' "
                "in this scope",
            )
            self.diag.note(used[1], f"'{used[0]}' used here")
            return None
        entry = Entry(name, what, pos, node)
        scope.entries[key] = entry
        return entry

    def _clash(self, pos: SourcePos, what: str, name: str, existing: Entry) -> None:
        if existing.name == name:
            msg = f"{what} '{name}' is already declared in this scope (as {existing.what})"
        else:
            msg = (
                f"{what} '{name}' clashes with {existing.what} '{existing.name}' "
                "(IDL identifiers that differ only in case collide)"
            )
        self.diag.error(pos, msg)
        self.diag.note(existing.pos, f"'{existing.name}' declared here")

    def _new_scope(self, kind: str, name: str, parent: Scope) -> Scope:
        return Scope(kind, name, parent, (*parent.path, name))

    def _register(self, decl: ast.Decl, scope: Scope, frame: Frame) -> None:
        """Give `decl` its scoped name and repository-id parts and list it."""
        decl.scope_path = (*scope.path, decl.name)
        self.repo_parts[id(decl)] = (_join(frame.prefix(decl.instance), decl.name), "1.0")
        self.declarations.append(decl)

    # =========================================================================================
    # lookup
    # =========================================================================================
    def _find_in(self, scope: Scope, key: str) -> list[tuple[Entry, Scope]]:
        """Entries named `key` in `scope` or, failing that, in the scopes it inherits."""
        e = scope.entries.get(key)
        if e is not None:
            return [(e, scope)]
        found: list[tuple[Entry, Scope]] = []
        seen: set[int] = set()
        todo = list(scope.bases)
        while todo:
            s = todo.pop(0)
            if id(s) in seen:
                continue
            seen.add(id(s))
            e = s.entries.get(key)
            if e is not None:
                if all(f[0].node is not e.node for f in found):
                    found.append((e, s))
                continue
            todo.extend(s.bases)
        return found

    def lookup(self, name: ast.ScopedName, scope: Scope) -> Entry | None:
        """Resolve a scoped name from `scope`; reports and returns None when it fails."""
        parts = name.parts
        first = parts[0]
        key = self._fold(first)
        hits: list[tuple[Entry, Scope]] = []
        if name.absolute:
            hits = self._find_in(self.global_scope, key)
        else:
            s: Scope | None = scope
            while s is not None:
                hits = self._find_in(s, key)
                if hits:
                    break
                s = s.parent
        if not hits:
            self.diag.error(name.pos, f"'{name}' is not declared" + self._where(name, scope))
            return None
        if len(hits) > 1:
            where = " and ".join(f"'{'::'.join(h[1].path)}'" for h in hits)
            self.diag.error(name.pos, f"'{first}' is ambiguous: it is inherited from {where}")
            return None
        entry, found_in = hits[0]
        self._check_case(first, entry, name.pos)
        if not name.absolute:
            self._mark_used(first, name.pos, scope, found_in)
        for part in parts[1:]:
            inner = entry.scope
            if inner is None:
                self.diag.error(
                    name.pos,
                    f"'{entry.name}' is {_a(entry.what)}, not a scope; cannot find '{part}' in it",
                )
                return None
            hits = self._find_in(inner, self._fold(part))
            if not hits:
                self.diag.error(
                    name.pos, f"'{name}' is not declared: no '{part}' in '{entry.name}'"
                )
                return None
            if len(hits) > 1:
                self.diag.error(name.pos, f"'{part}' is ambiguous in '{entry.name}'")
                return None
            entry = hits[0][0]
            self._check_case(part, entry, name.pos)
        return entry

    def _where(self, name: ast.ScopedName, scope: Scope) -> str:
        return (
            ""
            if scope.kind == "global" or name.absolute
            else f" (looked up from '{'::'.join(scope.path)}')"
        )

    def _check_case(self, spelled: str, entry: Entry, pos: SourcePos) -> None:
        if spelled != entry.name:
            self.diag.error(
                pos,
                f"'{spelled}' differs only in case from the declared {entry.what} '{entry.name}'",
            )
            self.diag.note(entry.pos, f"'{entry.name}' declared here")

    def _mark_used(self, ident: str, pos: SourcePos, scope: Scope, found_in: Scope) -> None:
        if self.case_sensitive:
            return
        key = ident.lower()
        s: Scope | None = scope
        while s is not None and s is not found_in:
            if key not in s.used and key not in s.entries:
                s.used[key] = (ident, pos)
            if s.kind in ("module", "global"):
                break
            s = s.parent
            if s is not None and s.kind in ("module", "global"):
                break

    # =========================================================================================
    # definitions
    # =========================================================================================
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

    # -- modules ------------------------------------------------------------------------------
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
        sub = Frame(inner, _join(frame.prefix(m.instance), m.name), m.instance)
        self._definitions(m.definitions, inner, sub)

    # -- pragmas and typeid/typeprefix --------------------------------------------------------
    def _pragma(self, p: ast.Pragma, scope: Scope, frame: Frame) -> None:
        words = p.text.split(None, 2)
        kind = words[1] if len(words) > 1 else ""
        rest = words[2] if len(words) > 2 else ""
        if kind == "prefix":
            m = re.match(r'"([^"]*)"\s*$', rest)
            if not m:
                self.diag.error(p.pos, '#pragma prefix expects a string: #pragma prefix "omg.org"')
                return
            frame.explicit[p.instance] = m.group(1)
            return
        if kind == "ID":
            m = re.match(r'((?:::)?[A-Za-z_]\w*(?:::[A-Za-z_]\w*)*)\s+"([^"]*)"\s*$', rest)
            if not m:
                self.diag.error(
                    p.pos, '#pragma ID expects a name and a string: #pragma ID X "IDL:X:1.0"'
                )
                return
            self._set_id(m.group(1), m.group(2), p.pos, scope)
            return
        if kind == "version":
            m = re.match(r"((?:::)?[A-Za-z_]\w*(?:::[A-Za-z_]\w*)*)\s+(\d+)\.(\d+)\s*$", rest)
            if not m:
                self.diag.error(p.pos, "#pragma version expects a name and MAJOR.MINOR")
                return
            decl = self._pragma_target(m.group(1), p.pos, scope)
            if decl is None:
                return
            version = f"{int(m.group(2))}.{int(m.group(3))}"
            old = self.versions.get(id(decl))
            if old is not None and old[0] != version:
                self.diag.error(p.pos, f"conflicting #pragma version for '{decl.scoped_name}'")
                self.diag.note(old[1], "earlier version set here")
                return
            explicit = self.explicit_ids.get(id(decl))
            if explicit is not None:
                # Allowed when the id already carries that version (omniidl, CORBA 3.0 10.7.5).
                if not explicit[0].startswith("IDL:") or explicit[0].rsplit(":", 1)[1] != version:
                    self.diag.error(
                        p.pos,
                        f"cannot set the version of '{decl.scoped_name}' to {version}: "
                        f"#pragma ID gave it the repository id '{explicit[0]}'",
                    )
                    self.diag.note(explicit[1], "#pragma ID here")
                return
            self.versions[id(decl)] = (version, p.pos)
            return
        self.diag.error(p.pos, f"unknown #pragma '{kind}'")  # pragma: no cover

    def _pragma_target(self, text: str, pos: SourcePos, scope: Scope) -> ast.Decl | None:
        absolute = text.startswith("::")
        parts = tuple(x for x in text.split("::") if x)
        entry = self.lookup(ast.ScopedName(parts, absolute, pos), scope)
        if entry is None:
            return None
        node = entry.node
        if not isinstance(node, ast.Decl) or id(node) not in self.repo_parts:
            self.diag.error(pos, f"'{text}' ({entry.what}) has no repository id")
            return None
        return node

    def _set_id(self, text: str, repo_id: str, pos: SourcePos, scope: Scope) -> None:
        decl = self._pragma_target(text, pos, scope)
        if decl is None:
            return
        if ":" not in repo_id:
            self.diag.error(pos, f"repository id '{repo_id}' has no format prefix (such as 'IDL:')")
            return
        old = self.explicit_ids.get(id(decl))
        if old is not None and old[0] != repo_id:
            self.diag.error(pos, f"conflicting repository ids for '{decl.scoped_name}'")
            self.diag.note(old[1], f"'{old[0]}' set here")
            return
        version = self.versions.get(id(decl))
        if version is not None:
            implied = f"IDL:{self.repo_parts[id(decl)][0]}:{version[0]}"
            if repo_id != implied:
                self.diag.error(
                    pos,
                    f"cannot set the repository id of '{decl.scoped_name}' to '{repo_id}': "
                    f"#pragma version made it '{implied}'",
                )
                self.diag.note(version[1], "#pragma version here")
            return
        self.explicit_ids[id(decl)] = (repo_id, pos)

    def _typeid(self, t: ast.TypeIdDcl, scope: Scope, frame: Frame) -> None:
        if not t.is_prefix:
            self._set_id(str(t.name), t.value, t.pos, scope)
            return
        entry = self.lookup(t.name, scope)
        if entry is None:
            return
        if entry.scope is None or entry.what not in ("module", "interface", "valuetype"):
            self.diag.error(
                t.pos, f"typeprefix needs a module, interface or value type, not {_a(entry.what)}"
            )
            return
        # Applied when repository ids are finished: the prefix goes before the scope's own name
        # and those of everything in it (CORBA 3.0 section 3.15.2), wherever the typeprefix is.
        self.type_prefixes.append((entry.scope.path, t.value))

    def _frame_for(self, inner: Scope, decl: ast.Decl, frame: Frame) -> Frame:
        return Frame(inner, _join(frame.prefix(decl.instance), decl.name), decl.instance)

    # -- interfaces ---------------------------------------------------------------------------
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
                self.diag.error(bname.pos, f"'{bname}' is {_a(b.what)}, not an interface")
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
            if (local := _local_type(a.type)) is not None:
                self.diag.error(a.pos, f"{where} attribute '{a.name}' has local type '{local}'")
        for op in i.operations:
            if (local := _local_type(op.returns)) is not None:
                self.diag.error(
                    op.pos, f"{where} operation '{op.name}' has local return type '{local}'"
                )
            for p in op.params:
                if (local := _local_type(p.type)) is not None:
                    self.diag.error(
                        p.pos,
                        f"{where} parameter '{p.name}' of operation '{op.name}' has local "
                        f"type '{local}'",
                    )
            for e in op.raises:
                if (local := _local_type(e)) is not None:
                    self.diag.error(
                        op.pos, f"{where} operation '{op.name}' raises local exception '{local}'"
                    )

    def _aliased(self, node: Any) -> Any:
        """What a base or `supports` name denotes through typedefs (`typedef I J;
        interface K : J {};` inherits I, as omniidl accepts)."""
        if isinstance(node, ast.Typedef) and not node.dims:
            target = self._unalias(node)
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
                self.diag.error(n.pos, f"'{n}' is {_a(e.what)}, not an exception")
                continue
            out.append(e.node)
        return out

    # -- value types --------------------------------------------------------------------------
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
            node = _completed(self._aliased(b.node))
            if not isinstance(node, ast.ValueType):
                self.diag.error(bname.pos, f"'{bname}' is {_a(b.what)}, not a value type")
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
            node = _completed(self._aliased(s_entry.node))
            if not isinstance(node, ast.Interface):
                self.diag.error(sname.pos, f"'{sname}' is {_a(s_entry.what)}, not an interface")
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
            if inherited is not iface and inherited not in _all_bases(iface):
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
            if self.saw_local and (local := _local_type(typ)) is not None:
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
        target = self._unalias(v.type)
        if isinstance(target, (ast.ValueType, ast.ValueBox)):
            self.diag.error(v.pos, f"value box '{v.name}' cannot box a value type")

    # -- structs, unions, enums, exceptions ---------------------------------------------------
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
                node = _completed(b.node)
                node = self._unalias(node) if isinstance(node, ast.Typedef) else node
                if not isinstance(node, ast.Struct):
                    self.diag.error(
                        s.base_name.pos, f"'{s.base_name}' is {_a(b.what)}, not a struct"
                    )
                else:
                    s.base = node
        sub = self._frame_for(inner, s, frame)
        self.defining.append(s)
        self._members(s.members, inner, sub, "member")
        self.defining.pop()
        self._body_pragmas(s, inner, sub)
        if s.base is not None:
            inherited = {self._fold(m.name): m for m in _all_struct_members(s.base)}
            for m in s.members:
                if self._fold(m.name) in inherited:
                    self.diag.error(
                        m.pos,
                        f"member '{m.name}' clashes with a member of base struct "
                        f"'{s.base.scoped_name}'",
                    )

    def _body_pragmas(self, d: ast.Decl, scope: Scope, frame: Frame) -> None:
        """`#pragma` lines inside a struct, exception, union or enum body, after its members."""
        for p in d.pragmas:
            self._pragma(p, scope, frame)

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
        prefix = _join(frame.prefix(en.instance), en.name)
        for e in en.enumerators:
            self._annotations(e.annotations, scope)
            self._declare(scope, e.name, e.pos, "enumerator", e)
            e.scope_path = (*scope.path, e.name)
            self.repo_parts[id(e)] = (_join(prefix, e.name), "1.0")
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
        disc = self._unalias(u.switch_type)
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
                        f"union '{u.name}' repeats the case label {_label_text(value)}",
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

    # -- typedefs, constants, natives ---------------------------------------------------------
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

    def _const_target(self, typ: Any, pos: SourcePos) -> Target | None:
        t = self._unalias(typ)
        if isinstance(t, ast.NamedType) and t.decl is None:
            return None  # an unresolved name, already reported
        if isinstance(t, ast.Typedef):  # aliased array
            self.diag.error(pos, "a constant cannot have an array type")
            return None
        if isinstance(t, ast.BaseType):
            n = t.name
            if n in INT_RANGES:
                return Target("int", n)
            if n in FLOAT_TYPES:
                return Target("float", n)
            if n == "char":
                return Target("char", n)
            if n == "wchar":
                return Target("wchar", n)
            if n == "boolean":
                return Target("bool", n)
        elif isinstance(t, ast.StringType):
            return Target("wstring" if t.wide else "string", str(t), bound=t.bound)
        elif isinstance(t, ast.FixedType):
            return Target("fixed", "fixed", bound=t.digits, scale=t.scale)
        elif isinstance(t, ast.Enum):
            return Target("enum", t.scoped_name, enum=t)
        self.diag.error(pos, f"constants of type {_type_text(typ)} are not allowed")
        return None

    def _native(self, n: ast.Native, scope: Scope, frame: Frame) -> None:
        self._annotations(n.annotations, scope)
        self._declare(scope, n.name, n.pos, "native type", n)
        self._register(n, scope, frame)

    def _annotation_decl(self, a: ast.AnnotationDecl, scope: Scope, frame: Frame) -> None:
        self.user_annotations.add(a.name)

    # =========================================================================================
    # types
    # =========================================================================================
    def _type(
        self,
        t: Any,
        scope: Scope,
        role: str,
        *,
        frame: Frame | None = None,
        in_sequence: bool = False,
        allow_bare_fixed: bool = False,
    ) -> Any:
        """Resolve a type spec; inline struct/union/enum definitions are declared in `scope`."""
        if isinstance(t, ast.BaseType):
            return t
        if isinstance(t, ast.NamedType):
            entry = self.lookup(t.name, scope)
            if entry is None:
                return t
            node = entry.node
            if isinstance(node, ast.BaseType):  # CORBA::TypeCode and the other built-ins
                return node
            if not _is_type(node):
                self.diag.error(t.name.pos, f"'{t.name}' is {_a(entry.what)}, not a type")
                self.diag.note(entry.pos, f"'{entry.name}' declared here")
                return t
            t.decl = node
            self._check_complete(t, node, in_sequence)
            return t
        if isinstance(t, ast.StringType):
            if t.bound_expr is not None:
                t.bound = self._positive(t.bound_expr, "string bound", scope)
            return t
        if isinstance(t, ast.SequenceType):
            t.element = self._type(
                t.element, scope, "sequence element type", frame=frame, in_sequence=True
            )
            if t.bound_expr is not None:
                t.bound = self._positive(t.bound_expr, "sequence bound", scope)
            return t
        if isinstance(t, ast.FixedType):
            if t.digits_expr is None or t.scale_expr is None:
                if not allow_bare_fixed:
                    self.diag.error(
                        t.pos, "'fixed' needs digits and scale here: fixed<DIGITS, SCALE>"
                    )
                return t
            digits = self._eval(t.digits_expr, Target("int", "unsigned short"), scope)
            scale = self._eval(t.scale_expr, Target("int", "unsigned short"), scope)
            if isinstance(digits, int) and isinstance(scale, int):
                if not 1 <= digits <= 31:
                    self.diag.error(t.pos, f"fixed-point types have 1 to 31 digits, not {digits}")
                elif scale > digits:
                    self.diag.error(
                        t.pos, f"fixed-point scale {scale} is larger than its {digits} digits"
                    )
                t.digits, t.scale = digits, scale
            return t
        if isinstance(t, ast.MapType):
            t.key = self._type(t.key, scope, "map key type", frame=frame, in_sequence=True)
            t.value = self._type(t.value, scope, "map value type", frame=frame, in_sequence=True)
            if t.bound_expr is not None:
                t.bound = self._positive(t.bound_expr, "map bound", scope)
            return t
        if isinstance(t, (ast.Struct, ast.Union_, ast.Enum)):
            if frame is None:
                self.diag.error(t.pos, f"a {t.kind} cannot be defined in a {role}")
                return t
            self._definition(t, scope, frame)
            return ast.NamedType(ast.ScopedName(t.scope_path, True, t.pos), decl=t)
        raise TypeError(f"unexpected type node {type(t).__name__}")  # pragma: no cover

    def _check_complete(self, t: ast.NamedType, node: Any, in_sequence: bool) -> None:
        if isinstance(node, ast.Forward) and node.of in ("struct", "union"):
            if node.full is not None:
                return
            if not in_sequence:
                self.diag.error(
                    t.name.pos,
                    f"cannot use forward-declared {node.of} '{t.name}' before it is fully defined",
                )
            elif not self.in_typedef and not self._being_defined(node):
                self.diag.error(
                    t.name.pos,
                    f"cannot use a sequence of forward-declared {node.of} '{t.name}' outside "
                    "its own definition before it is fully defined",
                )
            return
        if isinstance(node, (ast.Struct, ast.Union_)) and node in self.defining and not in_sequence:
            self.diag.error(
                t.name.pos,
                f"{node.kind} '{node.name}' cannot contain itself (recursion needs a sequence)",
            )
            return
        if isinstance(node, ast.Typedef) and not self.in_typedef:
            fwd = _incomplete_forward(node.type, set())
            if fwd is not None and not self._being_defined(fwd):
                self.diag.error(
                    t.name.pos,
                    f"cannot use '{t.name}' here: it holds forward-declared {fwd.of} "
                    f"'{fwd.scoped_name}', which is not yet fully defined",
                )

    def _being_defined(self, fwd: ast.Forward) -> bool:
        return any(d.scope_path == fwd.scope_path for d in self.defining)

    def _unalias(self, t: Any) -> Any:
        """Follow named types and typedefs (without array dimensions) to the underlying type."""
        for _ in range(1000):
            if isinstance(t, ast.NamedType):
                if t.decl is None:
                    return t
                t = t.decl
            if isinstance(t, ast.Forward) and t.full is not None:
                t = t.full
            if isinstance(t, ast.Typedef) and not t.dims:
                t = t.type
                continue
            if isinstance(t, ast.NamedType):
                continue
            return t
        return t  # pragma: no cover

    def _eval(self, expr: ast.Expr, target: Target, scope: Scope) -> ast.ConstValue | None:
        """Evaluate a constant expression whose names are looked up from `scope`."""
        prev = self._scope
        self._scope = scope
        try:
            return self.evaluator.evaluate(expr, target)
        finally:
            self._scope = prev

    def _positive(self, expr: ast.Expr, what: str, scope: Scope) -> int | None:
        v = self._eval(expr, ANY, scope)
        if v is not None and (not isinstance(v, int) or isinstance(v, bool)):
            shown = v.scoped_name if isinstance(v, ast.EnumValue) else repr(v)
            self.diag.error(expr.pos, f"{what} must be a positive integer, not {shown}")
            return None
        if isinstance(v, int):
            if v <= 0:
                self.diag.error(expr.pos, f"{what} must be positive, not {v}")
                return None
            if v > ARRAY_BOUND_MAX:
                self.diag.error(expr.pos, f"{what} {v} is too large (maximum {ARRAY_BOUND_MAX})")
                return None
            return v
        return None

    def _dims(self, exprs: list[ast.Expr], scope: Scope) -> list[int]:
        out: list[int] = []
        for e in exprs:
            v = self._positive(e, "array size", scope)
            out.append(v if v is not None else 1)
        return out

    # =========================================================================================
    # constants and annotations
    # =========================================================================================
    def _lookup_constant(self, ref: ast.NameRef) -> tuple[str, ast.ConstValue]:
        entry = self.lookup(ref.name, self._scope)
        if entry is None:
            raise EvalError(ref.pos, "")  # already reported by lookup
        node = entry.node
        if isinstance(node, ast.Enumerator) and node.enum is not None:
            return "enum", ast.EnumValue(node.enum, node.name, node.ordinal)
        if isinstance(node, ast.Const):
            if node.value is None:
                raise EvalError(ref.pos, f"constant '{ref.name}' has no valid value")
            return _kind_of_const(node, self._unalias(node.type)), node.value
        raise EvalError(ref.pos, f"'{ref.name}' is {_a(entry.what)}, not a constant")

    def _annotations(self, anns: list[ast.Annotation], scope: Scope) -> None:
        if not anns:
            return
        prev = self._scope
        self._scope = scope
        try:
            self._annotations_in_scope(anns)
        finally:
            self._scope = prev

    def _annotations_in_scope(self, anns: list[ast.Annotation]) -> None:
        for a in anns:
            name = a.short_name
            if name not in KNOWN_ANNOTATIONS and name not in self.user_annotations:
                self.diag.warning(
                    a.pos, f"unknown annotation '@{a.name}' (kept, but it has no effect)"
                )
            for key, expr in a.args.items():
                value = self._annotation_arg(expr)
                if value is not None:
                    a.params[key] = value
            if name in _ANNOTATION_LIMITS:
                v = a.params.get("value")
                limit = _ANNOTATION_LIMITS[name]
                if not isinstance(v, int) or isinstance(v, bool) or not 0 <= v <= limit:
                    self.diag.error(a.pos, f"@{name} needs an integer from 0 to {limit}")

    def _annotation_arg(self, expr: ast.Expr) -> ast.ConstValue | None:
        # A bare identifier that names nothing is an enumerator-like word (FINAL, SEQUENTIAL, ...).
        if isinstance(expr, ast.NameRef) and len(expr.name.parts) == 1 and not expr.name.absolute:
            key = self._fold(expr.name.parts[0])
            s: Scope | None = self._scope
            found = False
            while s is not None and not found:
                found = bool(self._find_in(s, key))
                s = s.parent
            if not found:
                return expr.name.parts[0]
        return self.evaluator.evaluate(expr, ANY)

    # =========================================================================================
    # repository ids
    # =========================================================================================
    def _check_forward_prefixes(self) -> None:
        """A definition and its forward declarations must share their repository-id prefix; a
        `#pragma ID` or `version` given to the forward declaration passes to the definition
        (a pragma after the definition changes only the definition), as in omniidl."""
        for fwd in self.forwards:
            full = fwd.full
            if full is None or id(full) not in self.repo_parts:
                continue
            fwd_path, full_path = self.repo_parts[id(fwd)][0], self.repo_parts[id(full)][0]
            if fwd_path != full_path:
                self.diag.error(
                    full.pos,
                    f"the repository id of '{full.scoped_name}' ('{full_path}') differs from the "
                    f"one of its forward declaration ('{fwd_path}'): check #pragma prefix",
                )
                self.diag.note(fwd.pos, "forward declaration here")
            for table in (self.explicit_ids, self.versions):
                if id(fwd) in table and id(full) not in table:
                    table[id(full)] = table[id(fwd)]

    def _finish_repo_ids(self) -> None:
        # typeprefix: the innermost scope wins, so apply outer ones first.
        for scope_path, prefix in sorted(self.type_prefixes, key=lambda tp: len(tp[0])):
            n = len(scope_path)
            for d in self.declarations:
                if d.scope_path[:n] == scope_path:
                    version = self.repo_parts[id(d)][1]
                    self.repo_parts[id(d)] = ("/".join((prefix, *d.scope_path[n - 1 :])), version)
        self._check_forward_prefixes()
        for d in self.declarations:
            key = id(d)
            explicit = self.explicit_ids.get(key)
            if explicit is not None:
                d.repo_id = explicit[0]
                continue
            path, version = self.repo_parts[key]
            v = self.versions.get(key)
            d.repo_id = f"IDL:{path}:{v[0] if v else version}"
        # Enumerators are not listed, but get ids for code generators.
        for d in self.declarations:
            if isinstance(d, ast.Enum):
                for e in d.enumerators:
                    parts = self.repo_parts.get(id(e))
                    if parts is not None:
                        e.repo_id = f"IDL:{parts[0]}:{parts[1]}"

    _handlers: dict[type, Any] = {}


def _completed(node: Any) -> Any:
    """A forward declaration's full declaration once it has been seen; otherwise `node`."""
    if isinstance(node, ast.Forward) and node.full is not None:
        return node.full
    return node


def _a(word: str) -> str:
    """`word` with its indefinite article: "an interface", "a struct"."""
    return f"{'an' if word[:1] in 'aeiou' else 'a'} {word}"


def _all_bases(i: ast.Interface) -> list[ast.Interface]:
    """Every interface `i` inherits from, directly or not."""
    out: list[ast.Interface] = []
    todo = list(i.bases)
    while todo:
        b = todo.pop()
        if b not in out:
            out.append(b)
            todo.extend(b.bases)
    return out


def _all_struct_members(s: ast.Struct) -> list[ast.Member]:
    out: list[ast.Member] = []
    seen: set[int] = set()
    while s is not None and id(s) not in seen:
        seen.add(id(s))
        out.extend(s.members)
        s = s.base  # type: ignore[assignment]
    return out


def _is_type(node: Any) -> bool:
    if isinstance(node, ast.Forward):
        return True
    return isinstance(
        node,
        (
            ast.Typedef,
            ast.Struct,
            ast.Union_,
            ast.Enum,
            ast.Native,
            ast.Interface,
            ast.ValueType,
            ast.ValueBox,
        ),
    )


def _local_type(t: Any, seen: set[int] | None = None) -> str | None:
    """The scoped name of the local interface that `t` is or holds (through typedefs,
    sequences, maps and members of structs, unions and exceptions), or None."""
    seen = set() if seen is None else seen
    if id(t) in seen:
        return None
    seen.add(id(t))
    if isinstance(t, ast.NamedType):
        return _local_type(t.decl, seen) if t.decl is not None else None
    if isinstance(t, ast.Forward):
        if t.full is not None:
            return _local_type(t.full, seen)
        return t.scoped_name if t.local else None
    if isinstance(t, ast.Interface):
        return t.scoped_name if t.local else None
    if isinstance(t, ast.Typedef):
        return _local_type(t.type, seen)
    if isinstance(t, ast.SequenceType):
        return _local_type(t.element, seen)
    if isinstance(t, ast.MapType):
        return _local_type(t.key, seen) or _local_type(t.value, seen)
    if isinstance(t, (ast.Struct, ast.Exception_)):
        members: list[Any] = t.members
    elif isinstance(t, ast.Union_):
        members = t.cases
    else:
        return None
    for m in members:
        if (local := _local_type(m.type, seen)) is not None:
            return local
    return None


def _incomplete_forward(t: Any, seen: set[int]) -> ast.Forward | None:
    if id(t) in seen:
        return None
    seen.add(id(t))
    if isinstance(t, ast.NamedType):
        return _incomplete_forward(t.decl, seen) if t.decl is not None else None
    if isinstance(t, ast.Forward):
        return t if t.of in ("struct", "union") and t.full is None else None
    if isinstance(t, ast.SequenceType):
        return _incomplete_forward(t.element, seen)
    if isinstance(t, ast.Typedef):
        return _incomplete_forward(t.type, seen)
    return None


def _kind_of_const(c: ast.Const, t: Any) -> str:
    if isinstance(t, ast.BaseType):
        n = t.name
        if n in INT_RANGES:
            return "int"
        if n in FLOAT_TYPES:
            return "float"
        return {"char": "char", "wchar": "wchar", "boolean": "bool"}.get(n, n)
    if isinstance(t, ast.StringType):
        return "wstring" if t.wide else "string"
    if isinstance(t, ast.FixedType):
        return "fixed"
    if isinstance(t, ast.Enum):
        return "enum"
    return "int"


def _label_text(v: Any) -> str:
    if isinstance(v, ast.EnumValue):
        return v.scoped_name
    if isinstance(v, bool):
        return "TRUE" if v else "FALSE"
    if isinstance(v, str):
        return repr(v)
    return str(v)


def _type_text(t: Any) -> str:
    if isinstance(t, ast.NamedType):
        return str(t.name)
    if isinstance(t, ast.SequenceType):
        return "a sequence"
    if isinstance(t, ast.MapType):
        return "a map"
    return str(t)


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
