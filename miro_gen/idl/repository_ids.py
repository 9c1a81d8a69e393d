"""Repository ids: the prefix each declaration gets where it is declared (`#pragma prefix`, the
frames of scopes), `#pragma ID` and `#pragma version`, `typeid` and `typeprefix`, forward
declarations that must agree with their definitions, and the ids written into the AST at the
end (CORBA 3.0 chapter 10.7, as omniidl applies it).

`RepositoryIds` is the resolver's second layer, on `Scopes`."""

from __future__ import annotations

import re

from miro_gen.diagnostics import Diagnostics, SourcePos
from miro_gen.idl import ast
from miro_gen.idl.scopes import Frame, Scope, Scopes, join
from miro_gen.idl.type_queries import article


class RepositoryIds(Scopes):
    """The declarations of one resolution, in order, and the parts of their repository ids."""

    def __init__(self, diag: Diagnostics, case_sensitive: bool = False) -> None:
        super().__init__(diag, case_sensitive)
        self.declarations: list[ast.Decl] = []
        self.forwards: list[ast.Forward] = []
        self.repo_parts: dict[int, tuple[str, str]] = {}  # id(decl) -> (prefix path, version)
        self.explicit_ids: dict[int, tuple[str, SourcePos]] = {}
        self.versions: dict[int, tuple[str, SourcePos]] = {}
        self.type_prefixes: list[tuple[tuple[str, ...], str]] = []  # (scope path, prefix)

    def _register(self, decl: ast.Decl, scope: Scope, frame: Frame) -> None:
        """Give `decl` its scoped name and repository-id parts and list it."""
        decl.scope_path = (*scope.path, decl.name)
        self.repo_parts[id(decl)] = (join(frame.prefix(decl.instance), decl.name), "1.0")
        self.declarations.append(decl)

    def _frame_for(self, inner: Scope, decl: ast.Decl, frame: Frame) -> Frame:
        return Frame(inner, join(frame.prefix(decl.instance), decl.name), decl.instance)

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

    def _body_pragmas(self, d: ast.Decl, scope: Scope, frame: Frame) -> None:
        """`#pragma` lines inside a struct, exception, union or enum body, after its members."""
        for p in d.pragmas:
            self._pragma(p, scope, frame)

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
                t.pos,
                f"typeprefix needs a module, interface or value type, not {article(entry.what)}",
            )
            return
        # Applied when repository ids are finished: the prefix goes before the scope's own name
        # and those of everything in it (CORBA 3.0 section 3.15.2), wherever the typeprefix is.
        self.type_prefixes.append((entry.scope.path, t.value))

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
