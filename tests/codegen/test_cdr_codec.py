"""The generated CDR codec on the test IDL (tests/codegen/*.idl) and its committed golden output.

Covered: the golden output is fresh, deterministic, free of absolute paths and timestamps, and
passes ruff and mypy --strict; constructs the codec does not support are refused at generation
time (tests/codegen/refused/); every struct, union and exception round-trips (default values and
hypothesis values), big-endian input decodes to the same values; the union API; enum, char and
boolean fields; encoding errors (BAD_PARAM naming the field); data schemas and type hashes.
Cyclone DDS byte-for-byte comparisons are in test_cdr_oracle.py, malformed input in
test_cdr_malformed.py.

Tests marked `xfail(strict=True, reason="bug: ...")` document bugs found while writing these.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import shutil
import struct
import subprocess
import sys
from array import array
from collections.abc import Callable
from pathlib import Path
from typing import Any

import codegen_helpers as H
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from miro_gen.exceptions import BAD_PARAM
from miro_gen.idl import ast, compile_idl

T = H.CodecTest
U = H.CodecUnions
TYPES = H.data_types()
IDS = [d.scoped_name for d in TYPES]

SETTINGS = settings(H.SETTINGS, max_examples=30)

# =============================================================================================
# golden output
# =============================================================================================


def test_golden_is_fresh() -> None:
    out = H.run_miro_idl(*H.miro_idl_args("tests/codegen/golden", "--check"))
    assert out.returncode == 0, (
        f"tests/codegen/golden is stale; regenerate it with\n    {H.REGENERATE}\n"
        "(never edit it by hand) and review the diff:\n" + out.stderr
    )


def test_golden_has_no_stray_files(tmp_path: Path) -> None:
    """The golden folder holds exactly what the command writes (no leftovers of renamed IDL)."""
    out = H.run_miro_idl(*H.miro_idl_args(tmp_path / "out"))
    assert out.returncode == 0, out.stderr
    assert sorted(H.tree(tmp_path / "out")) == sorted(H.tree(H.GOLDEN)), (
        f"tests/codegen/golden holds other files than miro-idl writes: remove it and run\n"
        f"    {H.REGENERATE}"
    )


def test_generation_is_deterministic(tmp_path: Path) -> None:
    """Twice, from two working folders outside the checkout, with other hash seeds: the same
    bytes; from the checkout with another hash seed: the golden bytes."""
    files = [str(p) for p in H.IDL_FILES]
    outputs = []
    for name, seed in (("first", "1"), ("second", "4242")):
        cwd = tmp_path / name / "work"
        cwd.mkdir(parents=True)
        out = H.run_miro_idl("-I", str(H.CODEGEN), "-o", "out", *files, cwd=cwd, hash_seed=seed)
        assert out.returncode == 0, out.stderr
        outputs.append(H.tree(cwd / "out"))
    assert outputs[0] == outputs[1]
    again = tmp_path / "from-checkout"
    out = H.run_miro_idl(*H.miro_idl_args(again), hash_seed="987")
    assert out.returncode == 0, out.stderr
    assert H.tree(again) == H.tree(H.GOLDEN)


def test_no_absolute_paths_or_timestamps_in_output(tmp_path: Path) -> None:
    cwd = tmp_path / "elsewhere"
    cwd.mkdir()
    out = H.run_miro_idl("-I", str(H.CODEGEN), "-o", "out", *map(str, H.IDL_FILES), cwd=cwd)
    assert out.returncode == 0, out.stderr
    forbidden = {str(H.REPO), str(tmp_path), str(Path.home()), "/tmp/", "/root/", "/home/"}
    stamp = re.compile(rb"\b(19|20)\d\d-\d\d-\d\d\b|\b\d\d:\d\d:\d\d\b")
    for folder in (cwd / "out", H.GOLDEN):
        for rel, content in H.tree(folder).items():
            text = content.decode("utf-8")
            for word in forbidden:
                assert word not in text, f"{folder / rel} contains {word!r}"
            assert not stamp.search(content), f"{folder / rel} contains a timestamp"
    # Outside the checkout, files are named by their file name only.
    head = (cwd / "out" / "CodecTest" / "types_idl.py").read_text().splitlines()[:3]
    assert "# Source: types.idl" in head


def _ruff() -> str:
    path = shutil.which("ruff") or str(Path(sys.executable).with_name("ruff"))
    if not Path(path).exists():
        pytest.skip("ruff is not installed")
    return path


def _ruff_findings() -> list[dict[str, Any]]:
    """ruff check on the golden output with the project's rules."""
    out = subprocess.run(
        [_ruff(), "check", "--no-cache", "--output-format", "json", "tests/codegen/golden"],
        cwd=H.REPO,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert out.returncode in (0, 1), out.stderr
    return list(json.loads(out.stdout or "[]"))


def test_golden_passes_ruff_check() -> None:
    findings = _ruff_findings()
    assert not findings, "\n".join(f"{f['filename']}: {f['code']} {f['message']}" for f in findings)


def test_golden_passes_mypy_strict(tmp_path: Path) -> None:
    env = dict(os.environ, MYPYPATH=str(H.GOLDEN))
    cmd = [sys.executable, "-m", "mypy", "--strict", "--python-version", "3.11"]
    cmd += ["--cache-dir", str(tmp_path / "mypy-cache"), "--no-error-summary"]
    for package in H.GOLDEN_PACKAGES:
        cmd += ["-p", package]
    out = subprocess.run(cmd, cwd=H.REPO, env=env, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stdout + out.stderr


# Imports every name of a package and of its subpackages, the first name first.
_IMPORT_ALL = """
import importlib, sys
def walk(name):
    package = importlib.import_module(name)
    for attr in package.__all__:
        value = getattr(package, attr)
        if type(value).__name__ == "module":
            walk(value.__name__)
walk(sys.argv[1])
"""


@pytest.mark.parametrize("package", ["CodecTest", "CodecUnions", "CodecTest__POA", "CodecOther"])
def test_each_golden_package_imports_on_its_own(package: str) -> None:
    """Any package first, then all of its names: packages that use each other (CodecTest and
    CodecOther do, through IDL modules reopened in two files) import in any order."""
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(H.GOLDEN), str(H.REPO)]))
    out = subprocess.run(
        [sys.executable, "-c", _IMPORT_ALL, package],
        env=env,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert out.returncode == 0, out.stderr


def _generate(tmp_path: Path, idl: str) -> Path:
    """Generate `idl` (one file) into tmp_path/out; the output folder."""
    (tmp_path / "t.idl").write_text(idl)
    out = H.run_miro_idl("-o", "out", "t.idl", cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    return tmp_path / "out"


def test_union_cases_of_one_type_pass_ruff(tmp_path: Path) -> None:
    out = _generate(
        tmp_path, "module S { union U switch (long) { case 1: long a; case 2: long b; }; };"
    )
    lint = subprocess.run(
        [_ruff(), "check", "--no-cache", "--isolated", "--select", "SIM114", str(out)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert lint.returncode == 0, lint.stdout


def test_union_branches_named_like_methods(tmp_path: Path) -> None:
    idl = "module KW { union U switch (long) { case 1: long serialize; case 2: long deserialize; };"
    idl += " };"
    out = _generate(tmp_path, idl)
    code = (
        "import KW\n"
        "u = KW.U(1, 5)\n"
        "assert KW.U.deserialize(u.serialize()) == u\n"
        "assert all(isinstance(getattr(KW.U, b), property) for b in KW.U._branches)\n"
    )
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(out), str(H.REPO)]))
    run = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=60
    )
    assert run.returncode == 0, run.stderr


