"""Shared machinery of the parameter tests (tests/params/test_params_*.py): compiling
compile-time files with the real `miro-params` command into a temporary folder and importing what
it wrote."""

from __future__ import annotations

import importlib
import sys
import textwrap
from pathlib import Path
from types import ModuleType

from hypothesis import HealthCheck, settings
from miro_cli import REPO, run_miro_params

PARAMS = REPO / "params"
ALL_TYPES = REPO / "tests" / "params" / "AllTypes.xml"

# reproducible, no example database, no deadline
SETTINGS = settings(
    max_examples=40,
    derandomize=True,
    deadline=None,
    database=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)


def write(path: Path, text: str) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(textwrap.dedent(text).lstrip(), encoding="utf-8")
    return path


def compile_params(out: Path, *files: Path | str, extra: tuple[str, ...] = ()) -> None:
    """Run `miro-params -I idl -o OUT FILES`; fail the test with its stderr if it fails."""
    result = run_miro_params("-I", str(REPO / "idl"), *extra, "-o", str(out), *map(str, files))
    assert result.returncode == 0, result.stderr


def import_generated(out: Path, module: str) -> ModuleType:
    """Import `module` from the folder `out` (put first on sys.path for this import; a package
    of the same name imported earlier from elsewhere is forgotten first)."""
    top = module.split(".")[0]
    for name in [m for m in sys.modules if m == top or m.startswith(top + ".")]:
        del sys.modules[name]
    sys.path.insert(0, str(out))
    try:
        importlib.invalidate_caches()
        return importlib.import_module(module)
    finally:
        sys.path.remove(str(out))


def compile_and_import(tmp: Path, xml: str, module: str, name: str = "P.xml") -> ModuleType:
    """Write a compile-time file, compile it and import its module."""
    src = write(tmp / "src" / name, xml)
    compile_params(tmp / "out", src)
    return import_generated(tmp / "out", module)


def all_types(tmp: Path) -> ModuleType:
    """tests/params/AllTypes.xml compiled and imported (module PTypes.AllTypes)."""
    compile_params(tmp, ALL_TYPES)
    return import_generated(tmp, "PTypes.AllTypes")
