"""Generated packages that span several folders on sys.path.

One IDL module or makeParams namespace can be written into several output folders: miro-idl's
and miro-params' (`Miro.Example_idl` in one, `Miro.SvcParameters` in another), the installed
project's `Miro` and a user's own IDL that reopens `module Miro`, the `Video` parameters of two
builds. Each folder holds an `__init__.py`, and Python runs only the first one it finds. So the
`__init__` of every generated package, whichever runs:

- extends `__path__` over every folder of the package (`package_path`), so that the modules of
  each folder import;
- serves the names of every folder's IDL modules (`lazy_names`): a miro-idl `__init__` lists
  its folder's names (`_EXPORTS`, `_TYPE_HASHES`, `_SUBMODULES`, `__all__`); those of the other
  folders are read from their `__init__.py` as data (never run) and added, the first folder's
  winning a name both define. Importing the package imports none of its modules: each is
  imported when one of its names is first used.

Type checkers do not run this: mypy finds each module file in whichever folder on its search
path holds it, and takes a package's `__init__` (its names) from the first folder.
"""

from __future__ import annotations

import importlib
import importlib.machinery
import os
import pkgutil
import sys
from collections.abc import Callable, MutableMapping
from typing import TYPE_CHECKING, Any

from miro_gen.runtime.registry import GENERATED_MARK

if TYPE_CHECKING:
    import ast

__all__ = ["lazy_names", "package_path"]

# The first line of an `__init__` that miro-idl wrote (it lists its folder's names).
IDL_MARK = GENERATED_MARK.encode()


def package_path(path: list[str], name: str) -> list[str]:
    """`__path__` of a generated package: every folder of that name the import system can find
    (sys.path entries, or the parent package's folders, and installed packages that a finder
    maps, such as setuptools' editable installs), its own first."""
    out = list(pkgutil.extend_path(path, name))
    for finder in sys.meta_path:
        if isinstance(finder, type) and issubclass(finder, importlib.machinery.PathFinder):
            continue
        find_spec = getattr(finder, "find_spec", None)
        if find_spec is None:
            continue
        try:
            spec = find_spec(name, None)
        except Exception:  # a finder that cannot answer for this name
            continue
        for folder in (spec.submodule_search_locations or []) if spec is not None else []:
            if folder not in out:
                out.append(folder)
    return out


def lazy_names(
    namespace: MutableMapping[str, Any],
) -> tuple[Callable[[str], object], Callable[[], list[str]]]:
    """`__getattr__` and `__dir__` for the generated package whose `__init__` has these globals
    (`__path__` already extended): the names of its IDL modules, in all its folders, each
    imported on first use and then kept in the package."""
    package = str(namespace["__name__"])
    exports: dict[str, str] = namespace.setdefault("_EXPORTS", {})
    hashes: dict[str, str] = namespace.setdefault("_TYPE_HASHES", {})
    submodules = set(namespace.get("_SUBMODULES", ()))
    public: list[str] = namespace.setdefault("__all__", [])
    own = _folder_of(namespace.get("__file__"))
    for folder in namespace.get("__path__", []):
        if own is not None and _same_folder(folder, own):
            continue
        tables = _read_tables(os.path.join(folder, "__init__.py"))
        for key, value in tables.get("_EXPORTS", {}).items():
            exports.setdefault(key, value)
        for key, value in tables.get("_TYPE_HASHES", {}).items():
            hashes.setdefault(key, value)
        submodules.update(tables.get("_SUBMODULES", ()))
        public += [n for n in tables.get("__all__", ()) if n not in public]
    namespace["_SUBMODULES"] = frozenset(submodules)

    def __getattr__(name: str) -> object:
        """Import what a name needs on first use, and keep it in the package for the next."""
        if name in exports:
            value = getattr(importlib.import_module(exports[name]), name)
        elif name in submodules:
            value = importlib.import_module(f"{package}.{name}")
        else:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        namespace[name] = value
        return value

    def __dir__() -> list[str]:
        return sorted({*namespace, *public})

    return __getattr__, __dir__


def _folder_of(file: object) -> str | None:
    return os.path.dirname(file) if isinstance(file, str) else None


def _same_folder(a: str, b: str) -> bool:
    try:
        return os.path.samefile(a, b)
    except OSError:
        return a == b


_TABLES = ("_EXPORTS", "_TYPE_HASHES", "_SUBMODULES", "__all__")


def _read_tables(init: str) -> dict[str, Any]:
    """The names a miro-idl `__init__` lists, read as data; {} for any other file (miro-params'
    `__init__`, a user's) or one that cannot be read."""
    import ast  # only for packages that span several folders

    try:
        with open(init, "rb") as f:
            if not f.readline().startswith(IDL_MARK):
                return {}
            tree = ast.parse(f.read())
    except (OSError, SyntaxError, ValueError):
        return {}
    out: dict[str, Any] = {}
    for node in tree.body:
        target: ast.expr
        value: ast.expr | None
        if isinstance(node, ast.AnnAssign):
            target, value = node.target, node.value
        elif isinstance(node, ast.Assign) and len(node.targets) == 1:
            target, value = node.targets[0], node.value
        else:
            continue
        if not (isinstance(target, ast.Name) and target.id in _TABLES and value is not None):
            continue
        if isinstance(value, ast.Call) and len(value.args) == 1:  # frozenset([...])
            value = value.args[0]
        try:
            out[target.id] = ast.literal_eval(value)
        except ValueError:
            continue
    return out
