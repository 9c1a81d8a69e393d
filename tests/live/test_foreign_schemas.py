"""Schema text from elsewhere has one policy (miro_gen.compile.foreign): a service on the network
that answers `interface_schema` with `#include "FILE"`, or with 10 MB of IDL, gets one line from
`miro call` and `miro list`, and the file is never read (its content, a string made for the
test, shows nowhere). Before, the live tools compiled a service's schema in their own process,
with its preprocessor: the include was followed and the file's first line came back in the
error message. A real service process over real sockets (tests/procs/hostile_schemas.py); the
tools run as a user runs them."""

from __future__ import annotations

import subprocess
import sys
import uuid
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest
from loopback import service_env
from miro_cli import REPO, run_miro_idl

PROC = REPO / "tests" / "procs" / "hostile_schemas.py"
DIRECTIVES = "the schema has preprocessor directives (#include, #define ...): schemas have none"
TOO_LARGE = "the schema is larger than 1048576 bytes (the most taken from elsewhere)"
ROOMY = ("--max-message-size", "64M")  # so that 10 MB of schema reaches the tools


@dataclass
class Hostile:
    naming: str
    secret: str  # the content of the file the schema includes
    secret_file: Path
    cache: Path

    def miro(self, *args: str) -> subprocess.CompletedProcess[str]:
        return subprocess.run(
            [sys.executable, "-m", "miro_gen.cli.main", *args, "--naming", self.naming],
            capture_output=True,
            text=True,
            env=service_env(MIRO_CACHE=str(self.cache)),
            timeout=120,
        )


@pytest.fixture(scope="module")
def hostile(naming: str, tmp_path_factory: pytest.TempPathFactory) -> Iterator[Hostile]:
    folder = tmp_path_factory.mktemp("hostile")
    secret = f"secret_{uuid.uuid4().hex}"
    secret_file = folder / "secret.idl"
    secret_file.write_text(f"{secret} {secret};\n")
    proc = subprocess.Popen(
        [sys.executable, str(PROC), str(secret_file), "--naming", naming, "-MNC", "robot", *ROOMY],
        stdout=subprocess.PIPE,
        text=True,
        env=service_env(),
    )
    try:
        assert proc.stdout is not None and proc.stdout.readline().strip() == "READY"
        yield Hostile(naming, secret, secret_file, folder / "cache")
    finally:
        proc.terminate()
        proc.wait(timeout=60)


def one_line(done: subprocess.CompletedProcess[str]) -> str:
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in done.stderr, done.stderr
    return lines[0]


def test_the_file_shows_wherever_it_is_read(hostile: Hostile, tmp_path: Path) -> None:
    """The control: compiled with the preprocessor, the schema's include is read and its
    content is in the error, so that the tests below would see it if the tools read it."""
    source = tmp_path / "schema.idl"
    source.write_text(f'#include "{hostile.secret_file}"\nmodule M {{ interface I {{}}; }};\n')
    done = run_miro_idl("--ast-json", str(source))
    assert done.returncode == 1 and hostile.secret in done.stderr


def test_call_refuses_an_include_in_one_line_without_reading_the_file(hostile: Hostile) -> None:
    done = hostile.miro("call", "robot/Include", "getData")
    assert done.returncode == 1
    assert one_line(done) == f"miro call: robot/Include: {DIRECTIVES}"
    assert hostile.secret not in done.stdout + done.stderr
    cached = [p for p in hostile.cache.rglob("*") if p.is_file()] if hostile.cache.exists() else []
    assert not cached  # nothing was compiled, nothing kept


def test_call_refuses_a_10_mb_schema_in_one_line(hostile: Hostile) -> None:
    done = hostile.miro("call", "robot/Huge", "getData", *ROOMY)
    assert done.returncode == 1
    assert one_line(done) == f"miro call: robot/Huge: {TOO_LARGE}"


def test_list_shows_both_refusals_in_one_line_each(hostile: Hostile) -> None:
    done = hostile.miro("list", *ROOMY)
    assert done.returncode == 0, done.stderr
    said = done.stdout + done.stderr
    assert "Traceback" not in said and hostile.secret not in said
    lines = done.stdout.splitlines()
    include = lines.index("    robot/Include  IDL:Hostile/Include:1.0")
    assert lines[include + 1] == f"      (no operations: {DIRECTIVES})"
    huge = lines.index("    robot/Huge  IDL:Hostile/Huge:1.0")
    assert lines[huge + 1] == f"      (no operations: {TOO_LARGE})"
    assert sum(DIRECTIVES in line for line in lines) == 1
    assert sum(TOO_LARGE in line for line in lines) == 1


