"""`miro`'s verbs come from one table (miro_gen/cli/verbs.py): every verb and sub-verb has its
one-line help, is listed by `miro --help` (or its verb's help), is completed at a Tab, and runs
the function the table names; and neither `miro --help` nor a Tab imports a verb's module.
Before, the parser, the dispatcher and the completion kept three lists, and `bridge`, `doctor`
and `keys` had no completion."""

from __future__ import annotations

import json
import subprocess
import sys
from collections.abc import Iterator

import pytest
from loopback import service_env

from miro_gen.cli import main, verbs
from miro_gen.cli.complete import candidates

SHOWN = [v for v in verbs.VERBS if not v.hidden]


def every_verb() -> Iterator[tuple[str, verbs.Verb]]:
    for v in verbs.VERBS:
        yield v.name, v
        for s in v.subs:
            yield f"{v.name} {s.name}", s


@pytest.mark.parametrize(("path", "verb"), list(every_verb()), ids=lambda x: str(x))
def test_every_verb_has_one_line_of_help_and_what_it_names_exists(
    path: str, verb: verbs.Verb
) -> None:
    assert verb.help.strip() and "\n" not in verb.help, path
    assert verbs.verb(path) is verb
    for spec in (verb.run, verb.parser, verb.complete):
        if spec:
            assert callable(verbs.target(spec)), f"{path}: {spec}"
    parent = verbs.find(path.split()[0])
    assert parent is not None and (verb.run or parent.run or verb.subs), f"{path} runs nothing"


def test_every_verb_is_completed_and_listed() -> None:
    assert candidates(["miro", ""]) == sorted(v.name for v in SHOWN)
    assert "_complete" not in candidates(["miro", "_"])
    assert {"bridge", "doctor", "keys"} <= set(candidates(["miro", ""]))  # the ones missing
    top = main.build_parser().format_help()
    for v in SHOWN:
        assert f"    {v.name} " in top or f"    {v.name}\n" in top, v.name
        assert v.help.split()[0] in top
        if v.subs:
            assert candidates(["miro", v.name, ""]) == sorted(s.name for s in v.subs), v.name
            assert (
                candidates(["miro", v.name, v.subs[0].name[:1]])[0]
                == sorted(s.name for s in v.subs if s.name.startswith(v.subs[0].name[:1]))[0]
            )
    for v in SHOWN:  # options: from the verb's parser, or at least --help
        options = candidates(["miro", v.name, "--"])
        assert "--help" in options, v.name
        assert ("--naming" in options) == v.common, v.name


def test_the_ros2_forms_are_completed_and_have_their_own_help() -> None:
    """`--ros2` is among the options completed for the verbs whose parser takes it, and
    `miro call --ros2 --help` is the ROS 2 form's help (as `ros2 service call`)."""
    for verb in ("call", "pub", "list", "echo", "hz"):
        assert "--ros2" in candidates(["miro", verb, "--r"]), verb
    assert "--count" in candidates(["miro", "echo", "--c"])
    assert "--window" in candidates(["miro", "hz", "--w"])
    from miro_gen.cli.call_ros2 import parser

    text = parser().format_help()
    assert text.startswith("usage: miro call --ros2 ") and "SERVICE [TYPE] [REQUEST]" in text


def test_every_verb_and_sub_verb_runs_its_help() -> None:
    """`miro VERB --help` and `miro VERB SUB --help` for the whole table, in one process:
    each prints its help and exits 0 (a sub-verb its own, whoever parses it)."""
    driver = (
        "import contextlib, io, json, sys\n"
        "from miro_gen.cli import main, verbs\n"
        "out = {}\n"
        "for v in verbs.VERBS:\n"
        "    if v.hidden: continue\n"
        "    for words in [[v.name], *[[v.name, s.name] for s in v.subs]]:\n"
        "        text = io.StringIO()\n"
        "        with contextlib.redirect_stdout(text), contextlib.redirect_stderr(text):\n"
        "            try: code = main.dispatch([*words, '--help'])\n"
        "            except SystemExit as e: code = e.code\n"
        "        out[' '.join(words)] = [code, text.getvalue()]\n"
        "json.dump(out, sys.stdout)\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", driver],
        capture_output=True,
        text=True,
        env=service_env(),
        timeout=120,
    )
    assert done.returncode == 0, done.stderr
    helps = json.loads(done.stdout)
    assert len(helps) == len(SHOWN) + sum(len(v.subs) for v in SHOWN)
    for words, (code, text) in helps.items():
        assert code in (0, None) and text.startswith("usage: "), f"miro {words} --help: {text}"
        assert "Traceback" not in text
    for v in SHOWN:  # a verb made of sub-verbs lists them, each with its help
        if not v.run:
            for s in v.subs:
                assert s.name in helps[v.name][1] and s.help.split()[0] in helps[v.name][1]


def test_help_and_a_tab_import_no_verbs_module() -> None:
    code = (
        "import contextlib, io, json, sys\n"
        "from miro_gen.cli import main\n"
        "with contextlib.redirect_stdout(io.StringIO()):\n"
        "    main.main(['_complete', '1', 'miro', 'p'])\n"
        "    main.main(['_complete', '2', 'miro', 'log', ''])\n"
        "    try: main.main(['--help'])\n"
        "    except SystemExit: pass\n"
        "print(json.dumps([m for m in sys.modules if m.startswith('miro_gen.')]))\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, env=service_env(), timeout=60
    )
    assert done.returncode == 0, done.stderr
    loaded = set(json.loads(done.stdout))
    assert loaded <= {
        "miro_gen.cli",
        "miro_gen.cli.main",
        "miro_gen.cli.verbs",
        "miro_gen.cli.common",
        "miro_gen.cli.complete",
        "miro_gen.diagnostics",
        "miro_gen.exceptions",
    }, loaded


def test_an_unknown_verb_or_sub_verb_is_a_usage_error() -> None:
    for words, listed in ((["nope"], "'bridge'"), (["log", "nope"], "'record'")):
        done = subprocess.run(
            [sys.executable, "-m", "miro_gen.cli.main", *words],
            capture_output=True,
            text=True,
            env=service_env(),
            timeout=60,
        )
        assert done.returncode == 2
        assert "invalid choice: 'nope'" in done.stderr and listed in done.stderr
