"""The Jinja environment of the Python back end: templates/idl/ and the filters they use."""

from __future__ import annotations

import textwrap
from functools import cache
from pathlib import Path
from typing import Any

import jinja2

from miro_gen import __version__
from miro_gen.codegen.model import PyModule, isort_key

LINE = 100


def template_dir() -> Path:
    """templates/ in a source checkout, or the copy installed inside the package."""
    checkout = Path(__file__).resolve().parents[2] / "templates"
    if (checkout / "idl").is_dir():
        return checkout
    return Path(__file__).resolve().parents[1] / "templates"


def pyrepr(value: Any) -> str:
    """A Python literal: strings always in double quotes (as ruff formats them)."""
    if isinstance(value, str):
        text = repr(value)
        if text.startswith("'") and '"' not in value:
            text = '"' + text[1:-1].replace("\\'", "'") + '"'
        return text
    return repr(value)


def docstring(text: str | None, indent: int, fallback: str | None = None) -> str:
    """A docstring literal for IDL doc text, wrapped to the line length and escaped."""
    body = (text or fallback or "").strip()
    body = body.replace("\\", "\\\\").replace('"""', '\\"\\"\\"')
    width = LINE - indent - 6
    lines = [line for p in body.split("\n") for line in _wrap_block(p, width)]
    if len(lines) == 1:
        end = " " if lines[0].endswith('"') else ""  # not four quotes in a row
        return f'"""{lines[0]}{end}"""'
    pad = " " * indent
    rest = "\n".join(pad + line if line else "" for line in lines[1:])
    return f'"""{lines[0]}\n{rest}\n{pad}"""'


def _wrap_block(line: str, width: int) -> list[str]:
    """One line of doc text, wrapped to `width` only if it is longer: the author's line breaks
    (Doxygen `@param` lines, lists) are kept. Continuation lines keep a list item's indent."""
    if len(line) <= width:
        return [line]
    lead = line[: len(line) - len(line.lstrip())]
    return textwrap.wrap(
        line, width, initial_indent="", subsequent_indent=lead, break_on_hyphens=False
    ) or [line]


@cache
def environment() -> jinja2.Environment:
    env = jinja2.Environment(
        loader=jinja2.FileSystemLoader(str(template_dir())),
        trim_blocks=True,
        lstrip_blocks=True,
        keep_trailing_newline=True,
        undefined=jinja2.StrictUndefined,
        autoescape=False,
    )
    env.filters["pyrepr"] = pyrepr
    env.filters["docstring"] = docstring
    env.globals["version"] = __version__
    return env


def render_module(module: PyModule) -> str:
    """The module's code; it exempts itself from the line-length rule only when it must
    (long IDL names and literals can make lines longer than the project's limit)."""
    template = environment().get_template("idl/module.py.j2")
    text = template.render(m=module, noqa=sorted(module.noqa))
    if any(len(line) > LINE for line in text.split("\n")):
        text = template.render(m=module, noqa=sorted({*module.noqa, "E501"}))
    return text


def render_package_init(
    doc: str,
    modules: list[str],
    subpackages: list[tuple[str, str]],
    exports: list[tuple[str, str]],
    submodules: list[str],
    hashes: list[tuple[str, str]],
) -> str:
    """A package `__init__` that imports its modules' names lazily (see the template); like a
    module, it exempts itself from the line-length rule only when it must."""
    public = sorted(
        {name for name, _ in exports} | {name for _, name in subpackages}, key=isort_key
    )
    template = environment().get_template("idl/package_init.py.j2")
    context = {
        "doc": doc,
        "modules": modules,
        "subpackages": subpackages,
        "exports": exports,
        "submodules": submodules,
        "public": public,
        "hashes": hashes,
    }
    text = template.render(long_lines=False, **context)
    if any(len(line) > LINE for line in text.split("\n")):
        text = template.render(long_lines=True, **context)
    return text