def test_every_declaration_has_its_class() -> None:
    """The test IDL reaches every kind the codec supports, and each lands where the mapping
    says (module package, `Outer_Inner` for nested declarations)."""
    kinds = {type(d).__name__ for d in H.specification().values()}
    assert {"Struct", "Union_", "Enum", "Typedef", "Exception_", "Const", "Interface"} <= kinds
    for d, cls in H.idl_types():
        assert cls._type_name == d.scoped_name
    assert T.Outer.Nested is T.Outer_Nested
    assert T.Holder.Inner is T.Holder_Inner
    assert T.Holder.Choice is T.Holder_Choice
    assert T.Outer.K1 is T.Outer_Kind.K1 and T.Holder.ON is T.Holder_Mode.ON


# =============================================================================================
# refused constructs
# =============================================================================================

REFUSED = sorted(H.REFUSED.glob("*.idl"))


@pytest.mark.parametrize("path", REFUSED, ids=[p.stem for p in REFUSED])
def test_refused_construct(path: Path, tmp_path: Path) -> None:
    text = path.read_text()
    construct = re.search(r"the error names (.+) at the marked line", text)
    assert construct is not None, "refused files say what the error names"
    line = next(i for i, s in enumerate(text.splitlines(), 1) if "<- error" in s)
    rel = path.relative_to(H.REPO).as_posix()
    out = H.run_miro_idl("-o", str(tmp_path / "out"), rel)
    assert out.returncode == 1, out.stdout + out.stderr
    errors = [s for s in out.stderr.splitlines() if ": error: " in s]
    assert errors, out.stderr
    m = re.match(rf"^{re.escape(rel)}:(\d+):(\d+): error: (.+)$", errors[0])
    assert m is not None, errors[0]
    assert int(m.group(1)) == line, errors[0]
    assert construct.group(1) in m.group(3), errors[0]
    assert "Traceback" not in out.stderr
    assert not (tmp_path / "out").exists()


