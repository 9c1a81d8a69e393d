"""Rendering and writing `miro-params` output: one module per compile-time file, and a package
`__init__` where no other tool owns one.

A package that `miro-idl` also generates (`Miro`) keeps miro-idl's `__init__`: parameter modules
are imported by their full name (`from Miro.SvcParameters import DevParameters`), and neither
tool's `--check` looks at the other's files. A package only miro-params writes gets a small
`__init__` of its own, marked as miro-params output.
"""

from __future__ import annotations

from pathlib import Path

from miro_gen.codegen.generate import GENERATED_MARK as IDL_MARK
from miro_gen.codegen.render import environment
from miro_gen.params.compiler.pymodel import GENERATED_MARK, PyParamsModule


def render_module(m: PyParamsModule) -> str:
    template = environment().get_template("params/module.py.j2")
    context = {
        "m": m,
        "imports": sorted(m.imports.items()),
        "sections": sorted(m.sections.items()),
    }
    return template.render(**context)


def _owner(path: Path) -> str | None:
    """Which tool wrote a file: "idl", "params", "user" or None when it does not exist."""
    try:
        with open(path, encoding="utf-8") as fh:
            first = fh.readline()
    except OSError:
        return None
    if first.startswith(IDL_MARK):
        return "idl"
    if first.startswith(GENERATED_MARK):
        return "params"
    return "user"


def generated_files(modules: list[PyParamsModule], outdir: Path) -> dict[str, str]:
    """Relative path -> content of every file miro-params owns for these modules."""
    files: dict[str, str] = {}
    packages: dict[str, tuple[str, list[str]]] = {}
    for m in modules:
        files[m.path] = render_module(m)
        parts = m.package.split(".")
        for i in range(1, len(parts) + 1):
            pkg = ".".join(parts[:i])
            ns, mods = packages.setdefault(pkg, (m.namespace or pkg, []))
            if i == len(parts):
                mods.append(f"{m.package}.{m.name}")
    for pkg, (ns, mods) in sorted(packages.items()):
        folder = pkg.replace(".", "/")
        init = outdir / folder / "__init__.py"
        if _owner(init) in ("idl", "user"):
            continue  # another tool (or the user) owns the package
        on_disk = sorted(
            f"{pkg}.{p.stem}"
            for p in (outdir / folder).glob("*.py")
            if p.name != "__init__.py" and _owner(p) == "params"
        )
        listed = sorted(set(mods) | set(on_disk), key=str.lower)
        files[f"{folder}/__init__.py"] = (
            environment()
            .get_template("params/package_init.py.j2")
            .render(namespace=ns.replace(".", "::"), modules=listed)
        )
        if "." not in pkg:  # PEP 561: mypy checks against it where it is installed
            files[f"{folder}/py.typed"] = ""
    return files
