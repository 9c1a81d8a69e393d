"""Run time: the generated classes reading, writing and printing run-time documents, and
`ConfigDocument` finding and checking them (the manual's examples end to end)."""

from __future__ import annotations

import datetime
import math
import re
import socket
from pathlib import Path
from types import ModuleType

import pydantic
import pytest
from hypothesis import given
from hypothesis import strategies as st
from lxml import etree
from miro_cli import REPO
from params_helpers import PARAMS, SETTINGS, all_types, write

from miro_gen.params.runtime import InetAddr, ParamsError
from miro_gen.params.runtime.document import ConfigDocument


@pytest.fixture(scope="module")
def types_module(tmp_path_factory: pytest.TempPathFactory) -> ModuleType:
    return all_types(tmp_path_factory.mktemp("alltypes"))


def document(body: str, section: str = "s", path: str = "run.xml") -> ConfigDocument:
    doc = ConfigDocument(
        text=f'<config>\n<section name="{section}">\n{body}</section>\n</config>\n', path=path
    )
    doc.set_section(section)
    return doc


# -- the manual's examples ------------------------------------------------------------------


def test_manual_example_10_2_and_10_3() -> None:
    from Test.Parameters import MyParameters

    params = MyParameters.instance()
    assert params is MyParameters.instance()  # instance="true": one per process
    assert params.testVector == [] and params.testInteger == 1
    config = ConfigDocument(["prog", "-MiroConfigFile", str(PARAMS / "etc" / "test.xml")])
    config.set_section("test")
    assert config.get_parameters("Test", params)
    assert params.testVector == [2, 4, 2, 5]
    assert params.testInteger == 1  # not in the document: the default stays
    assert str(params) == "TestVector: [2 4 2 5]\nTestInteger: 1"


def test_manual_example_10_4_nested_structures() -> None:
    from Test.Body import BodyFrameParameters, BodyParameters, MatrixParameters

    body = BodyParameters()
    config = ConfigDocument(["-MCF", str(PARAMS / "etc" / "body.xml")])
    config.set_section("body")
    config.get_parameters("Body", body)
    assert body.bodyName == "Raptor"
    assert body.hTransform == MatrixParameters(
        row1="1.00 0.00 0.00 0.00", row2="0.00 1.00 0.00 0.00", row3="0.00 0.00 1.00 5"
    )
    assert [f.frameName for f in body.frames] == ["CG", "CabRailCentre"]
    assert isinstance(body.frames[0], BodyFrameParameters)
    assert body.frames[1].hTransform.row3 == "0.00 0.00 1.00 5.00"
    assert body.transform == [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 5]]
    text = str(body)
    assert "Frames: (2)\n  [0]:\n    FrameName: CG\n" in text
    assert text.endswith("Transform: [1 0 0 0; 0 1 0 0; 0 0 1 5]")


# -- every type --------------------------------------------------------------------------------


def test_defaults_of_every_type(types_module: ModuleType) -> None:
    a = types_module.AllParameters()
    assert (a.flag, a.letter, a.short, a.uShort, a.int_, a.uInt) == (True, "m", -3, 3, -7, 7)
    assert (a.long, a.uLong, a.float_, a.double) == (-9000000000, 9000000000, 0.5, 0.1)
    assert (a.text, a.plain) == ("hello world", "")
    assert a.heading == pytest.approx(math.pi / 2) and a.bearing == pytest.approx(-math.pi / 4)
    assert a.period == datetime.timedelta(seconds=1, microseconds=500000)
    assert a.server == InetAddr("localhost", 2809)
    assert a.line.baudrate == 9600 and a.sched.policy == "SCHED_OTHER"
    assert (a.mode, a.modes, a.numbers) == ("Run", [], [1, 2, 3])
    assert (a.tags, a.ids, a.matrix, a.path) == (set(), set(), [], [])
    assert a.origin.x == 1.5 and a.tty.device == "/dev/ttyS0"
    assert type(a).VERSION == 3  # static_const: a class constant (makeParams: upper case)
    assert "VERSION" not in type(a).model_fields and "version" not in type(a).model_fields
    point3 = types_module.Point3Parameters()
    assert (point3.x, point3.y, point3.z) == (2.5, 0.0, 0.0)  # inherited: X's default overridden
    assert isinstance(point3, types_module.PointParameters)
    nameless = types_module.Parameters()
    assert nameless.lowerCase == 4 and nameless.from_ == 5  # a keyword gets a trailing _