def test_a_refused_file_stops_the_whole_run(tmp_path: Path) -> None:
    """With valid files on the same command line, nothing at all is written."""
    out = H.run_miro_idl(*H.miro_idl_args(tmp_path / "out", "tests/codegen/refused/any.idl"))
    assert out.returncode == 1
    assert not (tmp_path / "out").exists()


# =============================================================================================
# round trips
# =============================================================================================


@pytest.mark.parametrize("decl", TYPES, ids=IDS)
def test_default_value_round_trip(decl: Any) -> None:
    cls = H.pyclass(decl)
    value = cls()
    data = value.serialize()
    assert data[:4] == b"\x00\x01\x00\x00"
    back = cls.deserialize(data)
    assert type(back) is cls
    assert H.plain(back) == H.plain(value)
    assert back.serialize() == data
    if not isinstance(value, Exception):
        assert back == value


@pytest.mark.parametrize("decl", TYPES, ids=IDS)
@SETTINGS
@given(data=st.data())
def test_round_trip(decl: Any, data: st.DataObject) -> None:
    cls = H.pyclass(decl)
    value = data.draw(H.values(H.resolve(decl)))
    encoded = value.serialize()
    back = cls.deserialize(encoded)
    assert H.plain(back) == H.plain(value)
    assert back.serialize() == encoded
    # Any buffer type decodes.
    assert H.plain(cls.deserialize(bytearray(encoded))) == H.plain(value)
    assert H.plain(cls.deserialize(memoryview(encoded))) == H.plain(value)


CYCLONE_CANNOT = {
    # cyclonedds refuses a boolean union whose two labels are both used and that has no
    # default ("No space in discriminated union for default value"): hand-built below.
    "CodecUnions::ByBool",
}
BE_TYPES = [d for d in TYPES if d.scoped_name not in CYCLONE_CANNOT]


@pytest.mark.parametrize("decl", BE_TYPES, ids=[d.scoped_name for d in BE_TYPES])
@settings(SETTINGS, max_examples=15)
@given(data=st.data())
def test_big_endian_input(decl: Any, data: st.DataObject) -> None:
    """Cyclone writes the value big-endian (header 00 00): it decodes to the same value."""
    from cyclonedds.idl._support import Endianness

    ty = H.resolve(decl)
    value = data.draw(H.values(ty, oracle=True))
    big = H.cyclone().value(ty, value).serialize(endianness=Endianness.Big)
    assert big[:4] == b"\x00\x00\x00\x00"
    assert H.plain(H.pyclass(decl).deserialize(big)) == H.plain(value)


def _primitives_by_hand(v: Any, order: str) -> bytes:
    """Primitives built by hand (`order` "<" or ">"): each field aligned from the end of the
    header."""
    codes = ["h", "H", "i", "I", "q", "Q", "b", "B", "B", "B", "?", "f", "d"]
    codes += ["h", "H", "i", "I", "q", "Q"]
    out = bytearray(b"\x00\x01\x00\x00" if order == "<" else b"\x00\x00\x00\x00")
    names = H.fields_of(H.specification()["CodecTest::Primitives"])
    for code, name in zip(codes, names, strict=True):
        x = getattr(v, name)
        size = struct.calcsize(code)
        out += bytes(-(len(out) - 4) % size)
        out += struct.pack(order + code, ord(x) if name == "c" else x)
    return bytes(out)


def test_big_endian_by_hand() -> None:
    v = T.Primitives(-2, 65000, -3, 4000000000, -5, 2**64 - 6, -7, 200, 9, "\xe9", True)
    v.f, v.d, v.i16, v.u16, v.i32, v.u32, v.i64, v.u64 = 1.5, -2.25, 3, 4, -5, 6, -7, 8
    assert v.serialize() == _primitives_by_hand(v, "<")
    assert T.Primitives.deserialize(_primitives_by_hand(v, ">")) == v
    # A boolean union (Cyclone cannot build this one).
    be_yes = b"\x00\x00\x00\x00\x01\x00\x00\x00" + struct.pack(">i", -5)
    assert U.ByBool.deserialize(be_yes) == U.ByBool(yes=-5)
    be_no = b"\x00\x00\x00\x00\x00\x00\x00\x00" + struct.pack(">I", 3) + b"ab\x00"
    assert U.ByBool.deserialize(be_no) == U.ByBool(no="ab")
    assert (
        U.ByBool(no="ab").serialize() == b"\x00\x01\x00\x00\x00\x00\x00\x00\x03\x00\x00\x00ab\x00"
    )


# =============================================================================================
# hand-checked layouts (alignment traps)
# =============================================================================================