def test_with_the_default_message_size_the_transport_refuses_first(hostile: Hostile) -> None:
    """Without a larger --max-message-size the 10 MB reply never arrives: one line too."""
    done = hostile.miro("call", "robot/Huge", "getData")
    assert done.returncode == 1
    line = one_line(done)
    assert line.startswith("miro call: robot/Huge does not describe its interface (")


# -- the policy itself ---------------------------------------------------------------------------


@pytest.mark.parametrize(
    "text",
    [
        '#include "/etc/hostname"\nmodule M { struct S { long x; }; };',
        "module M { struct S { long x; }; };\n  #  define X 1",
        "/* a comment */ #include <x>",
        "%:include <x>",  # a digraph
        "??=include <x>",  # a trigraph
        'const string s = "abc\\\n#include <x>\n";',  # a literal continued: refused too
        "/* // */ #include <x>",
        "'#' \"#\" #include <x>",
    ],
)
def test_directives_are_refused_wherever_they_hide(text: str) -> None:
    from miro_gen.compile.foreign import refusal

    assert refusal(text) == DIRECTIVES


@pytest.mark.parametrize(
    ("text", "in_a_comment"),
    [
        ("/* " * 300_000, True),  # comments left open: once scanned in quadratic time
        ('"' * 1_000_001, False),
        ("'" * 1_000_001 + "#", False),  # the `#` inside the literal left open
        ("/*" + "*" * 1_000_000, True),
    ],
    ids=["open comments", "quotes", "apostrophes", "stars"],
)
def test_text_built_against_the_scan_is_read_once(text: str, in_a_comment: bool) -> None:
    """What a directive may hide in is scanned in one pass (bench/bench_foreign_schemas.py
    times it): these are read to the end and have no directive; one on the next line is
    refused, unless it is inside the comment left open."""
    from miro_gen.compile.foreign import refusal

    assert refusal(text) is None
    assert refusal(text + "\n#include <x>") == (None if in_a_comment else DIRECTIVES)


def test_a_hash_in_a_comment_or_a_literal_is_no_directive(tmp_path: Path) -> None:
    from miro_gen.compile.foreign import AST, PACKAGES, compile_foreign, refusal

    text = (
        "// #include <not this>\n/* #define NOR_THIS */\n"
        "module M { const string S = \"#1\"; const char C = '#'; struct P { long x; }; };\n"
    )
    assert refusal(text) is None
    compile_foreign([text], tmp_path / "out")
    assert (tmp_path / "out" / PACKAGES / "M" / "__init__.py").is_file()
    assert '"M::P"' in (tmp_path / "out" / AST).read_text()


def test_the_run_time_loads_no_compiler() -> None:
    """The log reader and the live tools' schema cache use the policy without importing a
    compiler (import-linter checks the imports; this checks what a process loads, package
    `__init__`s included)."""
    code = (
        "import sys\n"
        "import miro_gen.eventlog.types, miro_gen.live.schemas\n"
        "loaded = [m for m in sys.modules if m.startswith(('miro_gen.idl', 'miro_gen.codegen',"
        " 'miro_gen.params.compiler', 'miro_gen.compile.idl', 'miro_gen.compile.params'))]\n"
        "print(loaded)\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, env=service_env(), timeout=60
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "[]"


def test_the_compilers_process_applies_the_policy_itself(hostile: Hostile, tmp_path: Path) -> None:
    """`python -m miro_gen.compile FOLDER`, however it is started, refuses what the policy
    refuses, before a compiler is loaded."""
    (tmp_path / "schema.idl").write_text(f'#include "{hostile.secret_file}"\nmodule M {{}};\n')
    done = subprocess.run(
        [sys.executable, "-m", "miro_gen.compile", str(tmp_path)],
        capture_output=True,
        text=True,
        env=service_env(),
        timeout=60,
    )
    assert done.returncode == 1
    assert done.stderr.strip() == DIRECTIVES and hostile.secret not in done.stderr
    assert not (tmp_path / "py").exists() and not (tmp_path / "ast.json").exists()
