"""The IDL preprocessor, through `Preprocessor` and through the whole front end / `miro-idl`.

Every test writes real files under `tmp_path`: include search, guards, conditionals, macros,
error positions (also through includes), `#pragma prefix` scoping per file, encodings.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import pytest
from miro_cli import run_miro_idl
from repo_paths import REPO

from miro_gen.diagnostics import CompileError, Diagnostic, Diagnostics, SourcePos
from miro_gen.idl import preprocessor
from miro_gen.idl.ast_json import specifications_json
from miro_gen.idl.frontend import compile_idl
from miro_gen.idl.preprocessor import Preprocessor, SourceText

REPO_ROOT = REPO


# -- helpers ------------------------------------------------------------------------------------
def write(path: Path, text: str | bytes) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    if isinstance(text, bytes):
        path.write_bytes(text)
    else:
        path.write_bytes(text.encode("utf-8"))
    return path


def preprocess(
    main: Path, include_dirs: list[Path] | None = None, defines: dict[str, str] | None = None
) -> tuple[SourceText, Diagnostics]:
    diag = Diagnostics()
    src = Preprocessor([str(d) for d in include_dirs or []], defines, diag).run(str(main))
    return src, diag


def code_lines(src: SourceText) -> list[str]:
    """The non-blank output lines, stripped."""
    return [ln.strip() for ln in src.text.split("\n") if ln.strip()]


def pp_lines(tmp_path: Path, text: str, defines: dict[str, str] | None = None) -> list[str]:
    """Preprocess `text` (which must not produce errors) and return its non-blank lines."""
    src, diag = preprocess(write(tmp_path / "t.idl", text), defines=defines)
    assert not diag.has_errors, [str(d) for d in diag.items]
    return code_lines(src)


def pp_errors(tmp_path: Path, text: str, defines: dict[str, str] | None = None) -> list[Diagnostic]:
    _, diag = preprocess(write(tmp_path / "t.idl", text), defines=defines)
    return [d for d in diag.items if d.severity == "error"]


def decls(
    main: Path, include_dirs: list[Path] | None = None, defines: dict[str, str] | None = None
) -> dict[str, dict[str, Any]]:
    """Compile `main` and return its AST-JSON declarations by scoped name."""
    spec = compile_idl(str(main), [str(d) for d in include_dirs or []], defines)
    doc = specifications_json([str(main)], [spec])
    out: dict[str, dict[str, Any]] = {}
    for d in doc["declarations"]:
        out.setdefault(d["name"], d)
    return out


def decl_list(main: Path, include_dirs: list[Path] | None = None) -> list[dict[str, Any]]:
    spec = compile_idl(str(main), [str(d) for d in include_dirs or []])
    return list(specifications_json([str(main)], [spec])["declarations"])


def compile_errors(
    main: Path, include_dirs: list[Path] | None = None, defines: dict[str, str] | None = None
) -> list[Diagnostic]:
    with pytest.raises(CompileError) as ei:
        compile_idl(str(main), [str(d) for d in include_dirs or []], defines)
    errors = [d for d in ei.value.diagnostics if d.severity == "error"]
    assert errors
    return errors


def const_value(tmp_path: Path, text: str, name: str = "c", **kw: Any) -> Any:
    return decls(write(tmp_path / "c.idl", text), **kw)[name]["value"]


def compile_without_crash(main: Path) -> None:
    """A result or a CompileError; a crash fails with one line (a RecursionError's traceback
    would take pytest seconds to format)."""
    crash = None
    try:
        compile_idl(str(main))
    except CompileError:
        pass
    except RecursionError as e:
        crash = f"RecursionError: {e}"
    if crash is not None:
        pytest.fail(crash, pytrace=False)


# -- include search -----------------------------------------------------------------------------
@pytest.fixture
def include_tree(tmp_path: Path) -> dict[str, Path]:
    """main/ with its own x.idl, and two -I folders each with an x.idl of the same name."""
    main_dir = tmp_path / "main"
    inc1 = tmp_path / "inc1"
    inc2 = tmp_path / "inc2"
    write(main_dir / "x.idl", "const long WHICH = 0;\n")
    write(inc1 / "x.idl", "const long WHICH = 1;\n")
    write(inc2 / "x.idl", "const long WHICH = 2;\n")
    return {"root": tmp_path, "main": main_dir, "inc1": inc1, "inc2": inc2}


def test_quoted_include_prefers_including_folder(include_tree: dict[str, Path]) -> None:
    main = write(include_tree["main"] / "main.idl", '#include "x.idl"\n')
    got = decls(main, [include_tree["inc1"], include_tree["inc2"]])
    assert got["WHICH"]["value"] == 0
    assert Path(got["WHICH"]["file"]).parent == include_tree["main"]


def test_angle_include_searches_only_include_dirs(include_tree: dict[str, Path]) -> None:
    """As in the C preprocessor and omniidl: `<x.idl>` never looks beside the including file."""
    main = write(include_tree["main"] / "main.idl", "#include <x.idl>\n")
    assert decls(main, [include_tree["inc1"], include_tree["inc2"]])["WHICH"]["value"] == 1
    diag = Diagnostics()
    with pytest.raises(CompileError):
        compile_idl(str(main), [], None, diag)
    (error,) = [d for d in diag.items if d.severity == "error"]
    assert error.pos is not None and error.pos.line == 1
    assert "cannot find include file 'x.idl' (searched: no -I folders given;" in error.message
    assert 'it is beside the including file: write #include "x.idl" or add -I' in error.message


@pytest.mark.parametrize("spelling", ['"x.idl"', "<x.idl>"])
def test_include_then_first_include_dir_wins(include_tree: dict[str, Path], spelling: str) -> None:
    (include_tree["main"] / "x.idl").unlink()
    main = write(include_tree["main"] / "main.idl", f"#include {spelling}\n")
    assert decls(main, [include_tree["inc1"], include_tree["inc2"]])["WHICH"]["value"] == 1
    assert decls(main, [include_tree["inc2"], include_tree["inc1"]])["WHICH"]["value"] == 2


def test_include_falls_through_to_later_include_dir(include_tree: dict[str, Path]) -> None:
    (include_tree["main"] / "x.idl").unlink()
    (include_tree["inc1"] / "x.idl").unlink()
    main = write(include_tree["main"] / "main.idl", "#include <x.idl>\n")
    assert decls(main, [include_tree["inc1"], include_tree["inc2"]])["WHICH"]["value"] == 2


def test_include_does_not_search_the_working_directory(
    include_tree: dict[str, Path], monkeypatch: pytest.MonkeyPatch
) -> None:
    """The including file's folder is searched, not the current directory."""
    root = include_tree["root"]
    (include_tree["main"] / "x.idl").unlink()
    write(root / "x.idl", "const long WHICH = 9;\n")
    write(include_tree["main"] / "main.idl", '#include "x.idl"\n')
    monkeypatch.chdir(root)
    got = decls(Path("main") / "main.idl", [Path("inc1")])
    assert got["WHICH"]["value"] == 1


