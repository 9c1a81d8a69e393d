"""What a compile into a package checks before it writes anything: inputs it can read, an
output folder it can write into, package paths the file system can hold, and (IDL) that every
module the generated code imports can be generated (so that no generated module fails when it
is imported) and that no two files declare the same names."""

from __future__ import annotations

import os
from collections.abc import Callable
from typing import TYPE_CHECKING

from miro_gen.diagnostics import CompileError, Diagnostic, Diagnostics

if TYPE_CHECKING:
    from miro_gen.codegen.contexts import ModuleContext
    from miro_gen.idl.ast import Decl, Specification


def unreadable(path: str) -> str | None:
    """Why an input file cannot be read, or None."""
    if os.path.isdir(path):
        return "it is a folder, not an IDL file"
    if not os.path.exists(path):
        return "no such file"
    if not os.access(path, os.R_OK):
        return "permission denied"
    return None


def unreadable_params(files: list[str], diag: Diagnostics) -> None:
    """Compile-time parameter files that are folders or missing, as errors in `diag`."""
    for f in files:
        if os.path.isdir(f):
            diag.error(None, f"'{f}' is a folder, not a compile-time file (give its .xml files)")
        elif not os.path.exists(f):
            diag.error(None, f"cannot read '{f}': no such file")


def unusable_outdir(outdir: str, writing: bool = True) -> str | None:
    """Why generated packages cannot go into `outdir` (a folder, made if missing), or None.
    Not `writing` (`--check`): only read, so a read-only tree can be checked."""
    path = os.path.abspath(outdir)
    while not os.path.exists(path):
        parent = os.path.dirname(path)
        if parent == path:
            break
        path = parent
    if not os.path.isdir(path):
        what = "is a file" if path == os.path.abspath(outdir) else f"is inside file '{path}'"
        return f"the output folder {what}; give a folder (it is made if missing)"
    if writing and not os.access(path, os.W_OK | os.X_OK):
        return f"cannot write into '{path}': permission denied"
    return None


def too_long_paths(paths: list[str], outdir: str | os.PathLike[str]) -> list[str]:
    """Generated paths the file system cannot hold (deeply nested or very long module names),
    each as a message naming the IDL module, so that nothing is written at all."""
    base = os.path.abspath(str(outdir))
    try:
        name_max = os.pathconf(existing_parent(base), "PC_NAME_MAX")
        path_max = os.pathconf(existing_parent(base), "PC_PATH_MAX")
    except (OSError, ValueError):
        name_max, path_max = 255, 4096
    out: dict[str, str] = {}  # IDL module -> why
    for rel in sorted({*paths, *(f"{os.path.dirname(p)}/__init__.py" for p in paths)}):
        full = os.path.join(base, rel)
        parts = rel.split("/")
        longest = max(len(p.encode()) for p in parts)
        if longest <= name_max and len(full.encode()) < path_max:
            continue
        module = "::".join(parts[:-1]) or parts[-1]
        why = (
            f"a name is {longest} bytes long (the file system allows {name_max})"
            if longest > name_max
            else f"its path is {len(full.encode())} bytes long (the file system allows "
            f"{path_max - 1}); nest fewer modules"
        )
        out.setdefault(module, f"cannot generate IDL module {shorten(module)}: {why}")
    return list(out.values())


def installed(module: str) -> bool:
    """Whether a generated module the new code imports is importable here already: from an
    installed package, such as the `Miro.Time_idl` of an installed miro-gen, which a user's
    `Miro` package of their own is spread over with it (miro_gen/runtime/packages.py)."""
    import importlib.util

    try:
        return importlib.util.find_spec(module) is not None
    except Exception:  # a parent package that fails to import: as good as missing
        return False


def existing_parent(path: str) -> str:
    while not os.path.exists(path) and os.path.dirname(path) != path:
        path = os.path.dirname(path)
    return path