def test_layouts() -> None:
    h = b"\x00\x01\x00\x00"
    assert T.BoolDouble(True, 1.0).serialize() == h + b"\x01" + bytes(7) + struct.pack("<d", 1)
    assert T.OctetLongLong(7, -1).serialize() == h + b"\x07" + bytes(7) + b"\xff" * 8
    # An empty sequence: its length and no padding; the double after it aligns to 8.
    seqs = T.EmptySeqs(d=1.0, e=2.0, g=3, i=4.0).serialize()
    z = bytes(4)
    expect = h + z + z + struct.pack("<d", 1.0) + z + z + struct.pack("<d", 2.0) + z + z
    expect += struct.pack("<q", 3) + z + z + struct.pack("<d", 4.0)
    assert seqs == expect
    # A struct ending in a char inside a sequence: the next element's double aligns again.
    s = T.SeqEndsInChar([T.EndsInChar(1.0, "a"), T.EndsInChar(2.0, "b")], 3.0).serialize()
    first = struct.pack("<d", 1.0) + b"a" + bytes(7)
    second = struct.pack("<d", 2.0) + b"b" + bytes(7)
    assert s == h + struct.pack("<I", 2) + z + first + second + struct.pack("<d", 3.0)
    # Strings count their NUL; "" is length 1.
    assert T.Strings().serialize()[4:12] == b"\x01\x00\x00\x00\x00\x00\x00\x00"
    # Union: discriminator, then the branch aligned on its own.
    assert U.ByLongLong(minus_one=0.5).serialize() == h + b"\xff" * 8 + struct.pack("<d", 0.5)
    assert U.ByChar(bc=0.5).serialize() == h + b"b" + bytes(7) + struct.pack("<d", 0.5)


# =============================================================================================
# enum, char and boolean fields
# =============================================================================================


def test_enum_fields_decode_to_enum_members() -> None:
    v = T.Enums.deserialize(T.Enums(T.BLUE, T.ONLY, T.Words._None).serialize())
    assert v.hue is T.Color.BLUE and type(v.hue) is T.Color
    assert type(v.only_one) is T.Single and type(v.word) is T.Words
    s = T.Sequences.deserialize(T.Sequences(colors=[T.GREEN, T.RED]).serialize())
    assert s.colors == [T.GREEN, T.RED] and all(type(c) is T.Color for c in s.colors)
    a = T.Arrays.deserialize(T.Arrays(em=[[T.RED, T.BLUE], [T.GREEN, T.RED]]).serialize())
    assert all(type(c) is T.Color for row in a.em for c in row)
    assert [e.name for e in T.Words] == ["_None", "_name", "_value", "_from", "_mro"]


def test_char_fields_take_all_of_latin1() -> None:
    for code in range(256):
        c = chr(code)
        data = T.Primitives(c=c).serialize()
        assert T.Primitives.deserialize(data).c == c
    arr = T.Arrays(c4=["\x00", "\xff", "a", "\x80"], cm=[["x", "y"], ["\xe9", "z"]])
    assert T.Arrays.deserialize(arr.serialize()) == arr
    seq = T.Sequences(chars=list("h\xe9\x00\xff"))
    assert T.Sequences.deserialize(seq.serialize()).chars == list("h\xe9\x00\xff")
    diff = [
        (a, b)
        for a, b in zip(T.Primitives().serialize(), T.Primitives(c="\xe9").serialize(), strict=True)
        if a != b
    ]
    assert diff == [(0, 0xE9)]  # one byte, ISO Latin-1


def test_boolean_fields() -> None:
    for b in (False, True):
        back = T.Primitives.deserialize(T.Primitives(b=b).serialize())
        assert back.b is b
    flags = T.Sequences.deserialize(T.Sequences(flags=[True, False, True]).serialize()).flags
    assert flags == [True, False, True] and all(type(f) is bool for f in flags)


def test_octet_sequences_are_bytes() -> None:
    v = T.Sequences(octets=b"\x00\xffab", blobs=[b"", b"x"])
    back = T.Sequences.deserialize(v.serialize())
    assert back.octets == b"\x00\xffab" and type(back.octets) is bytes
    assert back.blobs == [b"", b"x"]


def test_keyword_names() -> None:
    k = T.Keywords(
        _from=1, _lambda=2.0, _list=array("i", [3]), _str="s", l=4, I=5, O=6, _None=True, _class=7
    )
    k._def, k._int, k.type, k.self, k._print, k.data, k.cls = 8, 9, 10, 11, 12, 13, 14
    k._serialize, k._deserialize = 15, 16
    assert T.Keywords.deserialize(k.serialize()) == k
    u = T.KeywordUnion(_list="x")
    assert T.KeywordUnion.deserialize(u.serialize())._list == "x"
    assert T.KeywordUnion(_str=k)._d == 4