def test_nested_include_resolved_relative_to_including_file(tmp_path: Path) -> None:
    write(tmp_path / "b.idl", "const long B_TOP = 1;\n")  # must NOT be picked up
    write(tmp_path / "sub" / "a.idl", '#include "b.idl"\nconst long A = 1;\n')
    write(tmp_path / "sub" / "b.idl", '#include "deeper/c.idl"\nconst long B_SUB = 2;\n')
    write(tmp_path / "sub" / "deeper" / "c.idl", '#include "../../top.idl"\nconst long C = 3;\n')
    write(tmp_path / "top.idl", "const long TOP = 4;\n")
    main = write(tmp_path / "main.idl", '#include "sub/a.idl"\n')
    got = decls(main)
    assert set(got) == {"TOP", "C", "B_SUB", "A"}
    assert Path(got["C"]["file"]).resolve() == (tmp_path / "sub" / "deeper" / "c.idl").resolve()


def test_nested_include_found_through_include_dir_from_subfolder(tmp_path: Path) -> None:
    """A file found via -I includes a sibling by a plain name: its own folder is searched."""
    write(tmp_path / "lib" / "pkg" / "a.idl", '#include "b.idl"\n')
    write(tmp_path / "lib" / "pkg" / "b.idl", "const long FROM_PKG = 1;\n")
    main = write(tmp_path / "app" / "main.idl", "#include <pkg/a.idl>\n")
    assert decls(main, [tmp_path / "lib"])["FROM_PKG"]["value"] == 1


def test_missing_include_reports_position_file_and_searched_folders(tmp_path: Path) -> None:
    inc1 = tmp_path / "inc1"
    inc2 = tmp_path / "inc2"
    inc1.mkdir()
    inc2.mkdir()
    main = write(
        tmp_path / "main.idl", "// header\n\n   #include <nowhere.idl>\nconst long A = 1;\n"
    )
    _, diag = preprocess(main, [inc1, inc2])
    errors = [d for d in diag.items if d.severity == "error"]
    assert len(errors) == 1
    err = errors[0]
    assert err.pos is not None
    assert (err.pos.path, err.pos.line, err.pos.col) == (str(main), 3, 4)
    assert "nowhere.idl" in err.message
    for folder in (tmp_path, inc1, inc2):
        assert str(folder) in err.message
    # The message lists the folders in search order.
    msg = err.message
    assert msg.index(str(inc1)) < msg.index(str(inc2))
    # And the whole front end fails with that error.
    errs = compile_errors(main, [inc1, inc2])
    assert "nowhere.idl" in errs[0].message


def test_missing_include_in_included_file_reported_there(tmp_path: Path) -> None:
    write(tmp_path / "sub" / "a.idl", '\n\n#include "gone.idl"\n')
    main = write(tmp_path / "main.idl", '#include "sub/a.idl"\n')
    err = compile_errors(main)[0]
    assert err.pos is not None
    assert Path(err.pos.path).resolve() == (tmp_path / "sub" / "a.idl").resolve()
    assert (err.pos.line, err.pos.col) == (3, 1)
    assert "gone.idl" in err.message
    assert str(tmp_path / "sub") in err.message


# -- include once -------------------------------------------------------------------------------
GUARDED = """\
#ifndef GUARDED_IDL
#define GUARDED_IDL
struct Guarded { long a; };
#endif // GUARDED_IDL
"""

ONCE = """\
#pragma once
struct Once { long a; };
"""


@pytest.mark.parametrize(
    ("fname", "body", "decl"), [("g.idl", GUARDED, "Guarded"), ("o.idl", ONCE, "Once")]
)
def test_twice_included_file_contributes_once(
    tmp_path: Path, fname: str, body: str, decl: str
) -> None:
    write(tmp_path / fname, body)
    write(tmp_path / "sub" / "user.idl", f'#include "../{fname}"\nstruct User {{ {decl} g; }};\n')
    main = write(
        tmp_path / "main.idl",
        f'#include "{fname}"\n#include "sub/user.idl"\n#include <{fname}>\n'
        f"struct Main {{ {decl} g; }};\n",
    )
    names = [d["name"] for d in decl_list(main, [tmp_path])]
    assert names.count(decl) == 1
    assert {"User", "Main"} <= set(names)


def test_unguarded_file_included_twice_is_a_redefinition(tmp_path: Path) -> None:
    """Control for the test above: without a guard the second inclusion does count."""
    write(tmp_path / "u.idl", "struct Unguarded { long a; };\n")
    main = write(tmp_path / "main.idl", '#include "u.idl"\n#include "u.idl"\n')
    assert any("Unguarded" in e.message for e in compile_errors(main))