ALL_VALUES = """\
<parameter name="All">
  <parameter name="Flag" value="false"/>
  <parameter name="Letter" value="q"/>
  <parameter name="Short" value="-32768"/>
  <parameter name="UShort" value="65535"/>
  <parameter name="int" value="0x10"/>
  <parameter name="UInt" value="4294967295"/>
  <parameter name="Long" value="-9223372036854775808"/>
  <parameter name="ULong" value="18446744073709551615"/>
  <parameter name="Float" value="2.5e3"/>
  <parameter name="Double" value="-1e-300"/>
  <parameter name="Text" value="  spaced &amp; &lt;escaped&gt;  "/>
  <parameter name="Heading" value="180"/>
  <parameter name="Period" value="2, 250000"/>
  <parameter name="Server" value="robot1:5000"/>
  <parameter name="Line">
    <parameter name="Baudrate" value="115200"/>
    <parameter name="Parityenb" value="true"/>
    <parameter name="Paritymode" value="even"/>
    <parameter name="Databits" value="7"/>
    <parameter name="Stopbits" value="2"/>
  </parameter>
  <parameter name="Sched">
    <parameter name="Policy" value="SCHED_FIFO"/>
    <parameter name="Priority" value="10"/>
  </parameter>
  <parameter name="Mode" value="Stop"/>
  <parameter name="Modes"><parameter value="C"/><parameter value="A"/></parameter>
  <parameter name="Numbers"><parameter value="4"/><parameter value="5"/></parameter>
  <parameter name="Ranges" value="0.5, 1.5 2.5"/>
  <parameter name="Names"><parameter value="front left"/><parameter value="rear"/></parameter>
  <parameter name="Tags">
    <parameter value="b"/><parameter value="a"/><parameter value="b"/>
  </parameter>
  <parameter name="Ids" value="3 1 2"/>
  <parameter name="Matrix">
    <parameter value="1 2"/>
    <parameter><parameter value="3"/><parameter value="4"/></parameter>
  </parameter>
  <parameter name="Origin"><parameter name="Y" value="7"/></parameter>
  <parameter name="Path">
    <parameter><parameter name="X" value="1"/><parameter name="Y" value="2"/></parameter>
    <parameter><parameter name="x" value="3"/></parameter>
  </parameter>
  <parameter name="Grid">
    <parameter><parameter><parameter name="Y" value="1"/></parameter></parameter>
    <parameter/>
  </parameter>
  <parameter name="Tty">
    <parameter name="Device" value="/dev/ttyUSB0"/>
    <parameter name="TtyParams"><parameter name="Baudrate" value="57600"/></parameter>
  </parameter>
  <parameter name="Scan">
    <parameter name="ScanType" value="2"/>
    <parameter name="Group">
      <parameter>
        <parameter name="Description"><parameter name="MaxRange" value="5000"/></parameter>
        <parameter name="Sensor">
          <parameter><parameter name="Alpha" value="-90"/></parameter>
          <parameter>
            <parameter name="Alpha" value="90"/><parameter name="Masked" value="1"/>
          </parameter>
        </parameter>
      </parameter>
    </parameter>
  </parameter>
</parameter>
"""


