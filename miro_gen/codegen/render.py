"""The Jinja environment of the code generators (templates/), its filters, and the rendering of
the Python back end's contexts into file contents.

Filters: `pyrepr` (a Python literal), `docstring` (a docstring literal, wrapped) and `wrap` with
the global `bracket` (line breaking, see layout.py). Templates do no arithmetic and no layout
decisions of their own.
"""

from __future__ import annotations

import re
import textwrap
import zlib
from collections.abc import Iterable, MutableMapping
from functools import cache
from types import FunctionType
from typing import Any

import jinja2
import jinja2.filters
from jinja2.runtime import Macro

from miro_gen import __version__, resources
from miro_gen.cache import cache_dir
from miro_gen.codegen.contexts import ModuleContext, PackageContext
from miro_gen.codegen.layout import bracket, wrap

LINE = 100

# What every generated file exempts itself from, so that it passes ruff in any project, whatever
# rules the project selects and wherever it keeps the generated packages: the order of imports
# is the generator's (isort would group generated packages as first or third party, depending on
# the project's layout: `# isort: skip_file`, which isort itself honours too); line lengths are
# the templates' and IDL's, module and package names are IDL's (`Example_idl`, `Miro`: N999 is in
# ruff's default rules); and unused exemptions are not reported (RUF100), since which of these
# rules apply is the project's choice. The layout is the templates' too (`# fmt: off`, to the end
# of the file: ruff's formatter and black keep it whatever line length the project formats to).
LINT_EXEMPTIONS = ("E501", "N999", "RUF100")


def pyrepr(value: Any) -> str:
    """A Python literal: strings always in double quotes (as ruff formats them)."""
    if isinstance(value, str):
        if _plain(value):  # names and schema lines: no quote, backslash or control but a last \n
            return f'"{value[:-1]}\\n"' if value[-1:] == "\n" else f'"{value}"'
        return _string_literal(value)
    return repr(value)


_plain = re.compile(r"[ !#-\[\]-~]*\n?").fullmatch  # printable ASCII but " and \; a last \n


def _string_literal(value: str) -> str:
    text = repr(value)
    if text.startswith("'") and '"' not in value:
        text = '"' + text[1:-1].replace("\\'", "'") + '"'
    return text


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


def _bytecode_cache(env: jinja2.Environment) -> jinja2.BytecodeCache | None:
    """Templates compiled by an earlier run, per user. Jinja checks a compiled template against
    its source only; how a template calls each filter and global (what it passes them) is
    compiled in too, so the cache's file names hold a digest of those."""
    folder = cache_dir()
    if folder is None:
        return None
    calls = sorted(
        (kind, name, str(getattr(f, "jinja_pass_arg", "")))
        for kind, names in (("filter", env.filters), ("global", env.globals))
        for name, f in names.items()
    )
    digest = zlib.crc32(repr(calls).encode())
    return jinja2.FileSystemBytecodeCache(folder, f"__jinja2_{digest:08x}_%s.cache")


class _Context(jinja2.runtime.Context):
    """Jinja's context with a shorter way to call macros and plain functions (the templates'
    `bracket`, `lint_header`): what `Context.call` does for them, without first asking each
    whether it wants the context passed in (a tenth of the rendering time)."""

    def call(__self, __obj: Any, *args: Any, **kwargs: Any) -> Any:
        kind = type(__obj)
        if kind is not Macro and (kind is not FunctionType or hasattr(__obj, "jinja_pass_arg")):
            return super().call(__obj, *args, **kwargs)
        if kwargs:
            kwargs.pop("_block_vars", None)
            kwargs.pop("_loop_vars", None)
        try:
            return __obj(*args, **kwargs)
        except StopIteration:
            return __self.environment.undefined(
                "value was undefined because a callable raised a StopIteration exception"
            )


class _Environment(jinja2.Environment):
    """Jinja's environment for templates that render many times in one short run:

    * each template's globals are one dict made when it is loaded (Jinja overlays them on
      the environment's with a ChainMap, which every `include` and `import` then walks; the
      environment's globals here are set before any template is loaded and never change);
    * the filters that have an async variant are their synchronous selves (this environment
      is not async: the wrapper would only ask, at every call)."""

    def make_globals(self, d: MutableMapping[str, Any] | None) -> MutableMapping[str, Any]:
        return {**self.globals, **(d or {})}


# (The synchronous functions take the same arguments as their async-aware wrappers.)
_SYNC_FILTERS = {"join": jinja2.filters.sync_do_join, "map": jinja2.filters.sync_do_map}


@cache
def environment() -> jinja2.Environment:
    env = _Environment(
        loader=jinja2.FileSystemLoader(str(resources.template_dir())),
        trim_blocks=True,
        lstrip_blocks=True,
        keep_trailing_newline=True,
        undefined=jinja2.StrictUndefined,
        autoescape=False,
        auto_reload=False,  # templates do not change during a run: no stat per use
    )
    env.context_class = _Context
    env.filters.update(_SYNC_FILTERS)
    env.filters["pyrepr"] = pyrepr
    env.filters["docstring"] = docstring
    env.filters["wrap"] = wrap
    env.globals["bracket"] = bracket
    env.globals["lint_header"] = lint_header
    env.globals["version"] = __version__
    env.bytecode_cache = _bytecode_cache(env)
    return env


def lint_header(extra: Iterable[str] = ()) -> str:
    """The lines after a generated file's header comments that exempt it from the formatter
    and from the lint rules it cannot follow in every project (LINT_EXEMPTIONS), plus `extra`
    rules (a module's names)."""
    codes = ", ".join(sorted({*LINT_EXEMPTIONS, *extra}))
    return f"# isort: skip_file\n# fmt: off\n# ruff: noqa: {codes}"


def preload() -> None:
    """Load the code generator's templates now (from the bytecode cache, else compiling them):
    before processes are forked to render, so that they do not each load them."""
    env = environment()
    for name in env.list_templates(filter_func=lambda name: name.startswith("idl/")):
        env.get_template(name)


def render_module(module: ModuleContext) -> str:
    """The code of a module."""
    return environment().get_template("idl/module.py.j2").render(m=module)


def render_package_init(package: PackageContext) -> str:
    """A package `__init__` that imports its modules' names lazily (see the template)."""
    return environment().get_template("idl/package_init.py.j2").render(p=package)
