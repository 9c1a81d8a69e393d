"""Code for a schema a running service gave: compiled once, kept, loaded when needed.

`miro call` and `miro pub` need the stub of an interface, or the class of a payload, that may
not be compiled on the caller's machine. The service's interface or data schema is compiled as
text from elsewhere (miro_gen.compile.foreign: no preprocessor directives, a size cap, in a
process of its own with a time and a memory cap) into a folder named after the text's hash (in
`$MIRO_CACHE`, else in `schemas/` of the per-user cache, `~/.cache/miro-gen/`), with its AST
JSON beside it; a later call with the same schema loads that. The hash names the exact text, so
what is cached never goes stale.

One process loads one version of a package: a schema whose package (`Miro`) is loaded already
from elsewhere is refused with a message, unless the loaded package has the very classes
needed (same repository id and hash), which are then used as they are.
"""

from __future__ import annotations

import hashlib
import importlib
import json
import os
import shutil
import sys
import tempfile
from pathlib import Path
from typing import Any

from miro_gen.compile.foreign import AST, PACKAGES, ForeignSchemaError, compile_foreign, refusal
from miro_gen.runtime.rpc import Stub


class SchemaError(Exception):
    """The schema cannot be compiled or loaded here (one line)."""


def cache_root() -> Path | None:
    """Where compiled schemas are kept: $MIRO_CACHE, else `schemas/` in the per-user cache
    (miro_gen.cache); None when there is none."""
    given = os.environ.get("MIRO_CACHE")
    if given:
        return Path(given)
    from miro_gen.cache import cache_dir

    folder = cache_dir()
    return Path(folder) / "schemas" if folder else None


class Compiled:
    """A schema compiled into `folder`: `py/` (the packages) and `ast.json`."""

    def __init__(self, folder: Path) -> None:
        self.folder = folder
        self.ast: dict[str, Any] = json.loads((folder / AST).read_text(encoding="utf-8"))

    @property
    def packages(self) -> list[str]:
        py = self.folder / PACKAGES
        return sorted(p.name for p in py.iterdir() if (p / "__init__.py").is_file())

    def declaration(self, name: str) -> dict[str, Any] | None:
        """The AST JSON declaration of a scoped name or repository id."""
        for d in self.ast["declarations"]:
            if name in (d["name"], d["repo_id"]):
                return dict(d)
        return None

    def load(self) -> None:
        """Make the packages importable, and import them."""
        py = str(self.folder / PACKAGES)
        for name in self.packages:
            loaded = sys.modules.get(name)
            if loaded is not None and not str(getattr(loaded, "__file__", "")).startswith(py):
                raise SchemaError(
                    f"another package {name} is loaded in this process already; the "
                    "service's version of it cannot be loaded beside it"
                )
        if py not in sys.path:
            sys.path.insert(0, py)
        for name in self.packages:
            importlib.import_module(name)


def compile_schema(text: str) -> Compiled:
    """The schema `text` a service gave, compiled (from the cache when it was compiled before):
    as schema text from elsewhere (miro_gen.compile.foreign: no directives, capped, in a
    process of its own). SchemaError (one line) when it is refused or does not compile."""
    why = refusal(text)  # before anything is made for it, or a cached one is looked for
    if why is not None:
        raise SchemaError(why)
    digest = hashlib.sha256(text.encode("utf-8")).hexdigest()
    root = cache_root()
    if root is not None and (root / digest / AST).is_file():
        return Compiled(root / digest)
    try:
        assert root is not None
        root.mkdir(parents=True, exist_ok=True)
        work = Path(tempfile.mkdtemp(prefix=".new-", dir=root))
        folder = root / digest
    except (AssertionError, OSError):  # no cache here: a folder for this process only
        work = Path(tempfile.mkdtemp(prefix="miro-schema-"))
        folder = work
    try:
        compile_foreign([text], work)
    except ForeignSchemaError as e:
        shutil.rmtree(work, ignore_errors=True)
        raise SchemaError(str(e)) from None
    if work != folder:
        try:
            os.replace(work, folder)
        except OSError:  # another process cached it meanwhile: use theirs
            shutil.rmtree(work, ignore_errors=True)
    return Compiled(folder)


def loaded_stub(repo_id: str, interface_hash: str) -> type[Stub] | None:
    """A stub class of this interface (same hash) that this process has loaded already."""
    for module in list(sys.modules.values()):
        for value in list(vars(module).values()) if module is not None else []:
            if (
                isinstance(value, type)
                and issubclass(value, Stub)
                and value.__dict__.get("_repo_id") == repo_id
                and value.__dict__.get("_interface_hash") == interface_hash
            ):
                return value
    return None


def stub_class(compiled: Compiled, repo_id: str) -> type[Stub]:
    """The stub of interface `repo_id` from `compiled` (loaded here first)."""
    decl = compiled.declaration(repo_id)
    if decl is None:
        raise SchemaError(f"the schema has no interface {repo_id}")
    compiled.load()
    parts = decl["name"].split("::")
    obj: Any = importlib.import_module(parts[0])
    for part in parts[1:]:
        obj = getattr(obj, part, None) or getattr(obj, "_" + part, None)
        if obj is None:
            break
    if not (isinstance(obj, type) and issubclass(obj, Stub)):
        raise SchemaError(f"no stub of {decl['name']} in the compiled schema")
    return obj


def data_class(compiled: Compiled, scoped_name: str) -> type[Any]:
    """The class of data type `scoped_name` from `compiled` (loaded here first)."""
    compiled.load()
    parts = scoped_name.split("::")
    obj: Any = importlib.import_module(parts[0])
    for part in parts[1:]:
        obj = getattr(obj, part, None)
        if obj is None:
            raise SchemaError(f"no type {scoped_name} in the compiled schema")
    return obj  # type: ignore[no-any-return]
