"""Valid IDL whose Python miro-idl cannot generate is refused at generation time, with the
construct and its position, and nothing is written; what it can generate imports and passes ruff
and mypy --strict. Each case here comes from real trees (omniORB's, TAO's IDL test suite)."""

from __future__ import annotations

import re
import sys
from pathlib import Path

import generated_checks as G
import pytest
from miro_cli import run_miro_idl


def write(path: Path, text: str) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text, encoding="utf-8")
    return path


def refused(tmp_path: Path, *args: str) -> list[str]:
    """The error lines of a run that must fail and write nothing."""
    out = run_miro_idl("-o", str(tmp_path / "out"), *args)
    assert out.returncode == 1, out.stdout + out.stderr
    assert "Traceback" not in out.stderr and "internal error" not in out.stderr, out.stderr
    assert not (tmp_path / "out").exists()
    return [line for line in out.stderr.splitlines() if ": error: " in line]


def generated(tmp_path: Path, idl: Path) -> Path:
    """The output folder of a run that must succeed."""
    out_dir = tmp_path / "out"
    out = run_miro_idl("-o", str(out_dir), str(idl))
    assert out.returncode == 0, out.stderr
    return out_dir


def test_included_file_that_cannot_be_generated(tmp_path: Path) -> None:
    """The code of b.idl would import a.idl's module, which `any` keeps from being generated,
    also through a file in between."""
    a = write(tmp_path / "a.idl", "module A {\n  struct WithAny { any value; };\n};\n")
    write(tmp_path / "m.idl", '#include "a.idl"\nmodule M { typedef A::WithAny W; };\n')
    b = write(tmp_path / "b.idl", '#include "m.idl"\nmodule B { struct S { M::W w; }; };\n')
    (error,) = refused(tmp_path, str(b))
    assert re.match(rf"^{re.escape(str(a))}:2:\d+: error: the 'any' type is not supported", error)
    assert error.endswith("whose Python module cannot be generated")


def test_two_files_declaring_the_same_names(tmp_path: Path) -> None:
    one = write(tmp_path / "one.idl", "module N { struct S { long a; }; const long C = 1; };\n")
    two = write(tmp_path / "two.idl", "module N { struct S { long a; }; const long C = 1; };\n")
    (error,) = refused(tmp_path, str(one), str(two))
    assert error.startswith(f"{two}:1:19: error: 'N::S' (and 1 more of its declarations) is also")
    for text in ("module N { struct S { long a; }; };\n", "module N { module S { const long"):
        write(two, text + (" X = 1; }; };\n" if "module S" in text else ""))
        assert refused(tmp_path, str(one), str(two))


def test_redundant_bases_are_left_out_of_the_class_statement(tmp_path: Path) -> None:
    idl = write(
        tmp_path / "inherit.idl",
        "module I {\n"
        "  interface one { void op_one(); };\n"
        "  interface two : one { void op_two(); };\n"
        "  interface three : one { void op_three(); };\n"
        "  interface four : two, three { void op_four(); };\n"
        "  interface five : four, three, two { void op_five(); };\n"
        "};\n",
    )
    out_dir = generated(tmp_path, idl)
    assert "class five(four):" in (out_dir / "I" / "inherit_idl.py").read_text()
    assert not G.import_problems(out_dir)


@pytest.mark.parametrize(
    ("text", "line", "words"),
    [
        (
            "interface X {}; interface Y {};\n"
            "interface A : X, Y {}; interface B : Y, X {};\n"
            "interface C : A, B {};\n",
            3,
            "Python cannot order its classes",
        ),
        (
            "module mB { interface B; };\n"
            "module mA { interface A { attribute ::mB::B theB; }; };\n"
            "module mB { interface B : ::mA::A { attribute ::mA::A theA; }; };\n",
            3,
            "its base comes from the generated module mA.t_idl, which imports mB.t_idl in turn",
        ),
        (
            "interface base { exception ex { string info; }; };\n"
            "interface derived : base { exception ex { long serial; }; };\n",
            2,
            "it redeclares 'base::ex' of a base interface",
        ),
        (
            "interface mother { struct member { long a; }; };\n"
            "interface father { struct member { short b; }; };\n"
            "interface child : mother, father {};\n",
            3,
            "its bases 'mother' and 'father' both declare 'member'",
        ),
    ],
    ids=["inheritance-order", "base-class-import-cycle", "redeclared-nested", "nested-in-two"],
)
def test_refused_class_structures(tmp_path: Path, text: str, line: int, words: str) -> None:
    idl = write(tmp_path / "t.idl", text)
    errors = refused(tmp_path, str(idl))
    assert len(errors) == 1, errors
    assert re.match(rf"^{re.escape(str(idl))}:{line}:\d+: error: ", errors[0]), errors[0]
    assert words in errors[0]


def test_constructs_found_in_real_trees_generate_clean_code(tmp_path: Path) -> None:
    """Object references in an exception (CosNaming's CannotProceed), an enum nested in a struct
    and a union whose enumerators share names with a module enum's, IDL names long enough to
    make long lines, a doc comment ending in a quote."""
    long = "VeryLongInterfaceNameThatMakesLongLinesInThePackageInit"
    idl = write(
        tmp_path / "real.idl",
        "module R {\n"
        "  interface Ctx {};\n"
        "  exception CannotProceed { Ctx cxt; Object obj; };\n"
        "  struct Refs { Ctx one; Ctx many[2]; };\n"
        "  enum Colors { red, green };\n"
        "  struct S { enum ColorMe { red, blue } c; };\n"
        "  union U switch (short) { case 1: enum En { red, pink } e; };\n"
        f"  struct {long}_{long}_Struct {{ long x; }};\n"
        '  /** Per-ORB interface.\n      Initial reference: "Manager" */\n'
        "  interface Manager {};\n"
        "};\n",
    )
    out_dir = generated(tmp_path, idl)
    assert not G.import_problems(out_dir)
    assert not G.ruff_problems(out_dir)
    assert not G.mypy_problems(out_dir, tmp_path / "mypy-cache")
    sys.path.insert(0, str(out_dir))
    try:
        import R.real_idl as r

        assert r.red is r.Colors.red  # not S.ColorMe.red or U.En.red
        assert r.S.red is r.S_ColorMe.red
        assert r.CannotProceed().cxt == r.CannotProceed().cxt
    finally:
        sys.path.remove(str(out_dir))
        for name in [m for m in sys.modules if m == "R" or m.startswith("R.")]:
            del sys.modules[name]
