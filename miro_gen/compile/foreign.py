"""Schema text from elsewhere, compiled under one policy.

A log's data schemas (`miro log echo`, the log player) and a running service's interface and
data schemas (`miro call`, `miro list`, `miro pub`, `miro echo`) are written by someone else: a
file from another machine, a service on the network. Such text is compiled only

* without preprocessor directives: a schema holds declarations only (codegen/schema.py and
  codegen/interface_schema.py write none), so an `#include "/etc/passwd"` or a macro bomb is
  refused before anything reads it;
* up to MAX_SCHEMA_BYTES;
* in a process of its own (`python -m miro_gen.compile`, see `__main__.py`), stopped past
  COMPILE_SECONDS and unable to take more than COMPILE_MEMORY, so that input built to make the
  compiler spin or swell costs the caller one message.

This module imports no compiler: the run time (eventlog) uses it, and the compilers run only
in that other process.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from collections.abc import Sequence
from pathlib import Path

MAX_SCHEMA_BYTES = 1 << 20  # of all the schemas compiled together
COMPILE_SECONDS = 30.0  # of the compiler's process, CPU and wall-clock
COMPILE_MEMORY = 2 << 30  # bytes of address space of the compiler's process
SOURCE = "schema.idl"  # in the folder: the text compiled
PACKAGES = "py"  # in the folder: the generated packages
AST = "ast.json"  # in the folder: the resolved declarations (miro-idl --ast-json)
# The compiler's process (it limits itself first thing: no code runs in this process between
# fork and exec, which is not safe in a process with threads, as the live tools are).
COMMAND = [sys.executable, "-m", "miro_gen.compile"]
MAX_GIVEN_BYTES = 16 * MAX_SCHEMA_BYTES  # of several schemas before their shared types merge
# What a directive may hide in: comments and literals, found left to right in one pass (`re.sub`);
# a comment or a literal left open runs to the end of the file (a comment) or of the line (a
# literal; an escaped line end does not continue it here, so that nothing after it can pass for
# text). What remains may hold no `#`, nor its digraph or trigraph.
_INERT = re.compile(
    r'//[^\n]*|/\*.*?(?:\*/|\Z)|"(?:\\[^\n]|[^"\\\n])*"?|\'(?:\\[^\n]|[^\'\\\n])*\'?', re.S
)
_DIRECTIVE_MARKS = ("#", "%:", "??=")
_BRACES = re.compile(r"[{};]")


class ForeignSchemaError(Exception):
    """A schema from elsewhere is refused, or does not compile here (one line)."""


def refusal(text: str) -> str | None:
    """Why schema text from elsewhere must not be compiled at all, or None."""
    if len(text) > MAX_SCHEMA_BYTES or len(text.encode("utf-8", "replace")) > MAX_SCHEMA_BYTES:
        return f"the schema is larger than {MAX_SCHEMA_BYTES} bytes (the most taken from elsewhere)"
    marked = any(mark in text for mark in _DIRECTIVE_MARKS)  # else nothing to look for
    if marked and any(mark in _INERT.sub(" ", text) for mark in _DIRECTIVE_MARKS):
        return "the schema has preprocessor directives (#include, #define ...): schemas have none"
    return None


def joined(schemas: Sequence[str]) -> str:
    """Several data schemas as one text: their top-level declarations (`module X { ... };`),
    each once (types shared by several schemas are in each)."""
    if len(schemas) == 1:
        return schemas[0]
    blocks: list[str] = []
    for schema in schemas:
        for block in _declarations(schema):
            if block not in blocks:
                blocks.append(block)
    return "\n".join(blocks) + "\n" if blocks else ""


def _declarations(schema: str) -> list[str]:
    out, depth, start = [], 0, 0
    for m in _BRACES.finditer(schema):
        ch = m.group()
        if ch == "{":
            depth += 1
        elif ch == "}":
            depth -= 1
        elif depth == 0:
            block = schema[start : m.end()].strip()
            if block:
                out.append(block)
            start = m.end()
    return out


def compile_foreign(schemas: Sequence[str], folder: Path) -> None:
    """Compile schema text from elsewhere into `folder` (made if missing): its packages in
    `folder/py`, its declarations in `folder/ast.json`. ForeignSchemaError (one line) when it
    is refused, or does not compile within the limits."""
    if sum(len(s) for s in schemas) > MAX_GIVEN_BYTES:
        raise ForeignSchemaError(
            f"the schemas are larger than {MAX_GIVEN_BYTES} bytes together (the most taken "
            "from elsewhere)"
        )
    for schema in schemas:
        why = refusal(schema)
        if why is not None:
            raise ForeignSchemaError(why)
    text = joined(schemas)
    why = refusal(text)  # the sizes together
    if why is not None:
        raise ForeignSchemaError(why)
    folder.mkdir(parents=True, exist_ok=True)
    (folder / SOURCE).write_text(text, encoding="utf-8")
    limits = ["--cpu", str(int(COMPILE_SECONDS) + 1), "--memory", str(COMPILE_MEMORY)]
    try:
        done = subprocess.run(
            [*COMMAND, *limits, str(folder)],
            capture_output=True,
            text=True,
            errors="replace",
            cwd=folder,
            env=dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in sys.path if p)),
            stdin=subprocess.DEVNULL,
            timeout=COMPILE_SECONDS,
        )
    except subprocess.TimeoutExpired:
        raise ForeignSchemaError(
            f"compiling the schema took longer than {COMPILE_SECONDS:g} s"
        ) from None
    if done.returncode != 0:
        if done.returncode < 0 or "MemoryError" in done.stderr:
            raise ForeignSchemaError("compiling the schema ran out of its time or memory")
        first = (done.stderr.strip().splitlines() or ["the compiler failed"])[0]
        raise ForeignSchemaError(f"the schema does not compile here: {first}")