def test_reading_every_type(types_module: ModuleType) -> None:
    a = types_module.AllParameters()
    assert document(ALL_VALUES).get_parameters("All", a)
    assert (a.flag, a.letter, a.short, a.uShort, a.int_, a.uInt) == (
        False,
        "q",
        -32768,
        65535,
        16,
        4294967295,
    )
    assert (a.long, a.uLong) == (-(2**63), 2**64 - 1)
    assert (a.float_, a.double) == (2500.0, -1e-300)
    assert a.text == "  spaced & <escaped>  "  # strings are kept as written
    assert a.heading == pytest.approx(math.pi)  # degrees in XML, radians in memory
    assert a.period == datetime.timedelta(seconds=2.25)
    assert a.server == InetAddr("robot1", 5000)
    assert a.line.pyserial() == {
        "baudrate": 115200,
        "bytesize": 7,
        "parity": "E",
        "stopbits": 2,
        "xonxoff": False,
        "rtscts": False,
        "timeout": 10.0,
    }
    assert (a.sched.policy, a.sched.priority) == ("SCHED_FIFO", 10)
    assert (a.mode, a.modes, a.numbers) == ("Stop", ["C", "A"], [4, 5])
    assert a.ranges == [0.5, 1.5, 2.5]  # the compact form
    assert a.names == ["front left", "rear"]
    assert a.tags == {"a", "b"} and a.ids == {1, 2, 3}
    assert a.matrix == [[1.0, 2.0], [3.0, 4.0]]  # rows compact or element by element
    assert (a.origin.x, a.origin.y) == (1.5, 7.0)  # a nested structure keeps unnamed defaults
    assert [(p.x, p.y) for p in a.path] == [(1.0, 2.0), (3.0, 0.0)]
    assert [[(p.x, p.y) for p in row] for row in a.grid] == [[(1.5, 1.0)], []]  # any depth
    assert a.tty.device == "/dev/ttyUSB0" and a.tty.ttyParams.baudrate == 57600
    assert a.scan.scanType == 2
    group = a.scan.group[0]
    assert group.description.maxRange == 5000
    assert [s.alpha for s in group.sensor] == pytest.approx([-math.pi / 2, math.pi / 2])
    assert [s.masked for s in group.sensor] == [False, True]
    assert type(group).__name__ == "SensorGroupIDL"  # the IDL struct itself, via its helper


@pytest.mark.parametrize(
    ("xml", "message"),
    [
        ('<parameter name="Flag" value="maybe"/>', "expected true or false, got 'maybe'"),
        ('<parameter name="Letter" value="ab"/>', "expected one character"),
        ('<parameter name="Short" value="40000"/>', "outside the range of short"),
        ('<parameter name="UInt" value="-1"/>', "outside the range of unsigned int"),
        ('<parameter name="Double" value="fast"/>', "expected a number (double)"),
        ('<parameter name="Float" value="1e39"/>', "outside the range of float"),
        ('<parameter name="Period" value="soon"/>', 'expected "sec, usec" or seconds'),
        ('<parameter name="Server" value="robot1"/>', "expected host:port"),
        ('<parameter name="Server" value="robot1:99999"/>', "outside 0..65535"),
        ('<parameter name="Mode" value="Fly"/>', "'Fly' is not one of Idle, Run, Stop"),
        ('<parameter name="Modes" value="A, D"/>', "'D' is not one of A, B, C"),
        ('<parameter name="Numbers" value="1 two 3"/>', "All.Numbers[1]: expected an integer"),
        (
            '<parameter name="Names" value="a b"/>',
            "lists its elements as <parameter value=.../>",
        ),
        ('<parameter name="Numbers"><parameter name="X" value="1"/></parameter>', "have no name"),
        ('<parameter name="Origin" value="1 2"/>', "is a structure"),
        ('<parameter name="Int"><parameter value="1"/></parameter>', "takes value=..."),
        ('<parameter name="Int"/>', "missing value=..."),
        ('<parameter name="Int" value="1">2</parameter>', "text inside <parameter> is not read"),
        ('<parameter name="Intt" value="1"/>', "unknown parameter 'Intt'"),
        ('<parameter name="Version" value="4"/>', "Version is a constant"),
        ('<parameter value="4"/>', "needs a name="),
        ('<param name="Int" value="4"/>', "unexpected element <param>"),
        (
            '<parameter name="Int" value="1"/><parameter name="int" value="2"/>',
            "All.Int: given twice",
        ),
        (
            '<parameter name="Path"><parameter><parameter name="Z" value="1"/></parameter>'
            "</parameter>",
            "All.Path[0]: unknown parameter 'Z'",
        ),
        (
            '<parameter name="Scan"><parameter name="Group"><parameter>'
            '<parameter name="Sensor"><parameter><parameter name="Alpha" value="x"/>'
            "</parameter></parameter></parameter></parameter></parameter>",
            "All.Scan.Group[0].Sensor[0].Alpha: expected a number (angle)",
        ),
    ],
)
def test_bad_values_are_reported_with_file_and_line(
    types_module: ModuleType, xml: str, message: str
) -> None:
    a = types_module.AllParameters()
    before = a.model_copy(deep=True)
    with pytest.raises(ParamsError) as e:
        document(f'<parameter name="All">\n{xml}\n</parameter>\n').get_parameters("All", a)
    text = str(e.value)
    assert re.match(r"run\.xml:4: error: ", text), text
    assert message in text, text
    assert a == before  # nothing changed