# -- conditionals -------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("#if 1\nA\n#else\nB\n#endif\n", ["A"]),
        ("#if 0\nA\n#else\nB\n#endif\n", ["B"]),
        ("#if 0\nA\n#elif 1\nB\n#elif 1\nC\n#else\nD\n#endif\n", ["B"]),
        ("#if 0\nA\n#elif 0\nB\n#else\nC\n#endif\n", ["C"]),
        ("#if 1\nA\n#elif 1\nB\n#else\nC\n#endif\n", ["A"]),
        ("#if 1\n#if 0\nA\n#else\nB\n#endif\nC\n#endif\n", ["B", "C"]),
        ("#if 0\n#if 1\nA\n#else\nB\n#endif\n#elif 1\nC\n#endif\n", ["C"]),
        ("#if 0\n#ifdef __MIRO_IDL__\nA\n#endif\n#else\nB\n#endif\n", ["B"]),
        ("#if 0\n#bogus directive is skipped\n#error not reached\n#endif\nZ\n", ["Z"]),
        # An inactive #elif with a bad expression is not evaluated.
        ("#if 1\nA\n#elif 1 +\nB\n#endif\n", ["A"]),
        ("#ifdef UNDEFINED_NAME\nA\n#else\nB\n#endif\n", ["B"]),
        ("#ifndef UNDEFINED_NAME\nA\n#else\nB\n#endif\n", ["A"]),
        ("#define X\n#ifdef X\nA\n#endif\n#ifndef X\nB\n#endif\n", ["A"]),
        ("#define X\n#if defined X\nA\n#endif\n", ["A"]),
        ("#define X\n#if defined(X)\nA\n#endif\n", ["A"]),
        ("#define X\n#if defined ( X ) && !defined(Y)\nA\n#endif\n", ["A"]),
        ("#define X\n#if defined X || defined Y\nA\n#endif\n", ["A"]),
        ("#if defined X || defined(Y)\nA\n#else\nB\n#endif\n", ["B"]),
        ("#if !defined(X)\nA\n#endif\n", ["A"]),
        # An undefined identifier is 0.
        ("#if NOT_A_MACRO\nA\n#else\nB\n#endif\n", ["B"]),
        ("#if NOT_A_MACRO == 0\nA\n#endif\n", ["A"]),
    ],
)
def test_conditionals(tmp_path: Path, text: str, expected: list[str]) -> None:
    assert pp_lines(tmp_path, text) == expected


@pytest.mark.parametrize(
    "expr",
    [
        "(2 + 3) * 4 == 20",
        "2 + 3 * 4 == 14",
        "7 / 2 == 3 && 7 % 2 == 1",
        "-7 / 2 == -3",
        "10 - 2 - 3 == 5",
        "1 << 4 == 16 && 256 >> 4 == 16",
        "-1 < 0",
        "(0x10 | 1) == 17 && (0xF & 6) == 6 && (5 ^ 1) == 4",
        "010 == 8",
        "~0 == -1",
        "!0 && !!5",
        "0 || 2",
        "3 > 2 && 2 >= 2 && 1 < 2 && 2 <= 2 && 1 != 2",
        "(1 ? 5 : 6) == 5 && (0 ? 5 : 6) == 6",
        "+3 == 3",
        "'A' == 65",
        "10L == 10 && 10u == 10",
        "(1 + 2) * (3 + 4) == 21",
        "((((1))))",
        "true",
    ],
)
def test_if_expression_true(tmp_path: Path, expr: str) -> None:
    assert pp_lines(tmp_path, f"#if {expr}\nYES\n#else\nNO\n#endif\n") == ["YES"]


@pytest.mark.parametrize(
    "expr",
    ["0", "1 - 1", "2 == 3", "1 && 0", "0 || 0", "!1", "(1 ? 0 : 1)", "false", "1 > 2", "5 & 2"],
)
def test_if_expression_false(tmp_path: Path, expr: str) -> None:
    assert pp_lines(tmp_path, f"#if {expr}\nYES\n#else\nNO\n#endif\n") == ["NO"]


def test_if_expression_uses_macros(tmp_path: Path) -> None:
    text = "#define VERSION 3\n#define TWICE(x) ((x) * 2)\n#if TWICE(VERSION) == 6\nA\n#endif\n"
    assert pp_lines(tmp_path, text) == ["A"]


@pytest.mark.parametrize("expr", ["1 +", "(1", "1 )", "1 / 0", "1 % 0", "@", ""])
def test_invalid_if_expression_is_an_error(tmp_path: Path, expr: str) -> None:
    errors = pp_errors(tmp_path, f"\n#if {expr}\nA\n#endif\n")
    assert len(errors) == 1
    assert errors[0].pos is not None and errors[0].pos.line == 2


def test_define_on_command_line(tmp_path: Path) -> None:
    text = (
        "#ifdef FLAG\nFLAG_ON\n#endif\n#if FLAG == 1\nIS_ONE\n#endif\n#if LEVEL > 2\nHIGH\n#endif\n"
    )
    assert pp_lines(tmp_path, text, {"FLAG": "1", "LEVEL": "5"}) == ["FLAG_ON", "IS_ONE", "HIGH"]
    assert pp_lines(tmp_path, text, {"LEVEL": "2"}) == []


def test_define_with_value_used_in_idl(tmp_path: Path) -> None:
    main = write(tmp_path / "m.idl", "const long c = SIZE * 2;\ntypedef sequence<long, SIZE> S;\n")
    got = decls(main, defines={"SIZE": "21"})
    assert got["c"]["value"] == 42
    assert got["S"]["type"] == "sequence<long, 21>"