def test_inheritance() -> None:
    d = T.Derived2(id=1, name="n", value=2.5, bases=[T.Base3(3)])
    assert isinstance(d, T.Derived) and isinstance(d, T.Base3)
    assert H.fields_of(H.specification()["CodecTest::Derived2"]) == [
        "id",
        "name",
        "value",
        "bases",
    ]
    data = d.serialize()
    assert data[:8] == b"\x00\x01\x00\x00\x01\x00\x00\x00"  # the base's member first
    assert T.Derived2.deserialize(data) == d


def test_exceptions_carry_fields_and_encode() -> None:
    f = T.Failure(3, "bad", [T.Point(1, 2)])
    assert isinstance(f, Exception)
    back = T.Failure.deserialize(f.serialize())
    assert (back.code, back.reason, back.where) == (3, "bad", [T.Point(1, 2)])
    assert "CodecTest::Failure" in str(f)
    assert T.Nothing().serialize() == b"\x00\x01\x00\x00"


def test_recursive_types() -> None:
    tree = T.Node(1, [T.Node(2, []), T.Node(3, [T.Node(4, [])])])
    assert T.Node.deserialize(tree.serialize()) == tree
    e = T.Expr(items=[T.Expr(leaf=1), T.Expr(items=[T.Expr(leaf=2)])])
    assert T.Expr.deserialize(e.serialize()) == e


# =============================================================================================
# unions
# =============================================================================================


def test_union_construction_both_ways() -> None:
    a = U.ByShort(neg=5)
    assert (a._d, a._v, a.neg) == (-1, 5, 5)
    b = U.ByShort(small=1.5)
    assert b._d == 0  # the branch's first label
    c = U.ByShort(2, 1.5)
    assert (c._d, c.small) == (2, 1.5)
    assert b != c  # same branch, other discriminator
    assert U.ByShort(0, 1.5) == b
    e = U.ByEnum(gb="x")
    assert e._d is T.GREEN
    assert U.ByEnum(T.BLUE, "x").gb == "x"
    first = U.ByShort()
    assert (first._d, first._v) == (-1, 0)  # the first branch, default value
    assert U.Branches()._v == T.Point()
    with pytest.raises(TypeError):
        U.ByShort(neg=1, small=2.0)
    with pytest.raises(TypeError):
        U.ByShort(1)
    with pytest.raises(TypeError):
        U.ByShort(nonexistent=1)


def test_union_properties() -> None:
    u = U.ByShort(neg=5)
    with pytest.raises(AttributeError):
        _ = u.small
    with pytest.raises(AttributeError):
        _ = u.other
    assert not hasattr(u, "small")
    u.small = 2.5  # selecting another branch
    assert (u._d, u._v, u.small) == (0, 2.5, 2.5)
    with pytest.raises(AttributeError):
        _ = u.neg
    # A discriminator no label uses selects the default branch, and stays as it is.
    d = U.ByShort(100, "x")
    assert d.other == "x" and d._d == 100
    assert U.ByShort.deserialize(d.serialize())._d == 100
    # No default: no branch is active, value None.
    for none in (U.ByEnumPartial(T.GREEN, None), U.ByBoolTrue(False, None), U.ByOctet(7, None)):
        back = type(none).deserialize(none.serialize())
        assert back == none and back._v is None
        for name in type(none)._branches:
            with pytest.raises(AttributeError):
                getattr(back, name)
    assert U.ByEnumPartial(T.GREEN, None).serialize() == b"\x00\x01\x00\x00\x01\x00\x00\x00"
    # A value given with a discriminator that selects no branch would be lost: refused.
    with pytest.raises(BAD_PARAM, match="selects no branch"):
        U.ByEnumPartial(T.GREEN, 5).serialize()


def test_union_repr_and_equality() -> None:
    assert repr(U.ByShort(neg=5)) == "ByShort(neg=5)"
    assert repr(U.ByShort(2, 1.5)) == "ByShort(2, 1.5)"
    assert repr(U.ByShort(other="x")) == "ByShort(other='x')"
    assert repr(U.ByChar(bc=1.0)) == "ByChar(bc=1.0)"
    assert "None" in repr(U.ByEnumPartial(T.GREEN, None))
    assert U.ByShort(neg=5) == U.ByShort(-1, 5)
    assert U.ByShort(neg=5) != U.ByShort(neg=6)
    assert U.ByLong(other="a") != U.ByShort(other="a")
    assert U.ByShort(neg=5) != (-1, 5)
    with pytest.raises(TypeError):
        hash(U.ByShort(neg=5))


# Branch `other` (the default) selected by name: the discriminator it gets. Cyclone DDS's choice
# is in the same column where it differs (see test_default_discriminator_matches_cyclone).
DEFAULT_DISCRIMINATORS: list[tuple[Any, Any]] = [
    (U.ByEnumDefault, T.RED),  # lowest unused enumerator (Cyclone: 3, no enumerator)
    (U.ByTypedefEnum, T.GREEN),  # (Cyclone: 3)
    (U.ByChar, "\x00"),
    (U.ByCharNul, "\x01"),  # (Cyclone: '\x00', which selects branch nul)
    (U.ByBoolDefault, False),
    (U.ByShort, -2),
    (U.ByUShort, 1),
    (U.ByLong, -1),
    (U.ByLongLong, -2),
    (U.ByULongLong, 1),
    (U.ByTypedef, -1),
    (U.ByInt8, -2),
    (U.ByUInt8, 1),
]