def test_all_errors_are_collected_and_nothing_changes(types_module: ModuleType) -> None:
    a = types_module.AllParameters()
    doc = document(
        '<parameter name="All">\n'
        '  <parameter name="Int" value="5"/>\n'
        '  <parameter name="Short" value="x"/>\n'
        '  <parameter name="Bogus" value="1"/>\n'
        '  <parameter name="Path"><parameter><parameter name="X" value="?"/></parameter>'
        "</parameter>\n"
        "</parameter>\n"
    )
    with pytest.raises(ParamsError) as e:
        doc.get_parameters("All", a)
    lines = [str(d) for d in e.value.diagnostics]
    assert [line.split(": error")[0] for line in lines] == ["run.xml:5", "run.xml:6", "run.xml:7"]
    assert a.int_ == -7  # the valid value on line 4 was not applied either


def test_pydantic_checks_keyword_arguments_and_assignments(types_module: ModuleType) -> None:
    with pytest.raises(pydantic.ValidationError, match="extra"):
        types_module.AllParameters(intt=3)
    a = types_module.AllParameters(int_=3)
    with pytest.raises(pydantic.ValidationError):
        a.mode = "Fly"
    with pytest.raises(pydantic.ValidationError):
        a.numbers = ["x"]
    assert types_module.AllParameters.model_fields["double"].description == "[m]"


def test_sched_params_apply_to_this_process() -> None:
    import os

    from miro_gen.params.runtime import SchedParams

    before = os.sched_getscheduler(0), os.sched_getparam(0)
    try:
        SchedParams(policy="SCHED_OTHER", priority=0).apply()  # needs no privileges
        assert os.sched_getscheduler(0) == os.SCHED_OTHER
    finally:
        os.sched_setscheduler(0, *before)


# -- round trips ----------------------------------------------------------------------------


def _roundtrip(module: ModuleType, value: object, compact: bool) -> object:
    elem = value.to_xml("All", compact=compact)  # type: ignore[attr-defined]
    text = etree.tostring(elem)
    fresh = module.AllParameters()
    fresh.from_xml(etree.fromstring(text), "roundtrip.xml")
    return fresh


def test_round_trip_of_the_full_document(types_module: ModuleType) -> None:
    a = types_module.AllParameters()
    document(ALL_VALUES).get_parameters("All", a)
    for compact in (False, True):
        assert _roundtrip(types_module, a, compact) == a


def test_compact_writing(types_module: ModuleType) -> None:
    a = types_module.AllParameters(numbers=[1, 2], matrix=[[1.0, 0.5], [0.0, 1.0]])
    elem = a.to_xml("All", compact=True)
    assert elem.find("parameter[@name='Numbers']").get("value") == "1 2"
    assert elem.find("parameter[@name='Matrix']").get("value") == "1 0.5; 0 1"
    classic = a.to_xml("All")
    assert [p.get("value") for p in classic.find("parameter[@name='Numbers']")] == ["1", "2"]


def test_shift_operators(types_module: ModuleType) -> None:
    a = types_module.PointParameters(x=3.0)
    elem = etree.Element("parameter", name="Point")
    a >>= elem
    b = types_module.PointParameters()
    b <<= elem
    assert b == a


