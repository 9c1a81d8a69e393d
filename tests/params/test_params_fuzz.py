"""Bad input never crashes: random run-time documents and random compile-time files end in
values or in `path:line` errors, never in another exception."""

from __future__ import annotations

import contextlib
from pathlib import Path
from types import ModuleType

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from lxml import etree
from params_helpers import SETTINGS, all_types

from miro_gen.diagnostics import CompileError, Diagnostics
from miro_gen.params.runtime import ParamsError


@pytest.fixture(scope="module")
def types_module(tmp_path_factory: pytest.TempPathFactory) -> ModuleType:
    return all_types(tmp_path_factory.mktemp("fuzz"))


NAMES = ["Flag", "int", "Text", "Heading", "Period", "Server", "Line", "Mode", "Modes",
         "Numbers", "Tags", "Matrix", "Origin", "Path", "Tty", "Scan", "Group", "Sensor",
         "Alpha", "X", "Baudrate", "Version", "Nope", None]  # fmt: skip
VALUES = ["", "1", "-1", "0x1F", "1e400", "nan", "true", "Run", "A, B", "1 2 3", "1 2; 3 4",
          "host:80", "1, 2", "é", "  ", None]  # fmt: skip


def trees(depth: int) -> st.SearchStrategy[etree._Element]:
    def build(name: str | None, value: str | None, kids: list[etree._Element]) -> etree._Element:
        elem = etree.Element("parameter")
        if name is not None:
            elem.set("name", name)
        if value is not None:
            elem.set("value", value)
        elem.extend(kids)
        return elem

    leaf = st.builds(build, st.sampled_from(NAMES), st.sampled_from(VALUES), st.just([]))
    if depth == 0:
        return leaf
    return st.one_of(
        leaf,
        st.builds(
            build,
            st.sampled_from(NAMES),
            st.sampled_from(VALUES),
            st.lists(trees(depth - 1), max_size=4),
        ),
    )


def test_random_documents_give_values_or_positioned_errors(types_module: ModuleType) -> None:
    @settings(SETTINGS, max_examples=300)
    @given(kids=st.lists(trees(3), max_size=5))
    def check(kids: list[etree._Element]) -> None:
        root = etree.fromstring(
            etree.tostring(etree.Element("parameter", name="All"))
        )  # a parsed element has line numbers
        root.extend(kids)
        text = etree.tostring(root)
        elem = etree.fromstring(text)
        params = types_module.AllParameters()
        before = params.model_copy(deep=True)
        try:
            params.from_xml(elem, "fuzz.xml")
        except ParamsError as e:
            assert e.diagnostics
            assert all(str(d).startswith("fuzz.xml:") for d in e.diagnostics), str(e)
            assert params == before

    check()


ATTRS = {
    "config_global": ["name", "value"],
    "config_item": ["name", "parent", "final", "dummy", "extern", "instance"],
    "config_parameter": ["name", "type", "default", "values", "static_const", "inherited"],
}
ATTR_VALUES = [
    "python_class",
    "local_forward",
    "Behaviour",
    "Mcp::",
    "::",
    "Config",
    "M_PI/2",
    "150*1024*1024",
    "ACE_SCHED_FIFO, 50",
    "0,5",
    "1 / 0",
    "(int)2.5",
    "INFINITY",
    "1 << 70",
    "~0u",
    "std::vector<AParameters>",
    "vector<BParameters>",
    "ACE_Sched_Params",
    "ACE_TTY_IO::Serial_Params",
    "Miro::Enumeration",
    "3, 1.5",
    "maybe",
    "",
    "A",
    "B",
    "int",
    "double",
    "true",
    "false",
    "namespace",
    "include",
    "x",
    "Miro::Config",
    "std::vector<int>",
    "vector<",
    "BParameters",
    "Enumeration",
    "1 2",
    "a, b",
    "Miro::Dev",
    "miro/SvcParameters.h",
    "angle",
    "ACE_Time_Value",
    "1, 2",
]


@st.composite
def compile_time_files(draw: st.DrawFn) -> bytes:
    root = etree.Element("config")
    for _ in range(draw(st.integers(0, 5))):
        tag = draw(st.sampled_from([*ATTRS, "config_group", "constructor", "bogus"]))
        parent = root
        if tag == "config_group":  # items inside a group, as real files put them
            parent = etree.SubElement(root, tag, name=draw(st.sampled_from(["g", "", "A"])))
            tag = "config_item"
        elem = etree.SubElement(parent, tag)
        for attr in draw(st.lists(st.sampled_from(ATTRS.get(tag, ["name"])), max_size=4)):
            elem.set(attr, draw(st.sampled_from(ATTR_VALUES)))
        if tag == "config_item":
            for _ in range(draw(st.integers(0, 3))):
                p = etree.SubElement(
                    elem, draw(st.sampled_from(["config_parameter", "constructor"]))
                )
                for attr in draw(st.lists(st.sampled_from(ATTRS["config_parameter"]), max_size=4)):
                    p.set(attr, draw(st.sampled_from(ATTR_VALUES)))
                if p.tag == "constructor":
                    p.text = draw(
                        st.sampled_from(
                            ["a = 1;", "for(;;)", "b.resize(2);", "", "{", "a = 1 << 2;",
                             "static int t[3] = {1};", "a = M_PI;", "a.b.c = 2;", "a = b;"]
                        )
                    )  # fmt: skip
    return etree.tostring(root)


def test_random_compile_time_files_compile_or_report_errors(tmp_path: Path) -> None:
    """...and what compiles renders as Python that compiles (the generator's own output)."""
    from miro_gen.compile.params import params_modules
    from miro_gen.params.compiler.generate import render_module
    from miro_gen.params.compiler.pymodel import PyParamsModule

    @settings(SETTINGS, max_examples=200)
    @given(data=compile_time_files())
    def check(data: bytes) -> None:
        src = tmp_path / "F.xml"
        src.write_bytes(data)
        diag = Diagnostics()
        modules: list[object] = []
        with contextlib.suppress(CompileError):
            modules = params_modules([str(src)], [], None, diag)
        for d in diag.items:
            assert d.severity != "error" or d.pos is None or d.pos.path.endswith("F.xml"), d
        if not diag.has_errors:
            for m in modules:
                assert isinstance(m, PyParamsModule)
                compile(render_module(m), "generated.py", "exec")

    check()