@pytest.mark.parametrize(
    ("cls", "expected"), DEFAULT_DISCRIMINATORS, ids=[c.__name__ for c, _ in DEFAULT_DISCRIMINATORS]
)
def test_default_discriminator(cls: Any, expected: Any) -> None:
    decl = H.specification()[cls._type_name]
    default = next(i for i, c in enumerate(decl.cases) if None in c.labels)
    name = H.branches_of(decl)[default]
    u = cls(**{name: cls._zero[name]()})
    assert u._d == expected and type(u._d) is type(expected)
    assert H.active_case(decl, u._d) == default
    back = cls.deserialize(u.serialize())
    assert back == u and getattr(back, name) == u._v


CYCLONE_DEFAULT_DIFFERS = {"ByEnumDefault", "ByTypedefEnum", "ByCharNul"}


@pytest.mark.parametrize(
    ("cls", "expected"), DEFAULT_DISCRIMINATORS, ids=[c.__name__ for c, _ in DEFAULT_DISCRIMINATORS]
)
def test_default_discriminator_matches_cyclone(cls: Any, expected: Any) -> None:
    """Where Cyclone picks a discriminator that selects the default branch, ours is the same
    (and the bytes are too); for enums Cyclone picks the ordinal after the last enumerator,
    which is no enumerator, and for chars always '\\x00' even when a label uses it."""
    decl = H.specification()[cls._type_name]
    theirs = H.cyclone().cls(decl).__idl_default_discriminator__
    if cls.__name__ in CYCLONE_DEFAULT_DIFFERS:
        assert theirs != expected
        return
    assert theirs == expected
    default = next(i for i, c in enumerate(decl.cases) if None in c.labels)
    name = H.branches_of(decl)[default]
    ours = cls(**{name: cls._zero[name]()})
    branch = {
        f"b_{decl.cases[default].name}": H.cyclone().value(H.case_types(decl)[default], ours._v)
    }
    assert ours.serialize() == H.cyclone().cls(decl)(**branch).serialize()


# =============================================================================================
# encoding errors
# =============================================================================================