_finite = st.floats(allow_nan=False, allow_infinity=False)
_text = st.text(st.characters(codec="utf-8", exclude_categories=("Cs", "Cc")), max_size=12)


@st.composite
def all_values(draw: st.DrawFn, module: ModuleType) -> object:
    point = st.builds(module.PointParameters, x=_finite, y=_finite)
    return module.AllParameters(
        flag=draw(st.booleans()),
        letter=draw(st.characters(codec="utf-8", exclude_categories=("Cs", "Cc"))),
        short=draw(st.integers(-(2**15), 2**15 - 1)),
        uLong=draw(st.integers(0, 2**64 - 1)),
        double=draw(_finite),
        float_=draw(st.floats(-1e38, 1e38)),
        text=draw(_text),
        period=datetime.timedelta(microseconds=draw(st.integers(-(10**12), 10**12))),
        server=InetAddr(
            draw(st.sampled_from(["localhost", "::1", "robot-1"])), draw(st.integers(0, 65535))
        ),
        mode=draw(st.sampled_from(["Idle", "Run", "Stop"])),
        modes=draw(st.lists(st.sampled_from(["A", "B", "C"]), max_size=4)),
        numbers=draw(st.lists(st.integers(-(2**31), 2**31 - 1), max_size=5)),
        ranges=draw(st.lists(_finite, max_size=5)),
        names=draw(st.lists(_text, max_size=3)),
        tags=draw(st.sets(_text, max_size=3)),
        ids=draw(st.sets(st.integers(0, 2**32 - 1), max_size=3)),
        matrix=draw(st.lists(st.lists(_finite, min_size=1, max_size=3), max_size=3)),
        origin=draw(point),
        path=draw(st.lists(point, max_size=3)),
        grid=draw(st.lists(st.lists(point, max_size=2), max_size=2)),
    )


def test_round_trip_property(types_module: ModuleType) -> None:
    @SETTINGS
    @given(data=st.data(), compact=st.booleans())
    def check(data: st.DataObject, compact: bool) -> None:
        value = data.draw(all_values(types_module))
        assert _roundtrip(types_module, value, compact) == value

    check()


@SETTINGS
@given(degrees=st.floats(-1e6, 1e6))
def test_angles_round_trip_through_degrees(degrees: float) -> None:
    from Miro.SvcParameters import MotionParameters

    m = MotionParameters(maxRotation=math.radians(degrees))
    back = MotionParameters().from_xml(m.to_xml("Motion"))
    assert back.maxRotation == pytest.approx(m.maxRotation, rel=1e-15, abs=1e-15)


# -- ConfigDocument -------------------------------------------------------------------------


