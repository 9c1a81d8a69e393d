"""Compilers under attack (issue 33): macro expansion that grows exponentially and nesting
thousands deep are refused with `file:line:col: error:` and exit 1, before the expensive work.

Before: 20 lines of doubling `#define`s took `miro-idl` 16 s and a 2 KB file using them 320 s
(every use expanded again down every path); 5,000 nested modules took 141 s and 889 MB before
an error about the package path. The seconds are measured in `bench/bench_refusals.py`; these
tests assert what is reported, where, and that legitimate expansion is unchanged (against gcc's
cpp, a real C preprocessor, on the same text).
"""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import pytest
from miro_cli import run_miro_idl, run_miro_params

from miro_gen.diagnostics import Diagnostics
from miro_gen.idl.preprocessor import Preprocessor

_ERROR = re.compile(r"^(?P<file>[^:\s]+):(?P<line>\d+):(?P<col>\d+): error: (?P<msg>.*)$")


def doubling(levels: int, base: str = "x") -> str:
    """`#define A0 base`, `#define A1 A0 A0`, ...: A(n) is 2^n copies of `base`."""
    lines = [f"#define A0 {base}"]
    lines += [f"#define A{i} A{i - 1} A{i - 1}" for i in range(1, levels)]
    return "\n".join(lines) + "\n"


# Each is refused with an error naming the macro used at the reported column.
ATTACKS = {
    # the issue's 20 lines, used once
    "doubling-20": doubling(20) + "typedef long A19;\n",
    # the issue's 2 KB: the same, used on 80 lines
    "doubling-2kb": doubling(20) + "".join(f"const long c{i} = A19;\n" for i in range(80)),
    # nothing comes out, but 2^40 expansions would
    "doubling-empty-40": doubling(41, "") + "const long c = 1 A40;\n",
    # each level expands the one below under two different sets of hidden names
    "hidden-names-40": "#define A0\n"
    + "".join(f"#define A{i} A{i - 1} B{i}\n#define B{i} A{i - 1}\n" for i in range(1, 41))
    + "const long c = 1 A40;\n",
    "function-doubling-30": "#define F(x) x x\nconst long c = "
    + "F(" * 30
    + "1"
    + ")" * 30
    + ";\n",
    "arguments-doubling-40": "#define D(a, b) a b\n#define A0\n"
    + "".join(f"#define A{i} D(A{i - 1}, A{i - 1})\n" for i in range(1, 41))
    + "const long c = 1 A40;\n",
    "if-doubling-20": doubling(20) + "#if A19\n#endif\n",
    "half-megabyte-lines": doubling(19) + "".join(f"const long c{i} = A18;\n" for i in range(200)),
}


@pytest.mark.parametrize("text", list(ATTACKS.values()), ids=list(ATTACKS))
def test_expansion_attack_is_refused_at_the_macro(tmp_path: Path, text: str) -> None:
    (tmp_path / "a.idl").write_text(text, encoding="utf-8")
    r = run_miro_idl("--ast-json", "a.idl", cwd=tmp_path, timeout=60)
    assert r.returncode == 1, r.stderr[-2000:]
    assert "Traceback" not in r.stderr
    assert r.stdout == ""
    errors = [ln for ln in r.stderr.splitlines() if ": error: " in ln]
    # refused at the first use or soon after, then preprocessing stops: few lines, not one per use
    assert 1 <= len(errors) <= 32, r.stderr[-2000:]
    source = text.split("\n")
    for ln in errors:
        m = _ERROR.match(ln)
        assert m is not None, ln
        named = re.search(r"macro '(\w+)'", m["msg"])
        assert named is not None, ln
        line = source[int(m["line"]) - 1]
        if line.startswith("#if"):  # a directive is reported at its '#'
            assert m["col"] == "1" and named[1] in line, ln
        else:  # at the macro's use, which the message names
            assert line[int(m["col"]) - 1 :].startswith(named[1]), (ln, line)
    last = errors[-1]
    assert "expands to more than 1 MB" in last or "budget for macro expansion" in last, last


def test_the_budget_error_stops_the_file(tmp_path: Path) -> None:
    """Past the budget, the rest of the file is not preprocessed: one error for 80 uses."""
    (tmp_path / "a.idl").write_text(
        doubling(17) + "".join(f"const long c{i} = A16;\n" for i in range(80)), encoding="utf-8"
    )
    r = run_miro_idl("--ast-json", "a.idl", cwd=tmp_path, timeout=60)
    assert r.returncode == 1
    errors = [ln for ln in r.stderr.splitlines() if ": error: " in ln]
    assert len(errors) == 1, r.stderr
    assert "goes over the budget for macro expansion in one file" in errors[0]
    assert errors[0].startswith("a.idl:")
    assert "expanding macro 'A16'" in errors[0]


def _preprocess(path: Path) -> tuple[str, Diagnostics]:
    diag = Diagnostics()
    return Preprocessor([], None, diag).run(str(path)).text, diag


def test_a_large_legitimate_expansion_fits(tmp_path: Path) -> None:
    """A16 is 65,536 tokens: expanded once per macro (remembered), it fits the budget; down
    every path it would be 131,071 expansions."""
    path = tmp_path / "a.idl"
    path.write_text(doubling(17) + "const long c = A16;\n", encoding="utf-8")
    text, diag = _preprocess(path)
    assert not diag.has_errors, diag.items
    assert len(re.findall(r"\bx\b", text)) == 1 << 16


