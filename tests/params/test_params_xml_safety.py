"""Hostile and broken XML: no entity expansion, no external entities, no DTD or network loads;
DOCTYPEs declaring entities refused; positions in every error; Miro's named entities kept."""

from __future__ import annotations

from pathlib import Path

import pytest
from miro_cli import run_miro_params
from params_helpers import write

from miro_gen.params.runtime import ParamsError
from miro_gen.params.runtime.document import ConfigDocument
from miro_gen.params.runtime.xmlsafe import ENTITIES, XmlError, parse_xml

BILLION_LAUGHS = """<?xml version="1.0"?>
<!DOCTYPE config [
  <!ENTITY lol "lol">
  <!ENTITY lol2 "&lol;&lol;&lol;&lol;&lol;&lol;&lol;&lol;&lol;&lol;">
  <!ENTITY lol3 "&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;">
  <!ENTITY lol4 "&lol3;&lol3;&lol3;&lol3;&lol3;&lol3;&lol3;&lol3;&lol3;&lol3;">
]>
<config><section name="s"><parameter name="Test">
  <parameter name="Name" value="&lol4;"/>
</parameter></section></config>
"""


def xxe(target: Path) -> str:
    return f"""<?xml version="1.0"?>
<!DOCTYPE config [ <!ENTITY secret SYSTEM "file://{target}"> ]>
<config><section name="s"><parameter name="Test">
  <parameter name="Name" value="&secret;"/>
</parameter></section></config>
"""


def test_billion_laughs_is_refused(tmp_path: Path) -> None:
    doc = write(tmp_path / "laughs.xml", BILLION_LAUGHS)
    with pytest.raises(ParamsError) as e:
        ConfigDocument(["-MCF", str(doc)])
    assert str(e.value).startswith(f"{doc}:2: error: the DOCTYPE declares entities")


def test_external_entities_are_refused_and_never_read(tmp_path: Path) -> None:
    secret = write(tmp_path / "secret.txt", "TOP-SECRET")
    doc = write(tmp_path / "xxe.xml", xxe(secret))
    with pytest.raises(ParamsError) as e:
        ConfigDocument(["-MCF", str(doc)])
    assert "declares entities" in str(e.value) and "TOP-SECRET" not in str(e.value)
    # the same in a compile-time file, through the command line
    src = write(tmp_path / "P.xml", xxe(secret).replace("config>", "config>", 1))
    out = run_miro_params("-o", str(tmp_path / "out"), str(src))
    assert out.returncode == 1 and "declares entities" in out.stderr
    assert "TOP-SECRET" not in out.stderr + out.stdout and not (tmp_path / "out").exists()


def test_an_external_dtd_is_not_loaded(tmp_path: Path) -> None:
    # Miro's files start with <!DOCTYPE ... SYSTEM "x.dtd">: accepted, the DTD never fetched
    tree = parse_xml(
        b'<!DOCTYPE config SYSTEM "http://192.0.2.1/never.dtd">\n<config/>', "remote.xml"
    )
    assert tree.getroot().tag == "config"


def test_unknown_entities_are_errors_with_line_and_column() -> None:
    with pytest.raises(XmlError) as e:
        parse_xml('<config>\n  <a m="x &bogus;"/>\n</config>', "u.xml")
    assert str(e.value) == "u.xml:2:11: error: unknown entity '&bogus;'"


def test_miro_named_entities_come_from_the_builtin_table() -> None:
    tree = parse_xml(
        '<!DOCTYPE config SYSTEM "x.dtd">\n'
        '<config><p measure="&deg;" unit="&micro;m" x="&amp;deg;" area="m&sup2;"/></config>',
        "e.xml",
    )
    p = tree.getroot()[0]
    assert (p.get("measure"), p.get("unit"), p.get("x"), p.get("area")) == (
        "°",
        "µm",
        "&deg;",
        "m²",
    )
    assert {"deg", "micro", "plusmn", "Omega"} <= ENTITIES.keys()


def test_measure_entities_reach_the_generated_code(tmp_path: Path) -> None:
    src = write(
        tmp_path / "M.xml",
        '<!DOCTYPE config SYSTEM "PolicyEditor_behaviour.dtd">\n'
        '<config><config_global name="namespace" value="M"/>\n'
        '<config_item name="A" parent="Miro::Config">\n'
        '<config_parameter name="Turn" type="angle" measure="&deg;/s"/>\n'
        "</config_item></config>\n",
    )
    out = run_miro_params("-o", str(tmp_path / "out"), str(src))
    assert out.returncode == 0, out.stderr
    module = (tmp_path / "out" / "M" / "M.py").read_text(encoding="utf-8")
    assert '_rt.XmlField("Turn", "turn", _rt.ANGLE, "°/s")' in module


@pytest.mark.parametrize(
    ("text", "where"),
    [
        ("<config>\n<section name='s'>\n</config>", "x.xml:3:"),
        ("<config>\n<section name='s' name='t'/></config>", "x.xml:2:"),
        ("", "x.xml:"),
        ("<config>\n\n\x01</config>", "x.xml:3:"),
    ],
)
def test_malformed_documents_report_positions(text: str, where: str) -> None:
    with pytest.raises(ParamsError) as e:
        ConfigDocument(text=text, path="x.xml")
    assert str(e.value).startswith(where), str(e.value)
    assert "error: XML: " in str(e.value)


def test_non_utf8_is_refused() -> None:
    with pytest.raises(ParamsError, match=r"l\.xml:2: error: the file is not UTF-8 text"):
        ConfigDocument(text=b"<config>\n<section name='\xe9'/></config>", path="l.xml")
