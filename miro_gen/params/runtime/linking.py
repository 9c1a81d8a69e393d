"""How generated modules find the modules they need: other generated modules (with a message
naming the compile-time file to compile when one is missing), hand-written classes of `dummy`
items (with a message naming the module and class to write), and the other folders a package
of parameter modules is spread over (`Video` in two output folders: `package_path`, which
miro-idl's packages share)."""

from __future__ import annotations

import importlib
from typing import Any

from miro_gen.params.runtime.config import Config
from miro_gen.runtime.packages import package_path

__all__ = ["hand_written", "missing_module", "package_path"]


def _is_missing(error: ModuleNotFoundError, module: str) -> bool:
    name = error.name or ""
    return bool(name) and (module == name or module.startswith(name + "."))


def missing_module(error: ModuleNotFoundError, module: str, source: str) -> None:
    """Raise an ImportError naming the compile-time file whose generated module `module` is
    missing; return (for the caller to re-raise) when something else is missing."""
    if _is_missing(error, module):
        raise ImportError(
            f"no module {module}: it is generated from {source}; compile it with "
            f"`miro-params -o OUTDIR {source}` into a folder on sys.path",
            name=module,
        ) from None


def hand_written(module: str, cls: str, item: str, declared: str) -> type[Config]:
    """The hand-written class of a dummy item, from the module a `python_class` global names."""
    what = (
        f"{item} is a dummy item ({declared}): its class is written by hand. Write "
        f"class {cls}(miro_gen.params.Config) in the module {module} "
        f"({module.replace('.', '/')}.py, on sys.path)"
    )
    try:
        found = importlib.import_module(module)
    except ModuleNotFoundError as e:
        if _is_missing(e, module):
            raise ImportError(f"no module {module}: {what}", name=module) from None
        raise
    target: Any = getattr(found, cls, None)
    if not (isinstance(target, type) and issubclass(target, Config)):
        raise ImportError(f"{module} has no class {cls} deriving from Config: {what}", name=module)
    return target