def test_hostname_document_is_found_in_cwd_then_miro_root(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    host = socket.gethostname().split(".")[0]
    root = tmp_path / "root"
    write(root / "etc" / f"{host}.xml", '<config><section name="from-root"/></config>')
    monkeypatch.setenv("MIRO_ROOT", str(root))
    monkeypatch.chdir(tmp_path)
    assert ConfigDocument([]).sections() == ["from-root"]
    write(tmp_path / f"{host}.xml", '<config><section name="from-cwd"/></config>')
    assert ConfigDocument([]).sections() == ["from-cwd"]
    write(tmp_path / "other.xml", '<config><section name="named"/></config>')
    assert ConfigDocument(["-MCF", "other.xml"]).sections() == ["named"]
    monkeypatch.delenv("MIRO_ROOT")
    (tmp_path / f"{host}.xml").unlink()
    assert ConfigDocument([]).sections() == []  # no document: every default stays


def test_a_missing_document_is_reported_once_at_notice_level(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    import logging

    host = socket.gethostname().split(".")[0]
    monkeypatch.setenv("MIRO_ROOT", str(tmp_path / "root"))
    monkeypatch.chdir(tmp_path)
    caplog.set_level(logging.DEBUG, logger="miro")
    for _ in range(3):
        assert ConfigDocument([]).sections() == []
    notices = [r for r in caplog.records if "no run-time parameter document" in r.getMessage()]
    assert len(notices) == 1 and notices[0].levelname == "NOTICE"
    message = notices[0].getMessage()
    assert str(tmp_path / f"{host}.xml") in message
    assert str(tmp_path / "root" / "etc" / f"{host}.xml") in message


def test_documents_over_the_size_limit_are_refused_before_they_are_parsed(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("MIRO_PARAMS_MAX_BYTES", "1000")
    big = write(tmp_path / "big.xml", "<config>" + " " * 1000 + "</config>")
    with pytest.raises(ParamsError) as e:
        ConfigDocument(path=big)
    assert str(e.value) == (
        f"{big}:1: error: the document is larger than 1000 bytes, the limit for parameter "
        "documents (set MIRO_PARAMS_MAX_BYTES to allow more)"
    )
    with pytest.raises(ParamsError, match="larger than 1000 bytes"):
        ConfigDocument(text=big.read_text())
    with pytest.raises(ParamsError, match="larger than 1000 bytes"):
        ConfigDocument(path="/dev/zero")  # reading stops at the limit
    monkeypatch.delenv("MIRO_PARAMS_MAX_BYTES")
    assert ConfigDocument(path=big).sections() == []  # the default limit is 8 MiB


def test_the_run_time_half_imports_no_compiler() -> None:
    import subprocess
    import sys

    code = (
        "import sys, miro_gen.params, Test.Parameters\n"
        "bad = [m for m in sys.modules if m.startswith(('lark', 'jinja2', "
        "'miro_gen.params.compiler', 'miro_gen.codegen'))]\n"
        "assert not bad, bad"
    )
    env = {"PYTHONPATH": f"{REPO}:{REPO / 'generated'}", "PATH": "/usr/bin:/bin"}
    result = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True)
    assert result.returncode == 0, result.stderr


def test_missing_category_keeps_defaults_and_instances_are_listed() -> None:
    from Miro.SvcParameters import DevParameters, SockParameters

    doc = document(
        '<instance name="front" type="Miro::SockParameters">\n'
        '  <parameter name="Address" value="10.0.0.2:7000"/>\n'
        "</instance>\n"
        '<instance name="rear" type="Miro::SockParameters"/>\n'
        '<instance name="disk" type="Miro::DevParameters"/>\n'
    )
    dev = DevParameters()
    assert not doc.get_parameters("Dev", dev)
    assert dev.device == "/dev/null"
    socks = doc.get_instances("Miro::SockParameters")
    assert [i.name for i in socks] == ["front", "rear"]
    front = SockParameters()
    doc.get_instance(socks[0], front)
    assert front.address == InetAddr("10.0.0.2", 7000)


def test_document_structure_errors(tmp_path: Path) -> None:
    bad_root = write(tmp_path / "a.xml", "<configuration/>")
    with pytest.raises(ParamsError, match=r"a\.xml:1: error: the root element is <configuration>"):
        ConfigDocument(["-MCF", str(bad_root)])
    no_name = write(tmp_path / "b.xml", "<config>\n<section/>\n<other/>\n</config>")
    with pytest.raises(ParamsError) as e:
        ConfigDocument(["-MCF", str(no_name)])
    assert [str(d) for d in e.value.diagnostics] == [
        f"{no_name}:3: error: unexpected element <other> (expected <section name=...>)",
        f"{no_name}:2: error: a <section> needs a name=",
    ]
    with pytest.raises(ParamsError, match="cannot read"):
        ConfigDocument(["-MCF", str(tmp_path / "missing.xml")])
    twice = document('<parameter name="A"/>\n<parameter name="A"/>\n')
    with pytest.raises(ParamsError, match=r"run\.xml:4: error: parameter 'A' given twice"):
        twice.find("A")


def test_parameters_made_of_nothing_are_the_validated_defaults() -> None:
    """`Cls()` (`instance()`, default factories) skips pydantic's validator, which is built
    only when something is validated: the object is the same as validating no data gives,
    constructor blocks included (Miro's laser and GPS parameters have them)."""
    import Miro.CameraParameters
    import Miro.GpsParameters
    import Miro.LaserParameters
    import Miro.SvcParameters
    import Test.Parameters

    from miro_gen.params.runtime import Config

    modules = [Miro.SvcParameters, Miro.LaserParameters, Miro.GpsParameters]
    modules += [Miro.CameraParameters, Test.Parameters]
    classes = [
        c
        for m in modules
        for c in vars(m).values()
        if isinstance(c, type) and issubclass(c, Config) and c.__module__ == m.__name__
    ]
    assert len(classes) > 20
    for cls in classes:
        made = cls()
        validated = cls.model_validate({})
        assert type(made) is cls
        assert made.model_dump() == validated.model_dump(), cls
        assert made.model_fields_set == validated.model_fields_set == set(), cls
        assert str(made) == str(validated), cls


def test_a_service_reads_its_parameters_without_lxml_or_a_validator(tmp_path: Path) -> None:
    """Without a parameter document, a service's start-up read imports neither lxml nor
    asyncio and builds no pydantic validator; the first assignment builds one and checks."""
    import subprocess
    import sys

    code = (
        "import sys\n"
        "from Miro.SvcParameters import TtyParameters\n"
        "from miro_gen.params import read_parameters\n"
        "from miro_gen.params.runtime import instance_of\n"
        "params = instance_of(TtyParameters)\n"
        "assert not read_parameters(params, 'Tty')\n"
        "print(params)\n"
        "loaded = [m for m in ('lxml', 'asyncio') if m in sys.modules]\n"
        "assert not loaded, loaded\n"
        "built = [c.__name__ for c in type(params).__mro__\n"
        "         if getattr(c, '__pydantic_complete__', False)]\n"
        "assert not built, built\n"
        "params.device = '/dev/ttyS1'\n"
        "assert type(params).__pydantic_complete__\n"
        "try:\n"
        "    params.ttyParams = 'fast'\n"
        "except Exception as e:\n"
        "    print(type(e).__name__)\n"
    )
    env = {"PYTHONPATH": f"{REPO}:{REPO / 'generated'}", "PATH": "/usr/bin:/bin"}
    result = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, cwd=tmp_path
    )
    assert result.returncode == 0, result.stderr
    assert "Device: /dev/ttyS0\nTtyParams:\n  Baudrate: 9600" in result.stdout
    assert result.stdout.strip().endswith("ValidationError")


def test_the_run_time_half_loads_no_openssl_and_leaves_hashlib_whole() -> None:
    """pydantic imports `secrets` for a comparison only: the parameter classes load without
    hashlib's OpenSSL (3.4 MB of every service), and a later `import hashlib` or `hmac` still
    gets OpenSSL's; pydantic's Secret types still compare."""
    import subprocess
    import sys

    code = (
        "import sys, Test.Parameters\n"
        "loaded = [m for m in ('_hashlib', 'hashlib', 'hmac') if m in sys.modules]\n"
        "assert not loaded, loaded\n"
        "import hashlib, hmac, pydantic, secrets\n"
        "assert hashlib.sha256.__name__ == 'openssl_sha256', hashlib.sha256\n"
        "assert hasattr(hashlib, 'pbkdf2_hmac') and '_hashlib' in sys.modules\n"
        "assert hmac.new(b'k', b'm', 'sha256').hexdigest() == hashlib.sha256(\n"
        "    bytes(b ^ 0x5C for b in b'k'.ljust(64, b'\\0'))\n"
        "    + hashlib.sha256(bytes(b ^ 0x36 for b in b'k'.ljust(64, b'\\0')) + b'm').digest()\n"
        ").hexdigest()\n"
        "assert pydantic.SecretStr('a') == pydantic.SecretStr('a')\n"
        "assert pydantic.SecretStr('a') != pydantic.SecretStr('b')\n"
        "assert secrets.compare_digest(b'x', b'x') and len(secrets.token_hex(8)) == 16\n"
    )
    env = {"PYTHONPATH": f"{REPO}:{REPO / 'generated'}", "PATH": "/usr/bin:/bin"}
    result = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
