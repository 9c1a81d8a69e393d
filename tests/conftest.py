"""The checkout's generated code comes first on the path, including what the wheel leaves out
(the manual's example parameters, package Test)."""

from __future__ import annotations

import sys
from pathlib import Path

GENERATED = str(Path(__file__).resolve().parents[1] / "generated")
if GENERATED not in sys.path:
    sys.path.insert(0, GENERATED)