def shorten(name: str, keep: int = 60) -> str:
    return name if len(name) <= 2 * keep else f"{name[:keep]}...{name[-keep:]}"


def refused_dependencies(
    specs: list[Specification],
    modules: list[ModuleContext],
    missing: list[str],
    compile_file: Callable[[str, Diagnostics], Specification],
    diag: Diagnostics,
) -> None:
    """Report, as errors in `diag`, the included IDL files whose generated modules the new code
    imports but which cannot be generated themselves, directly or through the files they need
    in turn (a construct the code generator refuses): the code would fail at import. Files that
    can be generated are left to the warning that says to compile them too."""
    from miro_gen.codegen import generate, names

    by_stem: dict[str, set[str]] = {}

    def learn(spec: Specification) -> None:
        for path in spec.includes:
            by_stem.setdefault(names.module_stem(path), set()).add(path)

    def sources(imported: str) -> list[str]:
        return sorted(by_stem.get(imported.rsplit(".", 1)[-1], ()))

    refusals: dict[str, Diagnostic | None] = {}

    def refusal(path: str) -> Diagnostic | None:
        """The first refusal met generating `path` and what it imports, or None."""
        if path in refusals:
            return refusals[path]
        refusals[path] = None  # while looking: an include cycle is not a refusal
        why = Diagnostics()
        try:
            spec = compile_file(path, why)
        except CompileError:
            return None  # it compiled as an include, so only its own macros differ: leave it
        learn(spec)
        built = generate.build_modules([(spec, path)], why)
        found = next((d for d in why.items if d.severity == "error"), None)
        for imported in sorted({i for m in built for i in m.imports}):
            for dep in sources(imported):
                if found is None and dep != path:
                    found = refusal(dep)
        refusals[path] = found
        return found

    for spec in specs:
        learn(spec)
    reported: set[int] = set()
    for imported in missing:
        users = ", ".join(sorted({m.source for m in modules if imported in m.imports}))
        for path in sources(imported):
            found = refusal(path)
            if found is not None and id(found) not in reported:
                reported.add(id(found))
                diag.error(
                    found.pos,
                    f"{found.message}; {users} uses declarations of {os.path.basename(path)}, "
                    "whose Python module cannot be generated",
                )


def clashing_declarations(specs: list[Specification], diag: Diagnostics) -> None:
    """Two command-line files that declare the same scoped names (omniORB ships both Naming.idl
    and CosNaming.idl with module CosNaming), or one a module and the other something else of
    that name: their generated modules would land in one package, one hiding the other's names.
    Reported once per pair of files, at the first clash."""
    from miro_gen.idl import ast
    from miro_gen.idl.rosidl.redeclarations import same_declaration

    first: dict[str, Decl] = {}
    clashes: dict[tuple[str, str], list[tuple[Decl, Decl]]] = {}
    for spec in specs:
        for d in spec.declarations:
            if d.pos.path != spec.main_file or isinstance(d, ast.Forward):
                continue
            seen = first.setdefault(d.scoped_name, d)
            both_modules = isinstance(seen, ast.Module) and isinstance(d, ast.Module)
            # ROS 2 files repeat identical typedefs (`double__36` in several geometry_msgs
            # files), as rosidl accepts: one hides the other harmlessly.
            repeated = isinstance(d, ast.Typedef) and spec.ros2_hashes and same_declaration(seen, d)
            if seen is not d and seen.pos.path != d.pos.path and not both_modules and not repeated:
                clashes.setdefault((seen.pos.path, d.pos.path), []).append((seen, d))
    for (earlier, _), pairs in clashes.items():
        seen, d = pairs[0]
        more = f" (and {len(pairs) - 1} more of its declarations)" if len(pairs) > 1 else ""
        diag.error(
            d.pos,
            f"'{d.scoped_name}'{more} is also declared in {earlier}, compiled in the same run: "
            "their Python modules would share a package, one hiding the other",
        )
        diag.note(seen.pos, f"'{d.scoped_name}' declared here")