def test_cli_define_options(tmp_path: Path) -> None:
    write(
        tmp_path / "m.idl",
        "#ifdef FLAG\nconst long flag = FLAG;\n#endif\nconst long size = SIZE;\n",
    )
    r = run_miro_idl("-D", "FLAG", "-D", "SIZE=7", "--ast-json", "m.idl", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    got = {d["name"]: d["value"] for d in json.loads(r.stdout)["declarations"]}
    assert got == {"flag": 1, "size": 7}


def test_undef(tmp_path: Path) -> None:
    text = "#define X 1\n#undef X\n#ifdef X\nA\n#else\nB\n#endif\n#undef NEVER_DEFINED\n"
    assert pp_lines(tmp_path, text) == ["B"]


def test_undef_of_command_line_define(tmp_path: Path) -> None:
    text = "#undef FLAG\n#ifdef FLAG\nA\n#else\nB\n#endif\nFLAG\n"
    assert pp_lines(tmp_path, text, {"FLAG": "1"}) == ["B", "FLAG"]


def test_redefine_replaces_macro(tmp_path: Path) -> None:
    assert const_value(tmp_path, "#define N 1\n#undef N\n#define N 2\nconst long c = N;\n") == 2


def test_macros_expand_from_the_line_after_each_change_of_the_table(tmp_path: Path) -> None:
    """A file's words are looked at once (issue 30): whether a line can use a macro must still
    follow every #define, #undef and #include that changes the table, line by line."""
    write(tmp_path / "defs.idl", "#define WIDTH 3\n")
    text = (
        "WIDTH HEIGHT\n"  # neither defined yet
        '#include "defs.idl"\n'
        "WIDTH HEIGHT\n"  # WIDTH from the header
        "#define HEIGHT 4\n"
        "WIDTH HEIGHT\n"
        "#undef WIDTH\n"
        "WIDTH HEIGHT\n"
        "#define WIDTH 5\n"
        "WIDTH HEIGHT\n"
    )
    assert pp_lines(tmp_path, text) == [
        "WIDTH HEIGHT",
        "3 HEIGHT",
        "3 4",
        "WIDTH 4",
        "5 4",
    ]


def test_a_macro_name_spliced_across_lines_expands(tmp_path: Path) -> None:
    """`WID\\` + newline + `TH` is the word WIDTH: no scan of the file's words may miss it."""
    text = "const long c = WID\\\nTH;\n"  # WIDTH from the command line: no other WIDTH
    assert const_value(tmp_path, text, defines={"WIDTH": "3"}) == 3


# -- macro expansion ----------------------------------------------------------------------------
def test_object_like_macro(tmp_path: Path) -> None:
    text = "#define N 10\n#define M (N + 1)\nconst long c = M * N;\n"
    assert const_value(tmp_path, text) == 110


def test_function_like_macro(tmp_path: Path) -> None:
    text = (
        "#define SUM(a, b) ((a) + (b))\n"
        "#define SEQ(T) sequence<T>\n"
        "#define DECLARE(T, name) typedef SEQ(T) name;\n"
        "const long c = SUM(SUM(1, 2), 3 * 4);\n"
        "DECLARE(short, ShortSeq)\n"
        "typedef SEQ(SEQ(long)) Nested;\n"
    )
    got = decls(write(tmp_path / "m.idl", text))
    assert got["c"]["value"] == 15
    assert got["ShortSeq"]["type"] == "sequence<short>"
    assert got["Nested"]["type"] == "sequence<sequence<long>>"


def test_function_like_macro_name_without_parentheses_is_left_alone(tmp_path: Path) -> None:
    assert pp_lines(tmp_path, "#define F(x) x + 1\nF G F(2)\n") == ["F G 2 + 1"]


def test_self_referential_macros_terminate(tmp_path: Path) -> None:
    assert pp_lines(tmp_path, "#define X X\n#define A B\n#define B A\nX A B\n") == ["X A B"]


def test_macros_not_expanded_in_strings_or_comments(tmp_path: Path) -> None:
    text = (
        "#define FOO bar\n"
        "#define CH Q\n"
        "/** FOO in a doc comment */\n"
        'const string s = "FOO and \\"FOO\\"";  // FOO\n'
        "const char c = 'F';\n"
        "/* FOO\n"
        "   FOO */ const long FOO_LEN = 3;\n"
    )
    main = write(tmp_path / "m.idl", text)
    src, diag = preprocess(main)
    assert not diag.has_errors
    lines = src.text.split("\n")
    assert lines[2] == "/** FOO in a doc comment */"
    assert lines[3] == 'const string s = "FOO and \\"FOO\\"";  // FOO'
    assert lines[5] == "/* FOO"
    assert lines[6] == "   FOO */ const long FOO_LEN = 3;"
    got = decls(main)
    assert got["s"]["value"] == 'FOO and "FOO"'
    assert got["s"]["doc"] is not None and "FOO" in got["s"]["doc"]
    assert "FOO_LEN" in got


def test_macro_expanded_after_comment_on_same_line(tmp_path: Path) -> None:
    text = "#define N 4\n/* N */ const long c = N; // N\n"
    assert pp_lines(tmp_path, text) == ["/* N */ const long c = 4; // N"]


def test_macro_arity_error(tmp_path: Path) -> None:
    errors = pp_errors(tmp_path, "#define F(a, b) a\n\nconst long c = F(1);\n")
    assert len(errors) == 1
    assert errors[0].pos is not None and errors[0].pos.line == 3
    assert "F" in errors[0].message


# -- #error, bad nesting, unknown directives, comments -----------------------------------------
def test_error_directive(tmp_path: Path) -> None:
    errors = pp_errors(tmp_path, "\n\n  #error this configuration is not supported\n")
    assert len(errors) == 1
    assert errors[0].pos is not None
    assert (errors[0].pos.line, errors[0].pos.col) == (3, 3)
    assert "this configuration is not supported" in errors[0].message


def test_error_directive_in_inactive_region_is_ignored(tmp_path: Path) -> None:
    assert pp_errors(tmp_path, "#if 0\n#error nope\n#endif\n#ifdef X\n#error nope\n#endif\n") == []


def test_warning_directive_is_not_an_error(tmp_path: Path) -> None:
    _, diag = preprocess(write(tmp_path / "t.idl", "#warning careful\nstruct S { long a; };\n"))
    assert not diag.has_errors
    assert any(d.severity == "warning" and "careful" in d.message for d in diag.items)


def test_unterminated_if_reported_at_the_if(tmp_path: Path) -> None:
    text = "const long a = 1;\n#if 1\n#ifdef X\n#endif\nconst long b = 2;\n"
    errors = pp_errors(tmp_path, text)
    assert len(errors) == 1
    assert errors[0].pos is not None and errors[0].pos.line == 2
    assert "#endif" in errors[0].message


def test_unterminated_nested_ifs_each_reported(tmp_path: Path) -> None:
    errors = pp_errors(tmp_path, "#ifndef A\n\n#if 0\n")
    assert sorted(e.pos.line for e in errors if e.pos) == [1, 3]


@pytest.mark.parametrize(
    ("text", "line", "word"),
    [
        ("struct S { long a; };\n\n#endif\n", 3, "#endif"),
        ("\n#else\n", 2, "#else"),
        ("\n\n\n#elif 1\n", 4, "#elif"),
        ("#if 1\n#else\n#else\n#endif\n", 3, "#else"),
        ("#if 1\n#else\n#elif 1\n#endif\n", 3, "#elif"),
    ],
)
def test_stray_conditional_directives(tmp_path: Path, text: str, line: int, word: str) -> None:
    errors = pp_errors(tmp_path, text)
    assert len(errors) == 1
    assert errors[0].pos is not None and errors[0].pos.line == line
    assert word in errors[0].message


def test_endif_in_included_file_does_not_close_includers_if(tmp_path: Path) -> None:
    write(tmp_path / "inc.idl", "#endif\n")
    main = write(tmp_path / "main.idl", '#if 1\n#include "inc.idl"\n#endif\n')
    errors = compile_errors(main)
    assert any(
        e.pos is not None and Path(e.pos.path).name == "inc.idl" and e.pos.line == 1 for e in errors
    )


def test_unknown_directive(tmp_path: Path) -> None:
    errors = pp_errors(tmp_path, "struct S { long a; };\n # frobnicate now\n")
    assert len(errors) == 1
    assert errors[0].pos is not None
    assert (errors[0].pos.line, errors[0].pos.col) == (2, 2)
    assert "frobnicate" in errors[0].message


@pytest.mark.parametrize("ending", ["", "\n"], ids=["no-final-newline", "final-newline"])
def test_unterminated_block_comment(tmp_path: Path, ending: str) -> None:
    text = "struct S { long a; };\n\nconst long c = 1; /* no end\n more" + ending
    errors = compile_errors(write(tmp_path / "t.idl", text))
    assert len(errors) == 1
    assert errors[0].pos is not None
    assert (errors[0].pos.line, errors[0].pos.col) == (3, 19)
    assert "comment" in errors[0].message


@pytest.mark.parametrize(
    "opening",
    [
        "/* text after the opener",
        "/**",
        "const long before = 0; /* text",
        "/*",
        "const long before = 0; /*",
    ],
)
def test_directives_inside_block_comments_are_ignored(tmp_path: Path, opening: str) -> None:
    text = (
        f"{opening}\n"
        "#error not an error\n"
        '#include "missing.idl"\n'
        "#if 0\n"
        "#define c 5\n"
        "*/\n"
        "const long c = 1;\n"
    )
    main = write(tmp_path / "m.idl", text)
    _, diag = preprocess(main)
    assert not diag.has_errors, [str(d) for d in diag.items]
    assert decls(main)["c"]["value"] == 1


def test_directives_after_blank_line_inside_block_comment_are_ignored(tmp_path: Path) -> None:
    text = "/*\n\n#error inside a comment\n#define FOO 2\n*/\nconst long FOO = 1;\n"
    main = write(tmp_path / "m.idl", text)
    _, diag = preprocess(main)
    assert not diag.has_errors, [str(d) for d in diag.items]
    assert decls(main)["FOO"]["value"] == 1


def test_block_comment_opened_on_directive_line(tmp_path: Path) -> None:
    text = (
        "#define X 1 /* a comment that\n#error this is inside the comment\n*/\nconst long c = X;\n"
    )
    main = write(tmp_path / "m.idl", text)
    _, diag = preprocess(main)
    assert not diag.has_errors, [str(d) for d in diag.items]
    assert decls(main)["c"]["value"] == 1


def test_line_continuation_in_directive(tmp_path: Path) -> None:
    text = (
        "#define SUM(a, b) \\\n"
        "   ((a) + \\\n"
        "    (b))\n"
        "const long c = SUM(1, 2);\n"
        "struct S { undefined_t x; };\n"
    )
    main = write(tmp_path / "m.idl", text)
    assert compile_errors(main)[0].pos.line == 5  # type: ignore[union-attr]
    write(main, text.replace("undefined_t", "long"))
    assert decls(main)["c"]["value"] == 3
    assert decls(main)["S"]["line"] == 5


def test_line_continuation_in_idl_text(tmp_path: Path) -> None:
    text = "const long \\\nc = 5;\n\nstruct S { long a; };\n"
    got = decls(write(tmp_path / "m.idl", text))
    assert got["c"]["value"] == 5
    assert got["S"]["line"] == 4


def test_line_continuation_in_conditional(tmp_path: Path) -> None:
    assert pp_lines(tmp_path, "#if 1 && \\\n  0\nA\n#else\nB\n#endif\n") == ["B"]


# -- positions through includes -----------------------------------------------------------------
def test_semantic_error_in_included_file_position(tmp_path: Path) -> None:
    write(
        tmp_path / "inc" / "types.idl",
        "// types\nmodule M {\n  struct S {\n    undefined_t member;\n  };\n};\n",
    )
    main = write(
        tmp_path / "main.idl",
        '// main\n\n#include "types.idl"\n\nstruct Also { also_undefined_t m; };\n',
    )
    errors = compile_errors(main, [tmp_path / "inc"])
    by_file = {Path(e.pos.path).name: e for e in errors if e.pos}
    inc_err = by_file["types.idl"]
    assert inc_err.pos is not None
    assert Path(inc_err.pos.path).resolve() == (tmp_path / "inc" / "types.idl").resolve()
    assert (inc_err.pos.line, inc_err.pos.col) == (4, 5)
    assert "undefined_t" in inc_err.message
    main_err = by_file["main.idl"]
    assert main_err.pos is not None
    assert (main_err.pos.line, main_err.pos.col) == (5, 15)


def test_syntax_error_in_included_file_position(tmp_path: Path) -> None:
    write(tmp_path / "sub" / "bad.idl", "struct A { long a; };\n\nstruct B { long b }; \n")
    main = write(tmp_path / "main.idl", '\n\n\n\n#include "sub/bad.idl"\nconst long c = 1;\n')
    errors = compile_errors(main)
    err = errors[0]
    assert err.pos is not None
    assert Path(err.pos.path).resolve() == (tmp_path / "sub" / "bad.idl").resolve()
    assert (err.pos.line, err.pos.col) == (3, 19)


def test_error_after_include_maps_back_to_main_file(tmp_path: Path) -> None:
    write(tmp_path / "ten.idl", "\n" * 9 + "const long TEN = 10;\n")
    main = write(tmp_path / "main.idl", '#include "ten.idl"\nconst long c = TEN;\n  bogus;\n')
    err = compile_errors(main)[0]
    assert err.pos is not None
    assert (Path(err.pos.path).name, err.pos.line, err.pos.col) == ("main.idl", 3, 3)


def test_cli_reports_included_file_positions(tmp_path: Path) -> None:
    write(tmp_path / "inc" / "types.idl", "module M {\n\n  struct S { nosuch_t x; };\n};\n")
    write(tmp_path / "inc" / "syntax.idl", "\nstruct T { long t; }\n")
    write(tmp_path / "a.idl", '#include "types.idl"\n')
    write(tmp_path / "b.idl", "#include <syntax.idl>\nconst long c = 1;\n")
    r = run_miro_idl("-I", "inc", "--ast-json", "a.idl", "b.idl", cwd=tmp_path)
    assert r.returncode == 1
    assert r.stdout == ""
    assert "Traceback" not in r.stderr
    lines = r.stderr.splitlines()
    assert any(
        ln.startswith(os.path.join("inc", "types.idl") + ":3:14: error: ") for ln in lines
    ), r.stderr
    # A missing ';' after the struct is seen at the next token (line 1 of b.idl after the
    # include): whatever the position, it must name a real file and be well formed.
    for ln in lines:
        path, line, col, rest = ln.split(":", 3)
        assert (tmp_path / path).is_file(), ln
        assert int(line) >= 1 and int(col) >= 1
        assert (
            rest.startswith(" error: ")
            or rest.startswith(" warning: ")
            or rest.startswith(" note: ")
        )


# -- #pragma prefix scoping per file -------------------------------------------------------------
def test_pragma_prefix_does_not_leak_into_included_file(tmp_path: Path) -> None:
    write(tmp_path / "b.idl", "struct X { long a; };\nmodule MB { struct XX { long a; }; };\n")
    main = write(
        tmp_path / "main.idl",
        '#pragma prefix "a.org"\n#include "b.idl"\nstruct Y { long a; };\n'
        "module MA { struct YY { long a; }; };\n",
    )
    got = decls(main)
    assert got["X"]["repo_id"] == "IDL:X:1.0"
    assert got["MB::XX"]["repo_id"] == "IDL:MB/XX:1.0"
    assert got["Y"]["repo_id"] == "IDL:a.org/Y:1.0"
    assert got["MA::YY"]["repo_id"] == "IDL:a.org/MA/YY:1.0"


def test_pragma_prefix_does_not_leak_out_of_included_file(tmp_path: Path) -> None:
    write(tmp_path / "c.idl", '#pragma prefix "c.org"\nstruct X { long a; };\n')
    main = write(tmp_path / "main.idl", '#include "c.idl"\nstruct Y { long a; };\n')
    got = decls(main)
    assert got["X"]["repo_id"] == "IDL:c.org/X:1.0"
    assert got["Y"]["repo_id"] == "IDL:Y:1.0"


def test_pragma_prefix_restored_after_include_with_its_own_prefix(tmp_path: Path) -> None:
    write(tmp_path / "c.idl", '#pragma prefix "c.org"\nstruct X { long a; };\n')
    main = write(
        tmp_path / "main.idl",
        '#pragma prefix "a.org"\nstruct W { long a; };\n#include "c.idl"\nstruct Y { long a; };\n',
    )
    got = decls(main)
    assert got["W"]["repo_id"] == "IDL:a.org/W:1.0"
    assert got["X"]["repo_id"] == "IDL:c.org/X:1.0"
    assert got["Y"]["repo_id"] == "IDL:a.org/Y:1.0"


def test_cli_pragma_prefix_scoping(tmp_path: Path) -> None:
    write(tmp_path / "b.idl", "struct X { long a; };\n")
    write(
        tmp_path / "main.idl", '#pragma prefix "a.org"\n#include "b.idl"\nstruct Y { long a; };\n'
    )
    r = run_miro_idl("--ast-json", "main.idl", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    got = {d["name"]: d for d in json.loads(r.stdout)["declarations"]}
    assert got["X"]["repo_id"] == "IDL:X:1.0"
    assert got["X"]["file"] == "b.idl"
    assert got["Y"]["repo_id"] == "IDL:a.org/Y:1.0"
    assert got["Y"]["file"] == "main.idl"


# -- SourceText.includes ------------------------------------------------------------------------
def test_source_text_lists_direct_includes(tmp_path: Path) -> None:
    write(tmp_path / "a.idl", '#include "sub/c.idl"\n')
    write(tmp_path / "b.idl", "#pragma once\n")
    write(tmp_path / "sub" / "c.idl", "")
    main = write(tmp_path / "main.idl", '#include "a.idl"\n#include "b.idl"\n#include "b.idl"\n')
    src, diag = preprocess(main)
    assert not diag.has_errors
    inc = {Path(k).resolve(): [Path(v).resolve() for v in vs] for k, vs in src.includes.items()}
    assert inc[main.resolve()] == [(tmp_path / "a.idl").resolve(), (tmp_path / "b.idl").resolve()]
    assert inc[(tmp_path / "a.idl").resolve()] == [(tmp_path / "sub" / "c.idl").resolve()]
    assert inc.get((tmp_path / "b.idl").resolve(), []) == []
    assert inc.get((tmp_path / "sub" / "c.idl").resolve(), []) == []
    # The specification carries the same table.
    spec = compile_idl(str(main))
    assert spec.includes == src.includes


# -- encodings and line endings ------------------------------------------------------------------
def test_crlf_line_endings(tmp_path: Path) -> None:
    text = (
        "#define N 3\r\n"
        "#if N == 3 \\\r\n"
        "  && 1\r\n"
        "module M {\r\n"
        "  /** doc */\r\n"
        "  struct S {\r\n"
        "    long a[N];\r\n"
        "  };\r\n"
        "};\r\n"
        "#endif\r\n"
    )
    main = write(tmp_path / "crlf.idl", text)
    got = decls(main)
    assert got["M::S"]["line"] == 6
    assert got["M::S"]["members"][0]["dims"] == [3]
    bad = write(
        tmp_path / "bad.idl", "module M {\r\n  struct S {\r\n    nosuch x;\r\n  };\r\n};\r\n"
    )
    err = compile_errors(bad)[0]
    assert err.pos is not None and (err.pos.line, err.pos.col) == (3, 5)


def test_crlf_include(tmp_path: Path) -> None:
    write(tmp_path / "inc.idl", "#ifndef INC\r\n#define INC\r\nconst long A = 1;\r\n#endif\r\n")
    main = write(tmp_path / "main.idl", '#include "inc.idl"\r\n#include "inc.idl"\r\n')
    assert decls(main)["A"]["value"] == 1


def test_utf8_bom(tmp_path: Path) -> None:
    main = write(
        tmp_path / "bom.idl",
        b'\xef\xbb\xbf#define N 2\nconst long c = N;\nconst string s = "\xc3\xa9";\n',
    )
    got = decls(main)
    assert got["c"]["value"] == 2
    assert got["s"]["value"] == "\u00e9"
    bad = write(tmp_path / "bad.idl", b"\xef\xbb\xbfnosuch_t x;\n")
    err = compile_errors(bad)[0]
    assert err.pos is not None and (err.pos.line, err.pos.col) == (1, 1)


def test_utf8_bom_in_included_file(tmp_path: Path) -> None:
    write(tmp_path / "inc.idl", b"\xef\xbb\xbf#pragma once\nconst long A = 1;\n")
    main = write(tmp_path / "main.idl", '#include "inc.idl"\n#include "inc.idl"\n')
    assert decls(main)["A"]["value"] == 1


def test_latin1_file(tmp_path: Path) -> None:
    main = write(
        tmp_path / "latin1.idl",
        b'// caf\xe9 \xfcber\n/** Gr\xfc\xdfe */\nconst string s = "caf\xe9";\n'
        b"const char c = '\xe9';\nstruct T { nosuch_t x; };\n",
    )
    err = compile_errors(main)[0]
    assert err.pos is not None and (err.pos.line, err.pos.col) == (5, 12)
    write(main, main.read_bytes().replace(b"nosuch_t", b"long"))
    got = decls(main)
    assert got["s"]["value"] == "caf\u00e9"
    assert got["c"]["value"] == "\u00e9"
    assert got["s"]["doc"] is not None and "Gr\u00fc\u00dfe" in got["s"]["doc"]


def test_cli_latin1_and_bom(tmp_path: Path) -> None:
    write(tmp_path / "l.idl", b'\xef\xbb\xbf#include "x.idl"\nconst long B = A;\n')
    write(tmp_path / "x.idl", b"// \xe9t\xe9\r\nconst long A = 1;\r\n")
    r = run_miro_idl("--ast-json", "l.idl", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    got = {d["name"]: d["value"] for d in json.loads(r.stdout)["declarations"]}
    assert got == {"A": 1, "B": 1}


# -- bugs found while writing these tests -------------------------------------------------------
def test_if_char_literal_with_bad_escape_is_an_error(tmp_path: Path) -> None:
    main = write(tmp_path / "m.idl", "#if '\\x' == 1\n#endif\n")
    errors = compile_errors(main)
    assert errors[0].pos is not None and errors[0].pos.line == 1


@pytest.mark.timeout(60)
def test_deeply_nested_if_expression(tmp_path: Path) -> None:
    main = write(tmp_path / "m.idl", "#if " + "(" * 1000 + "1" + ")" * 1000 + "\n#endif\n")
    compile_without_crash(main)


@pytest.mark.timeout(60)
def test_long_macro_chain(tmp_path: Path) -> None:
    text = "".join(f"#define M{i} M{i + 1}\n" for i in range(3000)) + "const long c = M0;\n"
    main = write(tmp_path / "m.idl", text)
    compile_without_crash(main)


def test_if_invalid_octal_literal_is_an_error(tmp_path: Path) -> None:
    main = write(tmp_path / "m.idl", "\n#if 08\n#endif\n")
    errors = compile_errors(main)
    assert errors[0].pos is not None and errors[0].pos.line == 2


def test_columns_after_macro_expansion_map_to_the_source(tmp_path: Path) -> None:
    """Positions after a macro use are columns of the source line; a problem inside an
    expansion is reported at the macro's use (its name)."""
    line = "const long LONG_MACRO_NAME = 1; struct S { F(bogus_t) b; nosuch_t c; };"
    main = write(tmp_path / "m.idl", "#define LONG_MACRO_NAME x\n#define F(a) a\n" + line + "\n")
    cols = sorted(e.pos.col for e in compile_errors(main) if e.pos)
    assert cols == [line.index("F(bogus_t)") + 1, line.index("nosuch_t") + 1]


def test_line_directive(tmp_path: Path) -> None:
    main = write(tmp_path / "m.idl", '\n#line 40 "renamed.idl"\n  bogus;\n')
    err = compile_errors(main)[0]
    assert err.pos == ("renamed.idl", 40, 3)


def test_line_zero_gives_no_line_zero_positions(tmp_path: Path) -> None:
    main = write(tmp_path / "m.idl", "#line 0\nbogus;\n")
    errors = compile_errors(main)
    assert all(e.pos is not None and e.pos.line >= 1 for e in errors), errors


@pytest.mark.parametrize("directive", ["#0xifndef FOO", "#line 12abc"])
def test_malformed_line_directive_is_an_error(tmp_path: Path, directive: str) -> None:
    main = write(tmp_path / "m.idl", directive + "\nconst long c = 1;\n")
    errors = compile_errors(main)
    assert errors[0].pos is not None and errors[0].pos.line == 1


# -- include cycles, nesting and counts ---------------------------------------------------------
def test_include_cycle_without_guards_is_named(tmp_path: Path) -> None:
    write(tmp_path / "b.idl", '#include "a.idl"\nmodule B {};\n')
    main = write(tmp_path / "a.idl", '#include "b.idl"\nmodule A {};\n')
    errors = compile_errors(main)
    assert len(errors) == 1, [str(e) for e in errors]
    (error,) = errors
    assert error.pos is not None
    assert (Path(error.pos.path).name, error.pos.line) == ("b.idl", 1)
    a, b = str(main), str(tmp_path / "b.idl")
    assert f"#include cycle: {a} -> {b} -> {a};" in error.message
    assert "include guards" in error.message


def test_include_cycle_with_guards_is_fine(tmp_path: Path) -> None:
    for name, other in (("a", "b"), ("b", "a")):
        guard = f"{name.upper()}_IDL"
        write(
            tmp_path / f"{name}.idl",
            f'#ifndef {guard}\n#define {guard}\n#include "{other}.idl"\n'
            f"module {name.upper()} {{ const long C = 1; }};\n#endif\n",
        )
    main = tmp_path / "a.idl"
    assert list(decls(main)) == ["B", "B::C", "A", "A::C"]


def test_include_cycle_that_redefines_a_macro_each_round_is_caught(tmp_path: Path) -> None:
    """The macro table stops changing after the first round: the second round repeats forever."""
    write(tmp_path / "b.idl", '#include "a.idl"\n')
    main = write(tmp_path / "a.idl", '#define X 1\n#include "b.idl"\nmodule A {};\n')
    (error,) = compile_errors(main)
    assert "#include cycle:" in error.message


def test_include_nesting_beyond_the_limit_is_one_error(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(preprocessor, "MAX_INCLUDE_DEPTH", 5)
    for i in range(10):
        write(tmp_path / f"f{i}.idl", f'#include "f{i + 1}.idl"\n')
    write(tmp_path / "f10.idl", "module M {};\n")
    (error,) = compile_errors(tmp_path / "f0.idl")
    assert error.message == "#include nested more than 5 deep"


def test_include_count_is_capped(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Files that each include the next one twice, without guards, double the work with each
    level (2^17 inclusions took 12 s): the count is capped, with one error saying why."""
    monkeypatch.setattr(preprocessor, "MAX_INCLUSIONS", 100)
    for i in range(10):
        write(tmp_path / f"f{i}.idl", f'#include "f{i + 1}.idl"\n#include "f{i + 1}.idl"\n')
    write(tmp_path / "f10.idl", "// nothing\n")
    _, diag = preprocess(tmp_path / "f0.idl")
    errors = [d for d in diag.items if d.severity == "error"]
    assert len(errors) == 1, [str(e) for e in errors]
    assert errors[0].message.startswith("more than 100 inclusions: files are included again")


def test_file_declaring_nothing_is_warned_about(tmp_path: Path) -> None:
    diag = Diagnostics()
    main = write(tmp_path / "e.idl", "// only a comment\n#if 0\nmodule M {};\n#endif\n")
    compile_idl(str(main), [], None, diag)
    (warning,) = [d for d in diag.items if d.severity == "warning"]
    assert warning.pos == SourcePos(str(main), 1, 1)
    assert warning.message.startswith("the file declares nothing")


def test_file_that_only_includes_is_not_warned_about(tmp_path: Path) -> None:
    write(tmp_path / "x.idl", "module X { const long C = 1; };\n")
    diag = Diagnostics()
    compile_idl(str(write(tmp_path / "all.idl", '#include "x.idl"\n')), [], None, diag)
    assert not diag.items


def test_omniidl_is_predefined_and_can_be_undefined(tmp_path: Path) -> None:
    """ORB trees pick their workarounds by __OMNIIDL__ (omniORB's CosLifeCycle.idl declares
    `_Factory` under it); -U removes a predefined macro, in command-line order with -D."""
    main = write(
        tmp_path / "o.idl",
        "#ifdef __OMNIIDL__\nconst long OMNI = __OMNIIDL__;\n"
        "#else\nconst long OTHER = 1;\n#endif\n",
    )
    assert decls(main)["OMNI"]["value"] == 0x2630
    out = run_miro_idl("-U", "__OMNIIDL__", "--ast-json", str(main))
    assert out.returncode == 0, out.stderr
    assert [d["name"] for d in json.loads(out.stdout)["declarations"]] == ["OTHER"]
    out = run_miro_idl(
        "-D", "__OMNIIDL__=5", "-U", "__OMNIIDL__", "-D", "X", "--ast-json", str(main)
    )
    assert [d["name"] for d in json.loads(out.stdout)["declarations"]] == ["OTHER"]
    assert run_miro_idl("-U", "1bad", "--ast-json", str(main)).returncode == 1
