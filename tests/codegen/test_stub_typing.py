"""The generated stubs and skeletons under `mypy --strict`, as a user's own code uses them."""

from __future__ import annotations

import os
import subprocess
import sys
from types import SimpleNamespace

import pytest
from repo_paths import REPO

# =============================================================================================
# static typing: the generated code under mypy --strict
# =============================================================================================

TYPED_USAGE = '''\
"""A servant and a client, written as a user would, for mypy --strict."""

from __future__ import annotations

from array import array
from typing import Any

import numpy
import Rpc
import Rpc__POA
from miro_gen.exceptions import UNKNOWN, CompletionStatus, SystemException
from miro_gen.runtime.rpc import LocalInvoker, Stub


class ModesImpl(Rpc__POA.Modes):
    def __init__(self) -> None:
        self.value = 0
        self.label = ""

    def nothing(self) -> None:
        pass

    def set_value(self, v: int) -> None:
        self.value = v

    def get_value(self) -> int:
        return self.value

    def out_only(self) -> int:
        return 1

    def result_and_outs(self, a: int) -> tuple[int, int, str]:
        return a, 2 * a, str(a)

    def two_outs(self) -> tuple[int, str]:
        return 1, "b"

    def inout_only(self, s: str) -> tuple[str, str]:
        return s, s.upper()

    def inout_struct(self, p: Rpc.Point) -> Rpc.Point:
        return Rpc.Point(p.y, p.x)

    def inout_seq(self, s: Rpc.LongSeq) -> Rpc.LongSeq:
        return s[::-1]

    def inout_string(self, s: str) -> str:
        return s[::-1]

    def inout_enum(self, c: Rpc.Color) -> Rpc.Color:
        return Rpc.Color.BLUE if c is Rpc.Color.RED else c

    def inout_union(self, u: Rpc.Shape) -> Rpc.Shape:
        return Rpc.Shape(count=u.count + 1)

    def mixed(
        self, a: Rpc.Point, s: Rpc.PointSeq, tag: str, o: int
    ) -> tuple[Rpc.Point, Rpc.PointSeq, Rpc.Color, int]:
        return a, [*s, a], Rpc.Color.GREEN, o

    def prims(
        self, s: int, us: int, l: int, ul: int, ll: int, ull: int,
        f: float, d: float, b: bool, ch: str, o: int,
    ) -> float:
        return d + f

    def blob(self, data: bytes) -> bytes:
        return data

    def bounded(self, s: Rpc.Short5, q: Rpc.Seq3) -> None:
        pass

    def pick(self, c: Rpc.Color) -> None:
        pass

    def raise_it(self, which: int) -> None:
        raise Rpc.Failed(reason="r", code=which)

    def no_raises(self, which: int) -> None:
        pass

    def fire(self, v: int) -> None:
        pass

    def _get_counter(self) -> int:
        return 0

    def _get_label(self) -> str:
        return self.label

    def _set_label(self, value: str) -> None:
        self.label = value


class DiamondImpl(Rpc__POA.Diamond):
    def base_op(self, x: int) -> int:
        return x

    def _get_base_attr(self) -> int:
        return 0

    def _set_base_attr(self, value: int) -> None:
        pass

    def left_op(self) -> str:
        return "l"

    def right_op(self) -> str:
        return "r"

    def diamond_op(self) -> str:
        return "d"


class NodeImpl(Rpc__POA.Node):
    def __init__(self) -> None:
        self.following: Rpc.Node | None = None

    def name(self) -> str:
        return "n"

    def next(self) -> Rpc.Node | None:
        return self.following

    def set_next(self, n: Rpc.Node | None) -> None:
        self.following = n

    def echo_object(self, o: Stub | None) -> Stub | None:
        return o

    def echo_base(self, b: Rpc.Base | None) -> Rpc.Base | None:
        return b

    def make_child(self, name: str) -> NodeImpl:  # a servant returned becomes a reference
        return NodeImpl()

    def swap(self, n: Rpc.Node | None) -> Rpc.Node | None:
        return n

    def reverse(self, s: list[Rpc.Node | None]) -> list[Rpc.Node | None]:
        return s[::-1]


def client() -> None:
    inv = LocalInvoker()
    modes: Rpc.Modes = inv.stub(Rpc.Modes, ModesImpl())
    modes.nothing()
    modes.set_value(3)
    value: int = modes.get_value()
    single: int = modes.out_only()
    result, twice, text = modes.result_and_outs(3)
    total: int = result + twice + value + single
    upper: str = text.upper()
    n, b = modes.two_outs()
    r, s = modes.inout_only("x")
    point: Rpc.Point = modes.inout_struct(Rpc.Point(1, 2))
    seq: Rpc.LongSeq = modes.inout_seq([1, 2])
    longs: array[int] = modes.inout_seq((1, 2))  # numbers go as any sequence or buffer
    longs = modes.inout_seq(array("i", longs))
    longs = modes.inout_seq(numpy.arange(3, dtype=numpy.int32))
    view: numpy.ndarray[Any, numpy.dtype[numpy.int32]] = numpy.frombuffer(seq, numpy.int32)
    rev: str = modes.inout_string("abc")
    color: Rpc.Color = modes.inout_enum(Rpc.Color.RED)
    shape: Rpc.Shape = modes.inout_union(Rpc.Shape(count=1))
    res, points, col, octet = modes.mixed(Rpc.Point(), [Rpc.Point(1, 2)], "t", 3)
    first: Rpc.Point = points[0]
    d: float = modes.prims(1, 2, 3, 4, 5, 6, 7.0, 8.0, True, "c", 9)
    raw: bytes = modes.blob(b"ab")
    modes.bounded("abc", [1])
    modes.pick(Rpc.Color.GREEN)
    modes.fire(1)
    modes._set_label("x")
    label: str = modes._get_label()
    counter: int = modes._get_counter()
    try:
        modes.raise_it(1)
    except Rpc.Failed as failed:
        reason: str = failed.reason
        code: int = failed.code
        print(reason, code)
    except UNKNOWN as unknown:
        done: CompletionStatus = unknown.completed
        print(done)
    except SystemException as other:
        print(other.message, other.minor)
    diamond: Rpc.Diamond = inv.stub(Rpc.Diamond, DiamondImpl())
    base: Rpc.Base = diamond
    left: Rpc.Left = diamond
    print(base.base_op(1), left.left_op(), diamond.right_op(), diamond.diamond_op())
    node: Rpc.Node = inv.stub(Rpc.Node, NodeImpl())
    node.set_next(node)
    node.set_next(None)
    node.set_next(NodeImpl())  # a local servant travels as a reference to itself
    nodes: list[Rpc.Node] = [node]
    for reversed_node in node.reverse(nodes):  # any sequence of stubs will do
        print(reversed_node)
    following: Rpc.Node | None = node.next()
    if following is not None:
        print(following.name())
    obj: Stub | None = node.echo_object(node)
    echoed: Rpc.Base | None = node.echo_base(diamond)
    swapped: Rpc.Node | None = node.swap(node)
    print(total, upper, n, b, r, s, point, seq, rev, color, shape, res, col, octet, first, d,
          raw, label, counter, obj, echoed, swapped, longs, view)
'''