# (value factory, the field the message must name)
NAMED: list[tuple[str, Callable[[], Any], str]] = [
    ("string over bound", lambda: T.Strings(bounded="abcdef"), "CodecTest::Strings.bounded"),
    ("bound counts bytes", lambda: T.Strings(one="\xe9"), "CodecTest::Strings.one"),
    ("typedef'd bound", lambda: T.Strings(name="x" * 9), "CodecTest::Strings.name"),
    ("bound from a constant", lambda: T.Strings(by_const="x" * 9), "CodecTest::Strings.by_const"),
    ("string with NUL", lambda: T.Strings(plain="a\0b"), "CodecTest::Strings.plain"),
    ("string not str", lambda: T.Strings(plain=5), "CodecTest::Strings.plain"),
    ("sequence over bound", lambda: T.Sequences(bounded=[0] * 6), "CodecTest::Sequences.bounded"),
    ("octets over bound", lambda: T.Sequences(octets4=b"12345"), "CodecTest::Sequences.octets4"),
    ("enums over bound", lambda: T.Sequences(colors2=[T.RED] * 3), "CodecTest::Sequences.colors2"),
    (
        "flat structs over bound",
        lambda: T.Sequences(points3=[T.Point3()] * 3),
        "CodecTest::Sequences.points3",
    ),
    (
        "inner sequence over bound",
        lambda: T.Sequences(nested_bounded=[[1, 2, 3]]),
        "CodecTest::Sequences.nested_bounded",
    ),
    (
        "string element over bound",
        lambda: T.Sequences(bounded_strings=["abcd"]),
        "CodecTest::Sequences.bounded_strings",
    ),
    ("NUL in an element", lambda: T.Sequences(strings=["a\0"]), "CodecTest::Sequences.strings"),
    ("char not Latin-1", lambda: T.Sequences(chars=["\u0400"]), "CodecTest::Sequences.chars"),
    ("ragged 2-D array", lambda: T.Arrays(m23=[[1, 2, 3], [1, 2]]), "CodecTest::Arrays.m23"),
    ("short string array", lambda: T.Arrays(s2=["a"]), "CodecTest::Arrays.s2"),
    ("short char array", lambda: T.Arrays(c4=["a"]), "CodecTest::Arrays.c4"),
    ("short struct array", lambda: T.Arrays(p2=[T.Point()]), "CodecTest::Arrays.p2"),
    ("short array of sequences", lambda: T.Arrays(sa=[[]]), "CodecTest::Arrays.sa"),
    ("typedef'd 2-D array", lambda: T.Typedefs(m=[[1, 2], [3]]), "CodecTest::Typedefs.m"),
    ("string array in a union", lambda: U.Branches(s2=["a"]), "CodecUnions::Branches.s2"),
    ("keyword member", lambda: T.Keywords(_str="\0"), "CodecTest::Keywords.str"),
    (
        "keyword branch",
        lambda: T.KeywordUnion(_list="a\0"),
        "CodecTest::KeywordUnion.list|CodecTest::KeywordUnion._list",
    ),
]
PACKED: list[tuple[str, Callable[[], Any], str]] = [
    ("short out of range", lambda: T.Primitives(s=1 << 15), "CodecTest::Primitives.s"),
    ("unsigned negative", lambda: T.Primitives(ull=-1), "CodecTest::Primitives.ull"),
    ("octet out of range", lambda: T.Primitives(o=256), "CodecTest::Primitives.o"),
    ("int8 out of range", lambda: T.Primitives(i8=128), "CodecTest::Primitives.i8"),
    ("two-character char", lambda: T.Primitives(c="ab"), "CodecTest::Primitives.c"),
    ("char not Latin-1 (field)", lambda: T.Primitives(c="\u0400"), "CodecTest::Primitives.c"),
    ("float not a number", lambda: T.Primitives(f="x"), "CodecTest::Primitives.f"),
    ("float32 overflow", lambda: T.Primitives(f=1e39), "CodecTest::Primitives.f"),
    ("empty char", lambda: T.Primitives(c=""), "CodecTest::Primitives.c"),
    ("enum given a name", lambda: T.Enums(hue="RED"), "CodecTest::Enums.hue"),
    ("enum not an enumerator", lambda: T.Enums(hue=7), "CodecTest::Enums.hue"),
    ("enum element", lambda: T.Sequences(colors=[T.RED, 9]), "CodecTest::Sequences.colors"),
    ("enum array element", lambda: T.Arrays(e3=[9, 0, 0]), "CodecTest::Arrays.e3"),
    ("enum discriminator", lambda: U.ByEnum(7, 1), "CodecUnions::ByEnum discriminator"),
    ("short fixed array", lambda: T.Arrays(a1=[1, 2]), "CodecTest::Arrays.a1"),
    ("short octet array", lambda: T.Arrays(o5=[1]), "CodecTest::Arrays.o5"),
    ("element of the wrong type", lambda: T.Sequences(longs=["x"]), "CodecTest::Sequences.longs"),
    ("element out of range", lambda: T.Sequences(shorts=[1 << 20]), "CodecTest::Sequences.shorts"),
    ("sequence is None", lambda: T.Sequences(longs=None), "CodecTest::Sequences.longs"),
    ("octets given a list", lambda: T.Sequences(octets=[1, 2]), "CodecTest::Sequences.octets"),
    ("struct is None", lambda: T.Line(a=None), "CodecTest::Line.a"),
    ("wrong struct type", lambda: T.Sequences(points=[T.Line()]), "CodecTest::Sequences.points"),
    ("branch of the wrong type", lambda: U.ByShort(-1, "s"), "CodecUnions::ByShort.neg"),
    ("discriminator out of range", lambda: U.ByOctet(300, 1), "CodecUnions::ByOctet discriminator"),
]
ENCODING_ERRORS = NAMED + PACKED


@pytest.mark.parametrize(
    ("make", "field"),
    [(m, f) for _, m, f in ENCODING_ERRORS],
    ids=[n for n, _, _ in ENCODING_ERRORS],
)
def test_encoding_error_is_bad_param(make: Callable[[], Any], field: str) -> None:
    with pytest.raises(BAD_PARAM) as info:
        make().serialize()
    assert field.split(" ")[0].split("|")[0].rsplit(".", 1)[0] in str(info.value)  # the type


@pytest.mark.parametrize(
    ("make", "field"),
    [(m, f) for _, m, f in ENCODING_ERRORS],
    ids=[n for n, _, _ in ENCODING_ERRORS],
)
def test_encoding_error_names_the_field(make: Callable[[], Any], field: str) -> None:
    with pytest.raises(BAD_PARAM) as info:
        make().serialize()
    assert any(f in str(info.value) for f in field.split("|")), str(info.value)


@pytest.mark.parametrize("element", ["ab", ""])
def test_char_sequence_element_must_be_one_character(element: str) -> None:
    with pytest.raises(BAD_PARAM):
        T.Sequences(chars=["x", element]).serialize()


