"""generated/ is what miro-idl makes of idl/ and miro-params of params/ now (CI fails on a stale
checkout)."""

from __future__ import annotations

import glob

from miro_cli import REPO, run_miro_idl, run_miro_params


def test_generated_is_fresh() -> None:
    idl = sorted(glob.glob(str(REPO / "idl" / "*.idl")))
    out = run_miro_idl("-I", "idl", "--check", *idl)
    assert out.returncode == 0, (
        "generated/ is stale; run `miro-idl -I idl idl/*.idl` and commit the result:\n" + out.stderr
    )


def test_generated_params_are_fresh() -> None:
    params = sorted(glob.glob(str(REPO / "params" / "*.xml")))
    params += sorted(glob.glob(str(REPO / "services" / "*" / "*Parameters.xml")))
    out = run_miro_params("-I", "idl", "--check", *params)
    assert out.returncode == 0, (
        "generated/ is stale; run `miro-params -I idl params/*.xml services/*/*Parameters.xml`"
        " and commit the result:\n" + out.stderr
    )
