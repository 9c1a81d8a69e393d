"""Naming topics, and making the types of a log decodable.

Which generated class has a type hash is miro_gen.runtime.registry's: the log tools use its
`find`, which imports, once, every generated package on the module search path, so that a log
of any type compiled on this machine decodes without configuration. Types that are not compiled
here are compiled from the data schemas in the log (`types_from_schemas`).
"""

from __future__ import annotations

import atexit
import importlib
import importlib.util
import os
import re
import shutil
import subprocess
import sys
import tempfile

ANY = "*"
# A log's schemas are compiled as untrusted input: no preprocessing, a size cap, and a compiler
# process that is stopped past these limits.
MAX_SCHEMA_BYTES = 1 << 20  # of all the schemas compiled together
COMPILE_SECONDS = 30.0
COMPILE_MEMORY = 2 << 30  # bytes of address space
# Comments and string or character literals, where a `#` is harmless.
_INERT = re.compile(r'//[^\n]*|/\*.*?\*/|"(?:\\.|[^"\\\n])*"|\'(?:\\.|[^\'\\\n])*\'', re.S)


def topic_name(domain: str, type_name: str) -> str:
    """The MCAP topic of events of `type_name` from `domain`: `domain/type`."""
    return f"{domain}/{type_name}"


def parse_topic(text: str) -> tuple[str, str]:
    """(domain, type) of `domain/type`; the domain may be a path (`lab/robot1/Odometry`), either
    part may be `*`. A bare `TYPE` means `*/TYPE`."""
    domain, sep, type_name = text.rpartition("/")
    if not sep:
        return ANY, text
    if not domain or not type_name:
        raise ValueError(f"{text!r} is not DOMAIN/TYPE")
    return domain, type_name


def matches(pattern: tuple[str, str], domain: str, type_name: str) -> bool:
    d, t = pattern
    return d in (ANY, domain) and t in (ANY, type_name)


def _declarations(schema: str) -> list[str]:
    """The top-level declarations of a data schema (`module X { ... };` blocks), as text."""
    out, depth, start = [], 0, 0
    for i, ch in enumerate(schema):
        if ch == "{":
            depth += 1
        elif ch == "}":
            depth -= 1
        elif ch == ";" and depth == 0:
            block = schema[start : i + 1].strip()
            if block:
                out.append(block)
            start = i + 1
    return out


def untrusted_schema_problem(schema: str) -> str | None:
    """Why a schema read from a log must not be compiled, or None. A data schema holds
    declarations only: a preprocessor directive (`#include "/etc/passwd"`, a macro bomb) is
    never part of one, so none is let through to the compiler."""
    bare = _INERT.sub(" ", schema)
    if "#" in bare or "%:" in bare or "??=" in bare:
        return "it has preprocessor directives (#include, #define ...): data schemas have none"
    return None


def types_from_schemas(schemas: list[str]) -> str | None:
    """Make the types of these data schemas (read from a log) decodable here: compile them with
    miro-idl into a temporary folder and import the packages. The log's schemas are the very text
    the types' hashes were made from, so the compiled types have the recorded hashes. Returns
    why it could not (None when it did): a schema is not a plain data schema or is too large,
    a package of that name exists here already, the compiler took too long or too much memory,
    or the schemas do not compile together."""
    blocks: list[str] = []
    for schema in schemas:
        problem = untrusted_schema_problem(schema)
        if problem is not None:
            return f"a schema cannot be compiled: {problem}"
        for block in _declarations(schema):
            if block not in blocks:  # types shared by several schemas, once
                blocks.append(block)
    if not blocks:
        return None
    if sum(len(b.encode()) for b in blocks) > MAX_SCHEMA_BYTES:
        return f"its schemas are larger than {MAX_SCHEMA_BYTES} bytes"
    folder = tempfile.mkdtemp(prefix="miro-log-types-")
    atexit.register(shutil.rmtree, folder, True)
    source = os.path.join(folder, "schemas.idl")
    with open(source, "w", encoding="utf-8") as f:
        f.write("\n".join(blocks) + "\n")
    out = os.path.join(folder, "generated")
    try:
        compiled = subprocess.run(
            [sys.executable, "-m", "miro_gen.cli.idl", "-o", out, source],
            capture_output=True,
            text=True,
            errors="replace",
            cwd=folder,
            env=dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in sys.path if p)),
            timeout=COMPILE_SECONDS,
            preexec_fn=_limit_compiler,
        )
    except subprocess.TimeoutExpired:
        return f"compiling its schemas took longer than {COMPILE_SECONDS:g} s"
    if compiled.returncode != 0:
        first = (compiled.stderr.strip().splitlines() or ["miro-idl failed"])[0]
        if compiled.returncode < 0 or "MemoryError" in compiled.stderr:
            first = "the compiler ran out of its time or memory"
        return f"its schemas do not compile: {first}"
    packages = sorted(n for n in os.listdir(out) if os.path.isdir(os.path.join(out, n)))
    taken = [n for n in packages if importlib.util.find_spec(n) is not None]
    if taken:
        return f"a package {taken[0]} without these types exists here already"
    sys.path.insert(0, out)
    for name in packages:
        try:
            importlib.import_module(name)
        except Exception as e:  # types too large to exist (an array of 10^20 elements)
            return f"its compiled types cannot be loaded: {type(e).__name__}: {e}"
    return None


def _limit_compiler() -> None:
    """In the compiler's process, before it starts: bound its memory and CPU time."""
    import resource

    resource.setrlimit(resource.RLIMIT_AS, (COMPILE_MEMORY, COMPILE_MEMORY))
    cpu = int(COMPILE_SECONDS) + 1
    resource.setrlimit(resource.RLIMIT_CPU, (cpu, cpu))
