"""`<constructor>` blocks compiled into Python, user-written helpers, and `extern` items."""

from __future__ import annotations

import math
import re
from pathlib import Path
from types import ModuleType

import pytest
from miro_cli import REPO, run_miro_params
from params_helpers import compile_and_import, compile_params, import_generated, write

from miro_gen.params.runtime.document import ConfigDocument

CTOR = REPO / "tests" / "params" / "Constructor.xml"


@pytest.fixture(scope="module")
def ctor(tmp_path_factory: pytest.TempPathFactory) -> ModuleType:
    out = tmp_path_factory.mktemp("ctor")
    compile_params(out, CTOR)
    return import_generated(out, "PCtor.Constructor")


def test_constructor_builds_the_defaults(ctor: ModuleType) -> None:
    import Miro

    s = ctor.SonarParameters()
    scan = s.scanDescription
    assert scan.scanType == Miro.RangeSensor.GROUPWISE == 2  # an IDL constant
    assert scan.eventName == "Sonar"
    (group,) = scan.group
    assert isinstance(group, Miro.SensorGroupIDL)
    assert (group.description.minRange, group.description.maxRange) == (150, 5000)
    assert group.description.focus == pytest.approx(math.radians(22.5))
    assert len(group.sensor) == 16  # resize(sensors): the member's default, 16
    assert [p.alpha for p in group.sensor] == pytest.approx(
        [math.radians(i * 22.5 - 180) for i in range(16)]
    )
    assert [p.distance for p in group.sensor[:3]] == [200, 210, 200]  # ?: and C++ %
    assert [p.masked for p in group.sensor] == [False] * 14 + [True] * 2
    assert s.weights == [0.5, 0.25, 0.25]  # local table, a descending loop, *=
    assert s.modes == ["off"]
    assert s.period.total_seconds() == 0.1
    assert s.label == "ring-16-big"  # if / else
    assert s.line.baudrate == 38400
    assert s.sensors == 2  # C++ arithmetic: 7 / 2 + (-7) % 3
    assert ctor.SonarParameters.instance() is ctor.SonarParameters.instance()


def test_constructor_defaults_give_way_to_arguments_and_documents(ctor: ModuleType) -> None:
    s = ctor.SonarParameters(label="given")
    assert s.label == "given" and s.weights == [0.5, 0.25, 0.25]
    assert s.model_fields_set == {"label"}
    doc = ConfigDocument(
        text='<config><section name="sonar"><parameter name="Sonar">'
        '<parameter name="Weights" value="1 2"/></parameter></section></config>'
    )
    doc.set_section("sonar")
    doc.get_parameters("Sonar", s)
    assert s.weights == [1.0, 2.0] and len(s.scanDescription.group[0].sensor) == 16


def test_generated_constructor_code_is_plain_python(tmp_path: Path) -> None:
    compile_params(tmp_path, CTOR)
    code = (tmp_path / "PCtor" / "Constructor.py").read_text()
    assert "for _l_i in range(0, self.sensors):" in code
    assert (
        "_rt.resize(self.scanDescription.group, 1, _m_Miro_ScanDescription_idl.SensorGroupIDL)"
        in code
    )
    assert "exec(" not in code and "eval(" not in code


def _ctor_file(tmp_path: Path, body: str, params: str = "") -> Path:
    return write(
        tmp_path / "C.xml",
        f"""\
        <config>
          <config_global name="namespace" value="PC" />
          <config_item name="A" parent="Miro::Config">
            <config_parameter name="N" type="int" default="2" />
            <config_parameter name="X" type="double" />
            <config_parameter name="S" type="std::string" />
            <config_parameter name="V" type="std::vector&lt;int&gt;" />
            <config_parameter name="E" type="Enumeration" values="a, b" />
            {params}
            <constructor>
{body}
            </constructor>
          </config_item>
        </config>
        """,
    )


@pytest.mark.parametrize(
    ("body", "line", "message"),
    [
        ("n = 1;\nx = y;", 12, "unknown name 'y'"),
        ("n = 1.5;", 11, "cannot store a float in n (a int)"),
        ("s = 3;", 11, "cannot store a int in s (a str)"),
        ('e = "c";', 11, "'c' is not one of a, b"),
        ("v = 3;", 11, "assigning a whole structure or vector"),
        ("n.length(3);", 11, "needs a vector or set member"),
        ("v.reserve(3);", 11, "reserve() is not supported"),
        ("x = sqrtf(2.0);", 11, "the function sqrtf() is not supported"),
        ("n = 1;\n\nwhile (n) { n--; }", 13, "constructor: unexpected"),
        ("x = 1.0 % 2;", 11, "% needs integers"),
        ("n = Miro::NoSuch::CONST;", 11, "unknown constant 'Miro::NoSuch::CONST'"),
        ("for (int i = 0; i &lt; 3; --i) n = i;", 11, "the loop never ends"),
        ('int k = 1; k = "x";', 11, "cannot store a str in k"),
        ("static const int t[2] = {1, 2, 3};", 11, "t[2] is given 3 values"),
        ("delete this;", 11, "unexpected"),
        ("if (v) n = 1;", 11, "structures and vectors cannot be used as values"),
    ],
)
def test_constructor_errors_name_line_and_construct(
    tmp_path: Path, body: str, line: int, message: str
) -> None:
    src = _ctor_file(tmp_path, body)
    out = run_miro_params("-o", str(tmp_path / "out"), str(src))
    assert out.returncode == 1, out.stdout
    assert "Traceback" not in out.stderr
    m = re.search(r"C\.xml:(\d+)(:\d+)?: error: (.*)", out.stderr)
    assert m, out.stderr
    assert int(m[1]) == line and message in m[3], out.stderr
    assert not (tmp_path / "out").exists()


