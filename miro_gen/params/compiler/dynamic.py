"""Parameter classes straight from compile-time files, without writing generated/: what
`miro-params --xsd` and `miro params show/validate` work on.

The files (and the files they include) are compiled and rendered exactly as `miro-params` would
write them, and each rendered module is loaded under its own name, included files first. The
code loaded is the generator's output, never text from the input files.
"""

from __future__ import annotations

import importlib
import sys
import types
from dataclasses import dataclass
from pathlib import Path

from miro_gen.diagnostics import CompileError, Diagnostics
from miro_gen.params.compiler.build import build_modules
from miro_gen.params.compiler.generate import render_module
from miro_gen.params.compiler.loader import Loader
from miro_gen.params.compiler.model import ItemDecl, ParamsFile
from miro_gen.params.compiler.pymodel import PyParamsModule
from miro_gen.params.runtime import Config


@dataclass
class ParamClass:
    """A generated class with what its compile-time item says about it."""

    cls: type[Config]
    item: ItemDecl
    target: bool  # declared in a file given on the command line (not only included)

    @property
    def abstract(self) -> bool:
        """final="false": a base of other classes, not listed unless asked."""
        return not self.item.final

    @property
    def names(self) -> list[str]:
        """The names a run-time document may use for it: `My`, `MyParameters`,
        `Test::MyParameters`, `Test::My`."""
        ns = self.item.file.namespace
        out = [self.item.name, self.item.class_name]
        if ns:
            out += [f"{ns}::{self.item.class_name}", f"{ns}::{self.item.name}"]
        return [n for n in out if n]


def load(
    paths: list[str],
    include_dirs: list[str],
    diag: Diagnostics,
    python_classes: dict[str, str] | None = None,
) -> list[ParamClass]:
    """The classes of `paths` and of the files they include; raises `CompileError`. A dummy
    item gets the stand-in made from its declaration: the tools check what it declares."""
    loader = Loader(include_dirs, diag)
    targets: list[ParamsFile] = []
    for path in paths:
        f = loader.load(Path(path))
        if f is not None:
            targets.append(f)
    files = list(loader.files.values())  # included files come before their includers
    modules = (
        build_modules(files, files, {}, diag, python_classes, tools=True)
        if not diag.has_errors
        else []
    )
    diag.check()
    out: list[ParamClass] = []
    target_paths = {f.path.resolve() for f in targets}
    for f, m in zip(files, modules, strict=True):
        module = _install(m, diag)
        for c in m.classes:
            if c.decl.file is not f or c.dummy_target is not None:
                continue  # stand-ins of other files' dummy items; IDL layouts
            cls = getattr(module, c.name, None)
            if isinstance(cls, type) and issubclass(cls, Config):
                out.append(ParamClass(cls, c.decl, f.path.resolve() in target_paths))
    return out


def _install(m: PyParamsModule, diag: Diagnostics) -> types.ModuleType:
    name = f"{m.package}.{m.name}"
    _ensure_package(m.package)
    module = types.ModuleType(name)
    module.__file__ = f"<miro-params {m.source}>"
    sys.modules[name] = module
    code = compile(render_module(m), module.__file__, "exec")
    try:
        exec(code, module.__dict__)  # the generator's own output (see the module docstring)
    except Exception as e:  # e.g. a helper module that cannot be imported
        del sys.modules[name]
        diag.error(None, f"cannot load the module generated for {m.source}: {e}")
        raise CompileError(diag.items) from e
    parent = sys.modules[m.package]
    setattr(parent, m.name, module)
    return module


def _ensure_package(package: str) -> None:
    """Import a package (or make an empty one, for packages only miro-params would write)."""
    parts = package.split(".")
    for i in range(1, len(parts) + 1):
        name = ".".join(parts[:i])
        if name in sys.modules:
            continue
        try:
            importlib.import_module(name)
        except ImportError:
            module = types.ModuleType(name)
            module.__path__ = []
            sys.modules[name] = module