def test_enum_ordinals_given_as_ints_encode() -> None:
    """An int that is an enumerator's ordinal encodes as that enumerator (IntEnum)."""
    assert T.Enums(hue=2).serialize() == T.Enums(hue=T.BLUE).serialize()


# =============================================================================================
# data schema and type hash
# =============================================================================================


@pytest.mark.parametrize("decl", TYPES, ids=IDS)
def test_identity_schema_and_hash(decl: Any) -> None:
    cls = H.pyclass(decl)
    assert cls._type_name == decl.scoped_name
    assert cls._repo_id == decl.repo_id
    schema = cls._data_schema
    assert schema.endswith("\n") and decl.name in schema
    assert cls._type_hash == hashlib.sha256(schema.encode("utf-8")).hexdigest()
    for word in ("#include", "#pragma", "interface", "::CodecTest", "exception"):
        assert word not in schema


@pytest.mark.parametrize("decl", TYPES, ids=IDS)
def test_schema_parses_to_the_same_schema(decl: Any, tmp_path: Path) -> None:
    """The schema is IDL that compiles on its own, and describes the same type: its own schema
    (from the front end and the same schema writer) is the same text."""
    from miro_gen.codegen.schema import data_schema

    cls = H.pyclass(decl)
    path = tmp_path / "schema.idl"
    path.write_text(cls._data_schema)
    spec = compile_idl(str(path))
    again = [
        d
        for d in spec.declarations
        if d.scoped_name == decl.scoped_name and not isinstance(d, ast.Forward)
    ]
    assert len(again) == 1
    assert data_schema(again[0]) == cls._data_schema


def test_schemas_pass_miro_idl(tmp_path: Path) -> None:
    """All schemas at once through the command line."""
    files = []
    for d, cls in H.idl_types():
        path = tmp_path / (d.scoped_name.replace("::", "_") + ".idl")
        path.write_text(cls._data_schema)
        files.append(str(path))
    out = H.run_miro_idl("--ast-json", *files)
    assert out.returncode == 0, out.stderr
    names = {x["name"] for x in json.loads(out.stdout)["declarations"]}
    assert {d.scoped_name for d in TYPES} <= names


def test_hashes_of_different_types_differ() -> None:
    hashes = {cls._type_hash: d.scoped_name for d, cls in H.idl_types()}
    assert len(hashes) == len(TYPES)


HASH_BASE = """\
module HashTest {
  enum E { A, B };
  struct P {
    double x;
    sequence<long, 3> s;
    string<4> t;
    E kind;
  };
  union U switch (E) {
    case A: P point;
    case B: long n;
  };
};
"""
HASH_SAME = """\
// The same types, other layout, comments and file name.
module HashTest {
  /// An enum.
  enum E { A,
           B };   // two
  /** A struct. */
  struct P { double x; sequence<long,3> s; string< 4 > t; E kind; };
  union U switch (E) { case A: P point; case B: long n; };
};
"""
HASH_VARIANTS = {
    "float member": HASH_BASE.replace("double x", "float x"),
    "sequence bound": HASH_BASE.replace("long, 3", "long, 4"),
    "string bound": HASH_BASE.replace("string<4>", "string<5>"),
    "member name": HASH_BASE.replace("double x", "double y"),
    "member order": HASH_BASE.replace(
        "    double x;\n    sequence<long, 3> s;\n", "    sequence<long, 3> s;\n    double x;\n"
    ),
    "enumerator added": HASH_BASE.replace("{ A, B }", "{ A, B, C }"),
    "module name": HASH_BASE.replace("module HashTest", "module HashTest2"),
}


def _hashes(text: str, tmp_path: Path, name: str) -> dict[str, str]:
    folder = tmp_path / name.replace(" ", "_")
    folder.mkdir()
    (folder / f"{name.replace(' ', '_')}.idl").write_text(text)
    out = H.run_miro_idl("-o", "out", f"{name.replace(' ', '_')}.idl", cwd=folder)
    assert out.returncode == 0, out.stderr
    found = {}
    pattern = r'_type_name = "HashTest2?::(\w+)"\n +_type_hash = "([0-9a-f]{64})"'
    for f in (folder / "out").rglob("*_idl.py"):
        found.update(re.findall(pattern, f.read_text()))
    return found


def test_identical_types_give_identical_hashes(tmp_path: Path) -> None:
    base = _hashes(HASH_BASE, tmp_path, "base")
    assert set(base) == {"P", "U"}
    assert _hashes(HASH_SAME, tmp_path, "same") == base
    seen = {base["P"]}
    for name, text in HASH_VARIANTS.items():
        variant = _hashes(text, tmp_path, name)
        assert variant["P"] not in seen, name
        assert variant["U"] != base["U"], name
        seen.add(variant["P"])
    label = _hashes(HASH_BASE.replace("case B: long n;", "default: long n;"), tmp_path, "label")
    assert label["P"] == base["P"] and label["U"] != base["U"]