TYPE_ERROR_USAGE = """\
import Rpc


def client(modes: Rpc.Modes) -> None:
    modes.set_value("not a number")
"""

SEQUENCE_OF_REFERENCES_USAGE = """\
import Rpc


def client(node: Rpc.Node) -> None:
    for other in node.reverse([node]):
        if other is not None:
            print(other.name())
"""


def _mypy(gen: SimpleNamespace, name: str, text: str) -> subprocess.CompletedProcess[str]:
    pytest.importorskip("mypy")
    folder = gen.out / "typecheck"
    folder.mkdir(exist_ok=True)
    (folder / "mypy.ini").write_text("[mypy]\n")
    path = folder / name
    path.write_text(text)
    # miro_gen's own generated packages (MiroNaming) come from generated/, as in a wheel.
    paths = [str(gen.out), str(REPO), str(REPO / "generated")]
    env = {**os.environ, "MYPYPATH": os.pathsep.join(paths)}
    return subprocess.run(
        [
            sys.executable,
            "-m",
            "mypy",
            "--strict",
            "--python-version",
            "3.11",
            "--config-file",
            str(folder / "mypy.ini"),
            "--cache-dir",
            str(folder / ".mypy_cache"),
            "--no-color-output",
            "--show-error-codes",
            name,
        ],
        cwd=folder,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )


def test_generated_code_is_usable_under_mypy_strict(gen: SimpleNamespace) -> None:
    out = _mypy(gen, "typed_usage.py", TYPED_USAGE)
    assert out.returncode == 0, out.stdout + out.stderr
    assert "Success" in out.stdout


def test_mypy_reports_a_wrong_argument_type(gen: SimpleNamespace) -> None:
    out = _mypy(gen, "type_error.py", TYPE_ERROR_USAGE)
    assert out.returncode == 1, out.stdout + out.stderr
    errors = [line for line in out.stdout.splitlines() if ": error:" in line]
    assert len(errors) == 1, out.stdout
    assert errors[0].startswith("type_error.py:5:"), errors[0]
    assert '"set_value"' in errors[0] and "[arg-type]" in errors[0], errors[0]


def test_sequence_of_references_is_typed_as_stubs(gen: SimpleNamespace) -> None:
    out = _mypy(gen, "sequence_of_references.py", SEQUENCE_OF_REFERENCES_USAGE)
    assert out.returncode == 0, out.stdout + out.stderr