def test_all_constructor_errors_are_collected(tmp_path: Path) -> None:
    src = _ctor_file(tmp_path, "n = 1.5;\nn = 2;\ns = 4;")
    out = run_miro_params("-o", str(tmp_path / "out"), str(src))
    assert out.returncode == 1
    assert re.findall(r"C\.xml:(\d+)", out.stderr) == ["11", "13"]


# MiroMicro's RobotParameters.xml: C++ that makeParams pasted into the constructor as it is
HOSTNAME_CXX = """\
char* hn = getenv("HOSTNAME");
if (hn != NULL) {
  std::string hostname = hn;
  unsigned int current = 0;
  do { ++current; } while (current &lt; hostname.length() &amp;&amp; hostname[current] != '.');
  s = hostname.substr(0, current);
}"""


def test_cxx_beyond_the_subset_is_an_error_that_says_the_way_out(tmp_path: Path) -> None:
    src = _ctor_file(tmp_path, HOSTNAME_CXX)
    out = run_miro_params("-o", str(tmp_path / "out"), str(src))
    assert out.returncode == 1 and "Traceback" not in out.stderr
    assert re.search(r"C\.xml:11:\d+: error: constructor: unexpected '\*'", out.stderr)
    assert re.search(r"C\.xml:11:\d+: note: .*--skip-untranslatable.*PC::AParameters", out.stderr)
    assert not (tmp_path / "out").exists()


def test_skip_untranslatable_generates_the_class_with_its_declared_defaults(
    tmp_path: Path,
) -> None:
    src = _ctor_file(tmp_path, HOSTNAME_CXX)
    out = run_miro_params("--skip-untranslatable", "-o", str(tmp_path / "out"), str(src))
    assert out.returncode == 0, out.stderr
    warning = "warning: constructor: unexpected '*'; the constructor of PC::AParameters is left out"
    assert warning in out.stderr
    a = import_generated(tmp_path / "out", "PC.C").AParameters()
    assert (a.n, a.s) == (2, "")


def test_user_helper_module_reads_and_writes_its_type(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.syspath_prepend(str(REPO / "tests" / "params"))  # polygon_helper.py
    module = compile_and_import(
        tmp_path,
        """\
        <config>
          <config_global name="namespace" value="PHelp" />
          <config_global name="python_helper" type="Miro::Polygon" value="polygon_helper" />
          <config_item name="Map" parent="Miro::Config">
            <config_parameter name="Outline" type="Miro::Polygon" />
            <config_parameter name="Holes" type="std::vector&lt;Miro::Polygon&gt;" />
          </config_item>
        </config>
        """,
        "PHelp.P",
    )
    m = module.MapParameters()
    assert m.outline == [] and m.holes == []
    doc = ConfigDocument(
        text='<config><section name="s"><parameter name="Map">\n'
        '<parameter name="Outline" value="0,0 4,0 4,3"/>\n'
        '<parameter name="Holes"><parameter value="1,1 2,1 2,2"/></parameter>\n'
        "</parameter></section></config>",
    )
    doc.set_section("s")
    doc.get_parameters("Map", m)
    assert m.outline == [(0, 0), (4, 0), (4, 3)] and m.holes == [[(1, 1), (2, 1), (2, 2)]]
    assert module.MapParameters().from_xml(m.to_xml("Map")) == m
    assert "Outline: 0,0 4,0 4,3" in str(m)
    bad = ConfigDocument(
        text='<config><section name="s"><parameter name="Map">\n'
        '<parameter name="Outline" value="0,0 4"/></parameter></section></config>',
        path="bad.xml",
    )
    bad.set_section("s")
    with pytest.raises(Exception, match=r"bad\.xml:2: error: Map\.Outline: expected x,y pairs"):
        bad.get_parameters("Map", m)


def test_extern_items_are_imported_not_generated(tmp_path: Path) -> None:
    write(
        tmp_path / "out" / "PExt" / "__init__.py",
        '"""Written by hand: the extern class."""\n\n'
        "from miro_gen.params.runtime import INT, Config, XmlField\n\n\n"
        "class OutsideParameters(Config):\n"
        "    value: int = 4\n"
        '    _xml_fields = (XmlField("Value", "value", INT),)\n',
    )
    module = compile_and_import(
        tmp_path,
        """\
        <config>
          <config_global name="namespace" value="PExt" />
          <config_item name="Outside" parent="Miro::Config" extern="true">
            <config_parameter name="Value" type="int" />
          </config_item>
          <config_item name="User" parent="Miro::Config">
            <config_parameter name="Inner" type="OutsideParameters" />
          </config_item>
        </config>
        """,
        "PExt.P",
    )
    assert not hasattr(module, "OutsideParameters")
    u = module.UserParameters()
    assert u.inner.value == 4 and type(u.inner).__module__ == "PExt"
