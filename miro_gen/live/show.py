"""Interfaces and values as the live tools print them: operation signatures in IDL's words,
from the AST JSON of an interface schema, and plain values as YAML (or JSON)."""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Any

from miro_gen.live.schemas import Compiled


@dataclass
class Signature:
    """An operation (or an attribute's accessor) as the shell calls it."""

    name: str  # as the caller types it (an attribute's: _get_x / _set_x)
    params: list[dict[str, str]]  # {"mode", "name", "type"}
    returns: str | None
    raises: list[str]
    oneway: bool = False

    @property
    def inputs(self) -> list[dict[str, str]]:
        return [p for p in self.params if p["mode"] in ("in", "inout")]

    @property
    def results(self) -> list[str]:
        """The names of what a call returns, in order (`return` for the result)."""
        names = ["return"] if self.returns else []
        return names + [p["name"] for p in self.params if p["mode"] in ("out", "inout")]

    def text(self) -> str:
        params = ", ".join(f"{p['mode']} {p['type']} {p['name']}" for p in self.params)
        text = f"{'oneway ' if self.oneway else ''}{self.returns or 'void'} {self.name}({params})"
        if self.raises:
            text += f" raises ({', '.join(self.raises)})"
        return text


def signatures(compiled: Compiled, repo_id: str) -> list[Signature]:
    """The operations of interface `repo_id` and of its bases (theirs first), then its
    attributes' accessors."""
    decl = compiled.declaration(repo_id)
    if decl is None:
        return []
    out: list[Signature] = []
    for base in decl.get("bases", []):
        for s in signatures(compiled, base):
            if all(s.name != o.name for o in out):
                out.append(s)
    for op in decl.get("operations", []):
        out.append(
            Signature(op["name"], op["params"], _void(op["returns"]), op["raises"], op["oneway"])
        )
    for a in decl.get("attributes", []):
        out.append(Signature(f"_get_{a['name']}", [], a["type"], a["get_raises"]))
        if not a["readonly"]:
            param = {"mode": "in", "name": "value", "type": a["type"]}
            out.append(Signature(f"_set_{a['name']}", [param], None, a["set_raises"]))
    return out


def _void(t: str | None) -> str | None:
    return None if t in (None, "void") else t


def dump(plain: Any, as_json: bool = False) -> str:
    """Plain data as YAML (a scalar as itself), or as JSON."""
    if as_json:
        return json.dumps(plain, ensure_ascii=False)
    if plain is None or isinstance(plain, bool):
        return json.dumps(plain)
    if isinstance(plain, int | float | str):
        return str(plain)
    import yaml

    text = yaml.safe_dump(plain, sort_keys=False, allow_unicode=True, default_flow_style=False)
    return str(text).rstrip()


def flow(plain: Any) -> str:
    """Plain data on one line (`{a: 1.0, b: 2.0}`)."""
    import yaml

    text = yaml.safe_dump(plain, default_flow_style=True, sort_keys=False, width=1 << 16)
    return str(text).split("\n...")[0].strip()
