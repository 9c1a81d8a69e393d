"""The names the documentation imports from `miro_gen` are there: every `from miro_gen import`
in README.md and docs/*.md (the consumer's `depth=KEEP_ALL` beside `StructuredPushConsumer`)."""

from __future__ import annotations

import re

from miro_cli import REPO

import miro_gen

IMPORT = re.compile(r"^from miro_gen import (\([^)]*\)|[^\n]*)", re.M)


def test_every_name_the_docs_import_from_miro_gen_is_exported() -> None:
    names: set[str] = set()
    for doc in [REPO / "README.md", *sorted((REPO / "docs").glob("*.md"))]:
        for m in IMPORT.finditer(doc.read_text()):
            names |= {n.strip() for n in m.group(1).strip("()").split(",") if n.strip()}
    assert {"Server", "StructuredPushConsumer", "KEEP_ALL"} <= names
    for name in sorted(names):
        assert name in miro_gen.__all__, name
        assert getattr(miro_gen, name) is not None
    assert miro_gen.KEEP_ALL == 0
