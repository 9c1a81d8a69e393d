"""Fixtures of the generated stubs' and skeletons' tests (test_stub_*.py): tests/rpc/Rpc.idl
compiled by `python -m miro_gen.cli.idl` into a temporary folder once per session and imported
from there, servants recording their calls, and an invoker counting what it is asked to send."""

from __future__ import annotations

import importlib
import subprocess
import sys
import threading
from collections.abc import Iterator
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pytest
from repo_paths import REPO
from stub_support import IDL, PACKAGES, CountingInvoker

# =============================================================================================
# generation, servants, fixtures
# =============================================================================================


def _drop_generated_modules() -> None:
    for name in [m for m in sys.modules if m.split(".")[0] in PACKAGES]:
        del sys.modules[name]


@pytest.fixture(scope="session")
def gen(tmp_path_factory: pytest.TempPathFactory) -> Iterator[SimpleNamespace]:
    """The generated packages `Rpc` and `Rpc__POA`, imported from a temporary folder."""
    out = tmp_path_factory.mktemp("rpc_generated")
    proc = subprocess.run(
        [sys.executable, "-m", "miro_gen.cli.idl", "-o", str(out), IDL],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 0, proc.stderr
    assert (out / "Rpc" / "__init__.py").is_file() and (out / "Rpc__POA" / "__init__.py").is_file()
    clash = [m for m in sys.modules if m.split(".")[0] in PACKAGES]
    assert not clash, f"modules {clash} are already imported from elsewhere"
    sys.path.insert(0, str(out))
    try:
        importlib.invalidate_caches()
        rpc = importlib.import_module("Rpc")
        poa = importlib.import_module("Rpc__POA")
        assert Path(rpc.__file__).resolve().parent.parent == out.resolve()
        ns = SimpleNamespace(Rpc=rpc, POA=poa, out=out)
        ns.impl = _servant_classes(rpc, poa)
        yield ns
    finally:
        sys.path.remove(str(out))
        _drop_generated_modules()
        importlib.invalidate_caches()


def _servant_classes(Rpc: Any, POA: Any) -> SimpleNamespace:
    """Implementations of the generated skeletons, recording what they are called with."""

    class ModesImpl(POA.Modes):
        def __init__(self) -> None:
            self.calls: list[tuple[str, tuple[Any, ...]]] = []
            self.value: Any = 0
            self.label = "initial"
            self.counter = 0
            self.exc: BaseException | None = None  # raised by no_raises, raise_it(9), fire
            self.gate: threading.Event | None = None  # fire waits for it
            self.fired = threading.Event()
            self.bad_two_outs: Any = None

        def _record(self, op: str, *args: Any) -> None:
            self.calls.append((op, args))

        def nothing(self) -> None:
            self._record("nothing")

        def set_value(self, v: int) -> None:
            self._record("set_value", v)
            self.value = v
            self.counter += 1

        def get_value(self) -> int:
            return self.value

        def out_only(self) -> int:
            self._record("out_only")
            return 42

        def result_and_outs(self, a: int) -> tuple[int, int, str]:
            self._record("result_and_outs", a)
            return a + 1, 2 * a, f"<{a}>"

        def two_outs(self) -> tuple[int, str]:
            self._record("two_outs")
            if self.bad_two_outs is not None:
                return self.bad_two_outs
            return -5, "two"

        def inout_only(self, s: str) -> tuple[str, str]:
            self._record("inout_only", s)
            return s.upper(), s[::-1]

        def inout_struct(self, p: Any) -> Any:
            self._record("inout_struct", p)
            return Rpc.Point(p.y, -p.x)

        def inout_seq(self, s: list[int]) -> list[int]:
            self._record("inout_seq", s)
            return [*s, sum(s)]

        def inout_string(self, s: str) -> str:
            self._record("inout_string", s)
            return s[::-1] + "!"

        def inout_enum(self, c: Any) -> Any:
            self._record("inout_enum", c)
            return Rpc.Color((c + 1) % 3)

        def inout_union(self, u: Any) -> Any:
            self._record("inout_union", u)
            branch = u._branch()
            if branch == "count":
                return Rpc.Shape(count=u.count + 1)
            if branch == "name":
                return Rpc.Shape(name=u.name + "?")
            return Rpc.Shape(u._d, Rpc.Point(u.where.y, u.where.x))

        def mixed(self, a: Any, s: list[Any], tag: str, o: int) -> Any:
            self._record("mixed", a, s, tag, o)
            color = Rpc.Color.GREEN if tag == "g" else Rpc.Color.BLUE
            return Rpc.Point(a.x + 1, a.y + 1), [*s, a], color, (o + 1) & 0xFF

        def prims(self, *args: Any) -> float:
            self._record("prims", *args)
            return float(args[7]) * 2

        def blob(self, data: bytes) -> bytes:
            self._record("blob", data)
            return data[::-1]

        def bounded(self, s: str, q: list[int]) -> None:
            self._record("bounded", s, q)

        def pick(self, c: Any) -> None:
            self._record("pick", c)

        def raise_it(self, which: int) -> None:
            self._record("raise_it", which)
            if which == 1:
                raise Rpc.Failed(reason="boom", code=7)
            if which == 2:
                raise Rpc.Empty()
            if which == 3:
                raise Rpc.Undeclared(what="surprise")
            if which == 9 and self.exc is not None:
                raise self.exc

        def no_raises(self, which: int) -> None:
            self._record("no_raises", which)
            if self.exc is not None:
                raise self.exc

        def fire(self, v: int) -> None:
            self._record("fire", v)
            if self.gate is not None:
                self.gate.wait(30)  # bounded, so that a stub that waits fails rather than hangs
            self.fired.set()
            if self.exc is not None:
                raise self.exc

        def _get_counter(self) -> int:
            return self.counter

        def _get_label(self) -> str:
            return self.label

        def _set_label(self, value: str) -> None:
            self._record("_set_label", value)
            self.label = value

        def called(self, op: str) -> list[tuple[Any, ...]]:
            return [args for name, args in self.calls if name == op]

    class BaseImpl(POA.Base):
        def __init__(self) -> None:
            self.attr = 0

        def base_op(self, x: int) -> int:
            return x * 10

        def _get_base_attr(self) -> int:
            return self.attr

        def _set_base_attr(self, value: int) -> None:
            self.attr = value

    class RightImpl(BaseImpl, POA.Right):
        def right_op(self) -> str:
            return "right"

    class DiamondImpl(BaseImpl, POA.Diamond):
        def left_op(self) -> str:
            return "left"

        def right_op(self) -> str:
            return "right"

        def diamond_op(self) -> str:
            return "diamond"

    class NodeImpl(POA.Node):
        def __init__(self, name: str) -> None:
            self._name = name
            self._next: Any = None
            self.received: list[Any] = []
            self.children: list[Any] = []

        def name(self) -> str:
            return self._name

        def next(self) -> Any:
            return self._next

        def set_next(self, n: Any) -> None:
            self.received.append(n)
            self._next = n

        def echo_object(self, o: Any) -> Any:
            self.received.append(o)
            return o

        def echo_base(self, b: Any) -> Any:
            self.received.append(b)
            return b

        def make_child(self, name: str) -> Any:
            if not name:
                return None
            child = NodeImpl(name)
            self.children.append(child)
            return child  # a local servant: the skeleton turns it into a reference

        def swap(self, n: Any) -> Any:
            self.received.append(n)
            old, self._next = self._next, n
            return old

        def reverse(self, s: list[Any]) -> list[Any]:
            self.received.append(s)
            return s[::-1]

    class KeywordsImpl(POA.Keywords):
        def __init__(self) -> None:
            self.calls: list[tuple[str, tuple[Any, ...]]] = []
            self.pass_ = 0

        # `print` and `sum` are not Python keywords; define both spellings so that the class
        # is instantiable whichever the generator picks (test_keyword_print_is_escaped...).
        def print(self, from_: int) -> None:
            self.calls.append(("print", (from_,)))

        _print = print

        def sum(self, *args: int) -> int:
            self.calls.append(("sum", args))
            return sum(a * 10**i for i, a in enumerate(args))

        _sum = sum

        def _lambda(self, s: str) -> int:
            self.calls.append(("lambda", (s,)))
            return len(s)

        def _None(self, *args: int) -> int:
            self.calls.append(("None", args))
            return sum(a * 10**i for i, a in enumerate(args))

        def _get_pass(self) -> int:
            return self.pass_

        def _set_pass(self, value: int) -> None:
            self.pass_ = value

        def _get_def(self) -> int:
            return 99

    return SimpleNamespace(
        Modes=ModesImpl,
        Base=BaseImpl,
        Right=RightImpl,
        Diamond=DiamondImpl,
        Node=NodeImpl,
        Keywords=KeywordsImpl,
    )


@pytest.fixture
def inv() -> CountingInvoker:
    return CountingInvoker()


@pytest.fixture
def modes(gen: SimpleNamespace, inv: CountingInvoker) -> tuple[Any, Any]:
    """(stub, servant) of interface Rpc::Modes."""
    servant = gen.impl.Modes()
    return inv.stub(gen.Rpc.Modes, servant), servant
