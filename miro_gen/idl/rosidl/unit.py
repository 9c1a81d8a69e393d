"""A ROS 2 interface file and what it uses, as one resolved translation unit.

The file is a `.msg`, `.srv` or `.action` (read as rosidl_adapter reads it, `msg_parser.py` and
`msg_ast.py`) or a `.idl` as rosidl writes them. Its type names are package-relative, as in
rosidl: `<root>/<pkg>/msg/Foo.msg` declares `pkg::msg::Foo`, and a type it uses,
`geometry_msgs/Point`, is found as `<root>/geometry_msgs/msg/Point.msg` (or `.idl`) under the
file's own root and the `-I` roots, as rosidl finds `share/<pkg>/msg/`. Each file is read once
(`#include` too: rosidl's files have no guards), identical redeclarations are dropped
(`redeclarations.py`), services and actions get their derived types (`derived.py`), the whole is
resolved case-sensitively, and every struct gets its RIHS01 type hash (`type_description.py`).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

from miro_gen.diagnostics import CompileError, Diagnostics, SourcePos
from miro_gen.idl import ast
from miro_gen.idl.parser import parse
from miro_gen.idl.preprocessor import Preprocessor
from miro_gen.idl.resolver import Resolver
from miro_gen.idl.rosidl import INTERFACE_SUFFIXES
from miro_gen.idl.rosidl.derived import add_derived
from miro_gen.idl.rosidl.msg_ast import file_definitions
from miro_gen.idl.rosidl.msg_parser import PACKAGE_NAME, read_messages
from miro_gen.idl.rosidl.redeclarations import drop_identical
from miro_gen.idl.rosidl.type_description import NotDescribable, TypeDescriptions, type_hash


def compile_ros2(
    path: str,
    include_dirs: Sequence[str],
    defines: dict[str, str | None] | None,
    diag: Diagnostics,
) -> ast.Specification:
    """Parse and resolve one ROS 2 interface file with what it uses; `CompileError` carries
    every problem."""
    before = diag.error_count
    unit = _Unit(path, include_dirs, defines, diag)
    definitions = unit.main()
    needs = add_derived(definitions, path)
    # What the derived types use comes first; read on its own, it may repeat what the file
    # included (dropped as identical below).
    extra = _Unit(path, include_dirs, defines, diag)
    implicit = [d for name in needs for d in extra.dependency(name, SourcePos(path, 1, 1))]
    if diag.error_count > before:
        raise CompileError(diag.items)
    definitions = drop_identical(extra.loaded + implicit + unit.loaded + definitions)
    resolver = Resolver(diag, case_sensitive=True)
    declarations = resolver.resolve(definitions)
    if diag.error_count > before:
        raise CompileError(diag.items)
    spec = ast.Specification(path, definitions, declarations, unit.includes)
    spec.ros2_hashes = _hashes(declarations, diag)
    if diag.error_count > before:
        raise CompileError(diag.items)
    return spec


def _hashes(declarations: list[ast.Decl], diag: Diagnostics) -> dict[str, str]:
    descriptions = TypeDescriptions()
    out: dict[str, str] = {}
    for d in declarations:
        if isinstance(d, ast.Struct):
            try:
                out[d.scoped_name] = type_hash(descriptions.full_description(d))
            except NotDescribable as e:
                diag.error(d.pos, f"struct '{d.scoped_name}' is not a ROS 2 type: {e}")
    return out


class _Unit:
    """Reads the files of one unit, each once, dependencies before what uses them."""

    def __init__(
        self,
        path: str,
        include_dirs: Sequence[str],
        defines: dict[str, str | None] | None,
        diag: Diagnostics,
    ) -> None:
        self.path = path
        self.diag = diag
        own_root = str(Path(path).parent.parent.parent)
        self.roots = [own_root, *include_dirs]
        self.prefer = (".idl", ".msg") if Path(path).suffix == ".idl" else (".msg", ".idl")
        self.once: set[str] = set()  # the real paths of the files read, shared with #include
        self.preprocessor = Preprocessor(self.roots, defines, diag, once=self.once)
        self.includes: dict[str, list[str]] = {}
        self.loaded: list[ast.Definition] = []  # the dependencies' definitions, in order
        self.types: set[str] = set()  # `pkg/msg/Name` of the dependencies read or being read

    def main(self) -> list[ast.Definition]:
        """The main file's definitions (its dependencies are read into `loaded` first)."""
        return self._file(self.path)

    def dependency(self, type_name: str, pos: SourcePos) -> list[ast.Definition]:
        """The definitions of message `pkg/msg/Name` (none when read already)."""
        if type_name in self.types:
            return []
        self.types.add(type_name)
        found = self._find(type_name)
        if found is None:
            roots = ", ".join(self.roots)
            self.diag.error(
                pos,
                f"cannot find {type_name} (searched {type_name}.msg and .idl under: {roots}); "
                "give the folder holding its package with -I",
            )
            return []
        return self._file(found)

    def _find(self, type_name: str) -> str | None:
        for root in self.roots:
            for suffix in self.prefer:
                candidate = os.path.join(root, type_name + suffix)
                if os.path.isfile(candidate):
                    return os.path.normpath(candidate)
        return None

    def _file(self, path: str) -> list[ast.Definition]:
        if Path(path).suffix == ".idl":
            return self._idl(path)
        real = os.path.realpath(path)
        if real in self.once:
            return []
        self.once.add(real)
        kind = INTERFACE_SUFFIXES[Path(path).suffix]
        package = Path(path).parent.parent.name
        if not PACKAGE_NAME.fullmatch(package):
            self.diag.error(
                SourcePos(path, 1, 1),
                f"cannot tell the package of {path}: ROS 2 interface files live in "
                f"<package>/{kind}/ with a package name in lower case ('{package}' is not one)",
            )
            return []
        try:
            text = Path(path).read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as e:
            self.diag.error(SourcePos(path, 1, 1), f"cannot read {path}: {e}")
            return []
        messages = read_messages(path, text, package, kind, Path(path).stem, self.diag)
        if messages is None:
            return []
        uses: dict[str, SourcePos] = {}
        for f in (f for m in messages for f in m.fields if f.type.package is not None):
            uses.setdefault(f"{f.type.package}/msg/{f.type.base}", f.pos)
        files = self.includes.setdefault(path, [])
        for name in sorted(uses):  # in the order of rosidl_adapter's includes
            self.loaded += self.dependency(name, uses[name])
            found = self._find(name)
            if found is not None and found not in files:
                files.append(found)
        return file_definitions(package, kind, messages, self.diag)

    def _idl(self, path: str) -> list[ast.Definition]:
        src = self.preprocessor.run(path)
        for f, included in src.includes.items():
            self.includes.setdefault(f, []).extend(included)
        definitions = parse(src, self.diag, case_sensitive=True)
        return definitions if definitions is not None else []
