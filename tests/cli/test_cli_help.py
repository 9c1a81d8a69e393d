"""`--help` of every `miro` verb, and of the verbs' own sub-commands: the help on standard
output and status 0, never a usage error or a traceback. The list comes from `miro --help`, so
that a new verb is checked without being named here (tests/project/test_wheel.py runs the same check
against an installed wheel)."""

from __future__ import annotations

from help_checks import check_every_help, verbs
from miro_cli import REPO, run_module


def test_every_verb_prints_its_help() -> None:
    modules = {"miro": "miro_gen.cli.main", "miro-idl": "miro_gen.cli.idl"}
    modules["miro-params"] = "miro_gen.cli.params"

    def run(command: str) -> str:
        tool, *args = command.split()
        done = run_module(modules[tool], *args, timeout=60)
        text = done.stdout + done.stderr
        assert done.returncode == 0, f"$ {command}: status {done.returncode}\n{text}"
        assert "Traceback" not in text, f"$ {command}\n{text}"
        return done.stdout

    done = check_every_help(run)
    assert "miro bridge corba --help" in done and "miro log record --help" in done


def test_every_simulator_is_documented() -> None:
    """Each kind `miro sim --help` lists has its row in docs/DEVICES.md's table of simulators."""
    done = run_module("miro_gen.cli.main", "sim", "--help", timeout=60)
    kinds = verbs(done.stdout)
    assert {"nmea", "scip", "camera", "laser"} <= set(kinds), done.stdout
    table = (REPO / "docs" / "DEVICES.md").read_text().split("## The simulators", 1)[1]
    missing = [k for k in kinds if f"| `miro sim {k}" not in table]
    assert not missing, f"not in docs/DEVICES.md's simulators: {missing}"
