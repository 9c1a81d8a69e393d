"""generated/ is what miro-idl makes of idl/ now (CI fails on a stale checkout)."""

from __future__ import annotations

import glob

from miro_cli import REPO, run_miro_idl


def test_generated_is_fresh() -> None:
    idl = sorted(glob.glob(str(REPO / "idl" / "*.idl")))
    out = run_miro_idl("-I", "idl", "--check", *idl)
    assert out.returncode == 0, (
        "generated/ is stale; run `miro-idl -I idl idl/*.idl` and commit the result:\n" + out.stderr
    )
