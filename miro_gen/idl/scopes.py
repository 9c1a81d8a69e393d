"""IDL scopes and the names declared in them: declaring (clashes, case folding), looking names
up (inherited scopes, outward, `::A`), and the CORBA rule that a use reserves its name in the
scopes between its use and its declaration (module docstring of miro_gen.idl.resolver).

`Scopes` is the first layer of the resolver: it owns the scope tree and the current scope
(where constant expressions look their names up)."""

from __future__ import annotations

from typing import Any

from miro_gen.diagnostics import Diagnostics, SourcePos
from miro_gen.idl import ast
from miro_gen.idl.type_queries import article

# CORBA's pseudo-objects in the built-in module CORBA, as base types of the same names.
BUILTIN_TYPES = ("TypeCode", "Principal", "Object", "ValueBase")
BUILTIN_POS = SourcePos("<built in>", 1, 0)


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


def join(prefix: str, name: str) -> str:
    return f"{prefix}/{name}" if prefix else name


class Scopes:
    """The scope tree of one resolution, from the global scope (with module CORBA in it)."""

    def __init__(self, diag: Diagnostics, case_sensitive: bool = False) -> None:
        self.diag = diag
        # The key of a name in a scope: CORBA folds case (identifiers that differ only in case
        # collide); under --case-sensitive (DDS and ROS 2 files, like idlc -f case-sensitive)
        # they are distinct, and a use does not reserve its name.
        self.case_sensitive = case_sensitive
        self._fold: Any = str if case_sensitive else str.lower
        self.global_scope = Scope("global", "", None, ())
        self._scope: Scope = self.global_scope  # where constant expressions look names up
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
                    f"'{entry.name}' is {article(entry.what)}, not a scope; "
                    f"cannot find '{part}' in it",
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
