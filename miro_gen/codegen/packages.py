"""The package `__init__`s: built from the module contexts of this run, plus the generated
modules and subpackages that earlier runs left in the output folder.

A package re-exports every generated `*_idl` module in its folder, those of earlier runs
included, so IDL files can be compiled one at a time. What this run generates is known from
its contexts; a module only an earlier run wrote is read back (its `__all__` and the type
hashes of its classes). Other files in a package folder (a `miro-params` module, say) are
neither read nor listed.
"""

from __future__ import annotations

import ast as pyast
from dataclasses import dataclass
from pathlib import Path

from miro_gen.codegen.contexts import ModuleContext, PackageContext, isort_key
from miro_gen.runtime.registry import GENERATED_MARK as GENERATED_MARK  # what the templates write


@dataclass
class _ModuleNames:
    """What a package needs of one of its modules."""

    exports: list[str]
    type_hashes: dict[str, str]  # type hash -> class name


def package_contexts(modules: list[ModuleContext], outdir: Path) -> list[PackageContext]:
    """The `__init__` of every package the modules are in (and of the packages above)."""
    by_package: dict[str, dict[str, _ModuleNames]] = {}
    for m in modules:
        names = _ModuleNames(m.exports, m.type_hashes)
        by_package.setdefault(m.package, {}).setdefault(m.stem, names)  # the first one wins
    packages: set[str] = set()
    for m in modules:
        parts = m.package.split(".")
        packages.update(".".join(parts[:i]) for i in range(1, len(parts) + 1))
    subpackages: dict[str, set[str]] = {}  # package -> the names of its subpackages
    for package in packages:
        parent, _, name = package.rpartition(".")
        if parent:
            subpackages.setdefault(parent, set()).add(name)
    out = []
    for package in sorted(packages):
        folder = outdir / package.replace(".", "/")
        stems = dict(by_package.get(package, {}))
        for stem in _generated_on_disk(folder) - stems.keys():
            stems[stem] = _read_back(folder / f"{stem}.py")
        exports: dict[str, str] = {}
        hashes: dict[str, str] = {}
        for stem in sorted(stems, key=str.lower):  # later modules win, as star imports did
            exports.update(dict.fromkeys(stems[stem].exports, f"{package}.{stem}"))
            hashes.update(stems[stem].type_hashes)
        children = subpackages.get(package, set()) | _packages_on_disk(folder)
        out.append(
            PackageContext(
                package=package,
                modules=[f"{package}.{s}" for s in sorted(stems, key=str.lower)],
                subpackages=sorted(children, key=isort_key),  # as isort orders imports
                exports=exports,
                type_hashes=hashes,
            )
        )
    return out


def is_generated(path: Path) -> bool:
    """Whether a file was written by miro-idl (its first line says so)."""
    try:
        with open(path, encoding="utf-8") as fh:
            return fh.readline().startswith(GENERATED_MARK)
    except (OSError, UnicodeDecodeError):
        return False


def _generated_on_disk(folder: Path) -> set[str]:
    if not folder.is_dir():
        return set()
    return {f.stem for f in folder.glob("*_idl.py") if is_generated(f)}


def _packages_on_disk(folder: Path) -> set[str]:
    if not folder.is_dir():
        return set()
    return {
        d.name
        for d in folder.iterdir()
        if d.is_dir() and (d / "__init__.py").is_file() and is_generated(d / "__init__.py")
    }


def _read_back(path: Path) -> _ModuleNames:
    """The `__all__` and the classes' type hashes of a module an earlier run wrote."""
    try:
        tree = pyast.parse(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, SyntaxError, ValueError):
        return _ModuleNames([], {})
    exports: list[str] = []
    hashes: dict[str, str] = {}
    for node in tree.body:
        if isinstance(node, pyast.Assign) and any(
            isinstance(t, pyast.Name) and t.id == "__all__" for t in node.targets
        ):
            try:
                value = pyast.literal_eval(node.value)
            except ValueError:
                value = []
            exports = [v for v in value if isinstance(v, str)]
        elif isinstance(node, pyast.ClassDef):
            for stmt in node.body:
                if (
                    isinstance(stmt, pyast.Assign)
                    and any(
                        isinstance(t, pyast.Name) and t.id == "_type_hash" for t in stmt.targets
                    )
                    and isinstance(stmt.value, pyast.Constant)
                    and isinstance(stmt.value.value, str)
                ):
                    hashes[stmt.value.value] = node.name
    return _ModuleNames(exports, hashes)
