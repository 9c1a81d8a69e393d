"""`miro-params --xsd` (checked with lxml's XML Schema validator), `miro params show|validate`."""

from __future__ import annotations

from pathlib import Path

import pytest
from lxml import etree
from miro_cli import REPO, run_miro_params, run_module
from params_helpers import ALL_TYPES, PARAMS, write
from test_params_runtime import ALL_VALUES


def schema(*files: Path | str) -> etree.XMLSchema:
    out = run_miro_params("-I", str(REPO / "idl"), "--xsd", *map(str, files))
    assert out.returncode == 0, out.stderr
    return etree.XMLSchema(etree.fromstring(out.stdout.encode()))


def miro_params(*args: str) -> tuple[int, str, str]:
    out = run_module("miro_gen.cli.main", "params", *args)
    assert "Traceback" not in out.stderr, out.stderr
    return out.returncode, out.stdout, out.stderr


def test_xsd_accepts_the_manual_documents() -> None:
    xsd = schema(PARAMS / "Parameters.xml", PARAMS / "Body.xml")
    for doc in ("test.xml", "body.xml"):
        tree = etree.parse(str(PARAMS / "etc" / doc))
        assert xsd.validate(tree), (doc, xsd.error_log)


def test_xsd_accepts_every_type_and_rejects_misspelt_names(tmp_path: Path) -> None:
    xsd = schema(ALL_TYPES)
    good = etree.fromstring(f'<config><section name="s">{ALL_VALUES}</section></config>'.encode())
    assert xsd.validate(good), xsd.error_log
    for bad in (
        '<parameter name="All"><parameter name="Flagg" value="true"/></parameter>',
        '<parameter name="All"><parameter name="Line">'
        '<parameter name="Baudrat" value="1"/></parameter></parameter>',
        '<parameter name="All"><parameter name="Numbers"><parameter name="Bogus"/>'
        "</parameter></parameter>",
        '<parameter name="All"><other/></parameter>',
        "<parameter/>",
    ):
        doc = etree.fromstring(f'<config><section name="s">{bad}</section></config>'.encode())
        assert not xsd.validate(doc), bad


def test_xsd_types_values_where_a_level_has_one_type() -> None:
    xsd = schema(PARAMS / "Parameters.xml")
    ok = '<config><section name="t"><parameter name="Test"><parameter name="TestVector">'
    assert xsd.validate(
        etree.fromstring(f'{ok}<parameter value="7"/></parameter></parameter></section></config>')
    )
    assert not xsd.validate(
        etree.fromstring(f'{ok}<parameter value="x"/></parameter></parameter></section></config>')
    )


def test_xsd_reports_errors_like_the_compiler(tmp_path: Path) -> None:
    src = write(tmp_path / "X.xml", "<config>\n<config_item name='A'>\n<config_parameter/>")
    out = run_miro_params("--xsd", str(src))
    assert out.returncode == 1 and "X.xml:3" in out.stderr and not out.stdout


def test_show_prints_defaults_merged_with_the_document() -> None:
    rc, out, err = miro_params("show", "-p", str(PARAMS / "Parameters.xml"), "params/etc/test.xml")
    assert rc == 0, err
    assert out == "[test]\nTest (Test::MyParameters):\n  TestVector: [2 4 2 5]\n  TestInteger: 1\n"


def test_show_one_section_with_default_params_folder(tmp_path: Path) -> None:
    doc = write(
        tmp_path / "robot.xml",
        """\
        <config>
          <section name="Miro">
            <parameter name="Tty"><parameter name="Device" value="/dev/ttyUSB1"/></parameter>
            <instance name="front" type="Miro::SockParameters">
              <parameter name="Address" value="10.0.0.9:4000"/>
            </instance>
          </section>
          <section name="test"><parameter name="Test"/></section>
        </config>
        """,
    )
    rc, out, err = miro_params("show", "--section", "Miro", str(doc))
    assert rc == 0, err
    assert "[test]" not in out
    assert "Tty (Miro::TtyParameters):\n  Device: /dev/ttyUSB1\n  TtyParams:\n" in out
    assert "instance 'front': Miro::SockParameters (Miro::SockParameters):\n" in out
    assert "  Address: 10.0.0.9:4000\n  Timeout: 1 s\n" in out


def test_validate_reports_every_problem(tmp_path: Path) -> None:
    bad = write(
        tmp_path / "bad.xml",
        """\
        <config>
          <section name="test">
            <parameter name="Test">
              <parameter name="TestVector" value="1 x"/>
              <parameter name="TestInt" value="2"/>
            </parameter>
            <parameter name="Nothing"/>
          </section>
        </config>
        """,
    )
    rc, out, err = miro_params("validate", str(bad), "params/etc/test.xml", "params/etc/body.xml")
    assert rc == 1
    lines = err.strip().splitlines()
    assert lines[0] == f"{bad}:4: error: Test.TestVector[1]: expected an integer (int), got 'x'"
    assert lines[1].startswith(f"{bad}:5: error: Test: unknown parameter 'TestInt'")
    assert lines[2].startswith(f"{bad}:7: error: no parameter class for parameter 'Nothing'")
    assert len(lines) == 3
    rc, out, err = miro_params("validate", "params/etc/test.xml", "params/etc/body.xml")
    assert rc == 0 and "2 document(s) valid" in out


@pytest.mark.parametrize("text", ["<config><section", '<!DOCTYPE c [<!ENTITY a "b">]><config/>'])
def test_validate_refuses_broken_and_hostile_documents(tmp_path: Path, text: str) -> None:
    doc = write(tmp_path / "d.xml", text)
    rc, _, err = miro_params("validate", str(doc))
    assert rc == 1 and f"{doc}:1" in err


def test_loading_10000_parameters_takes_under_half_a_second() -> None:
    """bench/bench_params.py --check: the issue's target, on this machine."""
    out = run_module("bench.bench_params", "--check", timeout=300)
    assert out.returncode == 0, out.stdout + out.stderr
    assert out.stdout.count(" ok") == 3, out.stdout


def test_miro_params_without_a_tool_is_the_compiler() -> None:
    rc, _, err = miro_params("-I", "idl", "--check", *sorted(map(str, PARAMS.glob("*.xml"))))
    assert rc == 0 and err == "", err  # generated/ is fresh: --check says nothing