LEGITIMATE = """\
#define A0 x
#define A1 A0 A0
#define A2 A1 A1
#define A3 A2 A2
#define A4 A3 A3
#define SELF SELF + 1
#define P Q
#define Q P
#define F(a, b) a + b
#define G(a) F(a, a) * F(1, a)
#define H(a, b, c) b
#define TWICE(x) x x
#define EMPTY
#define CALL(f, v) f(v)
const long c1 = A4;
const long c2 = SELF;
const long c3 = P Q;
const long c4 = G(G(A2));
const long c5 = H(A4, TWICE(TWICE(A1)), (1, 2));
const long c6 = EMPTY TWICE(EMPTY A1 EMPTY) EMPTY;
const long c7 = CALL(TWICE, A2) CALL(G, 3) A3 A3 G(A1) G(A1);
"""


@pytest.mark.skipif(shutil.which("cpp") is None, reason="gcc's cpp is not installed")
def test_legitimate_expansion_is_what_cpp_makes(tmp_path: Path) -> None:
    """Remembered expansions, arguments expanded only when used: the same tokens as cpp."""
    path = tmp_path / "a.idl"
    path.write_text(LEGITIMATE, encoding="utf-8")
    ours, diag = _preprocess(path)
    assert not diag.has_errors, diag.items
    cpp = subprocess.run(["cpp", "-P", str(path)], capture_output=True, text=True, check=True)

    def tokens(text: str) -> list[str]:
        return re.findall(r"\w+|[^\w\s]", text)

    assert tokens(ours) == tokens(cpp.stdout)


# -- nesting ------------------------------------------------------------------------------------
def _modules(n: int) -> str:
    return "".join(f"module m{i} {{\n" for i in range(n)) + "const long c = 1;\n" + "};\n" * n


def test_5000_nested_modules_refused_at_the_257th_brace(tmp_path: Path) -> None:
    (tmp_path / "n.idl").write_text(_modules(5000), encoding="utf-8")
    r = run_miro_idl("-o", "out", "n.idl", cwd=tmp_path, timeout=60)
    assert r.returncode == 1
    assert r.stderr.splitlines() == [
        "n.idl:257:13: error: '{' nested more than 256 deep (braces, parentheses and brackets "
        "together); miro-idl stops here"
    ]
    assert not (tmp_path / "out").exists()


def test_256_nested_modules_still_compile(tmp_path: Path) -> None:
    (tmp_path / "n.idl").write_text(_modules(256), encoding="utf-8")
    r = run_miro_idl("--ast-json", "n.idl", cwd=tmp_path, timeout=60)
    assert r.returncode == 0, r.stderr[-2000:]


@pytest.mark.parametrize(
    ("text", "col"),
    [
        ("const long c = " + "(" * 300 + "1" + ")" * 300 + ";\n", 16 + 256),
        # the 257th `sequence<`'s '<'
        ("typedef " + "sequence<" * 300 + "long" + ">" * 300 + " S;\n", 9 + 256 * 9 + 8),
    ],
    ids=["parentheses", "sequences"],
)
def test_deep_brackets_refused_where_they_pass_the_limit(
    tmp_path: Path, text: str, col: int
) -> None:
    (tmp_path / "n.idl").write_text(text, encoding="utf-8")
    r = run_miro_idl("--ast-json", "n.idl", cwd=tmp_path, timeout=60)
    assert r.returncode == 1
    assert r.stderr.startswith(f"n.idl:1:{col}: error: "), r.stderr
    assert "nested more than 256 deep" in r.stderr


# -- miro-params --------------------------------------------------------------------------------
_HEAD = '<?xml version="1.0" encoding="UTF-8"?>\n<config>\n'


def _item(name: str, body: str = "") -> str:
    return (
        f'<config_group name="g">\n<config_item name="{name}" parent="Miro::Config">\n{body}'
        "</config_item>\n</config_group>\n"
    )


def test_params_include_chain_refused_at_the_include(tmp_path: Path) -> None:
    """Before: a RecursionError, reported without a position."""
    for i in range(300):
        include = f'<config_global name="include" value="I{i + 1}.h" />\n' if i < 299 else ""
        (tmp_path / f"I{i}.xml").write_text(_HEAD + include + _item(f"I{i}") + "</config>\n")
    r = run_miro_params("-o", "out", "I0.xml", cwd=tmp_path, timeout=60)
    assert r.returncode == 1
    assert r.stderr.splitlines() == ["I199.xml:3: error: includes nested more than 200 deep"]


@pytest.mark.parametrize(
    ("body", "message"),
    [
        (
            '<config_parameter name="V" type="'
            + "std::vector&lt;" * 5000
            + "int"
            + "&gt;" * 5000
            + '" />\n',
            "nests more than 200 deep",
        ),
        (
            '<config_parameter name="X" type="int" />\n<constructor>\n'
            + "{" * 5000
            + "x = 1;"
            + "}" * 5000
            + "</constructor>\n",
            "constructor: brackets nested more than 200 deep",
        ),
        (
            '<config_parameter name="X" type="int" default="'
            + "(" * 5000
            + "1"
            + ")" * 5000
            + '" />\n',
            "brackets nested more than 200 deep",
        ),
    ],
    ids=["type", "constructor", "default"],
)
def test_params_deep_brackets_refused_at_the_element(
    tmp_path: Path, body: str, message: str
) -> None:
    (tmp_path / "p.xml").write_text(_HEAD + _item("P", body) + "</config>\n")
    r = run_miro_params("-o", "out", "p.xml", cwd=tmp_path, timeout=60)
    assert r.returncode == 1
    errors = r.stderr.splitlines()
    assert len(errors) == 1 and errors[0].startswith("p.xml:"), r.stderr
    assert message in errors[0]
