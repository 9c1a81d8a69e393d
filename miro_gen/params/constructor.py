"""Placeholder: constructor blocks are compiled in the next step."""

from __future__ import annotations

from typing import Any

from miro_gen.diagnostics import Diagnostics
from miro_gen.params.model import ItemDecl


def compile_constructor(item: ItemDecl, builder: Any, diag: Diagnostics) -> list[str]:
    assert item.constructor is not None
    diag.error(item.constructor.pos, "<constructor> blocks are not supported yet")
    return []
