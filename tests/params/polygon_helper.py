"""A user-written helper (docs/PARAMS.md, "Helpers"): a polygon written `value="x,y x,y ..."`,
for a C++ type that generated parsing cannot describe. miro-params' generated code calls its
codec's read, write, show and default."""

from __future__ import annotations

from miro_gen.params.runtime import Scalar

Value = list[tuple[float, float]]


def _parse(text: str) -> Value:
    points = []
    for pair in text.split():
        x, sep, y = pair.partition(",")
        if not sep:
            raise ValueError(f"expected x,y pairs, got {pair!r}")
        points.append((float(x), float(y)))
    return points


def _format(value: Value) -> str:
    return " ".join(f"{x:g},{y:g}" for x, y in value)


codec = Scalar("Polygon", _parse, _format, default=[])
