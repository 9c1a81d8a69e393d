"""Shell completion for `miro`: its verbs, sub-verbs and options (from the table of
cli/verbs.py), and what is running: object names and their operations (`miro call`), services
and their parameters (`miro param`), event topics and payload types (`miro pub`, `miro echo`,
`miro hz`), by the completers the table names.

    eval "$(miro completion bash)"      # in ~/.bashrc (zsh: the same, after bashcompinit)

The shell calls `miro _complete INDEX WORD...` at each Tab; it prints the candidates, one a
line. What is running is asked of the naming service and the services, each given a second at
most, so that a robot that is not up costs a Tab a second, not a hang.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable, Sequence
from typing import Any, cast

from miro_gen.cli.verbs import VERBS, Verb, find, target

TIMEOUT = 1.0  # seconds a Tab may wait for the naming service or a service

BASH = r"""# miro shell completion (bash; zsh: autoload -U bashcompinit && bashcompinit first)
_miro_complete() {
    local IFS=$'\n'
    COMPREPLY=($(compgen -W "$(miro _complete "$COMP_CWORD" "${COMP_WORDS[@]}" 2>/dev/null)" \
        -- "${COMP_WORDS[COMP_CWORD]}"))
    if [ ${#COMPREPLY[@]} -eq 0 ]; then
        COMPREPLY=($(compgen -f -- "${COMP_WORDS[COMP_CWORD]}"))
    fi
}
complete -o filenames -F _miro_complete miro
"""


def completion_main(argv: Sequence[str]) -> int:
    p = argparse.ArgumentParser(
        prog="miro completion",
        description="Print the shell code that completes miro's commands, names, operations "
        'and types: eval "$(miro completion bash)" in ~/.bashrc (zsh: after '
        "autoload -U bashcompinit && bashcompinit).",
    )
    p.add_argument("shell", choices=("bash", "zsh"), nargs="?", default="bash")
    p.parse_args(argv)
    sys.stdout.write(BASH)
    return 0


def complete_main(argv: Sequence[str]) -> int:
    """`miro _complete INDEX WORD...`: the candidates for WORD[INDEX]."""
    try:
        index = int(argv[0])
        words = list(argv[1:])
    except (IndexError, ValueError):
        return 0
    words += [""] * (index + 1 - len(words))
    try:
        for candidate in candidates(words[: index + 1]):
            print(candidate)
    except Exception:  # a Tab must never print a traceback into the command line
        return 0
    return 0


def candidates(words: list[str]) -> list[str]:
    """What may come at the last of `words` (words[0] is `miro`): the verbs, sub-verbs and
    options of cli/verbs.py's table, and what its completers say is running."""
    current = words[-1]
    if len(words) == 2:
        return _filter([v.name for v in VERBS if not v.hidden], current)
    verb = find(words[1])
    if verb is None:
        return []
    if current.startswith("-"):
        return [o for o in _options(verb) if o.startswith(current)]
    previous = words[-2]
    if previous in ("--payload",):
        return _filter(_payload_types(words), current)
    if previous in ("--naming", "--host", "-MNC", "-MLL", "--channel", "-o", "--output"):
        return []
    args = _positionals(words[2:-1])
    if verb.subs and not args:
        return _filter([s.name for s in verb.subs], current)
    sub = verb.sub(args[0]) if verb.subs else None
    if sub is not None and sub.run:
        return []  # a sub-verb's own arguments: files (the shell's default)
    if not verb.complete:
        return []
    complete = cast("Callable[[list[str], list[str]], list[str]]", target(verb.complete))
    return _filter(complete(words, args), current)


def _filter(items: list[str], prefix: str) -> list[str]:
    return sorted({i for i in items if i.startswith(prefix)})


def _positionals(words: list[str]) -> list[str]:
    """The positional arguments among `words` (options and their values left out)."""
    out, skip = [], False
    for w in words:
        if skip:
            skip = False
        elif w in (
            "--naming",
            "--host",
            "-MNC",
            "-MLL",
            "-MCF",
            "--channel",
            "--payload",
            "--timeout",
            "-r",
            "--rate",
            "-n",
            "--count",
            "-o",
            "--output",
        ):
            skip = True
        elif not w.startswith("-"):
            out.append(w)
    return out


def _options(verb: Verb) -> list[str]:
    """The options of `verb`, from its parser, and the common options if it takes them."""
    common = ["--naming", "-MNC", "-MLL", "--host"] if verb.common else []
    if not verb.parser:
        return ["--help", *common]
    parser = cast("Callable[[], argparse.ArgumentParser]", target(verb.parser))()
    return [o for a in parser._actions for o in a.option_strings] + common


# ---- what is running ---------------------------------------------------------------------------


def _robot(words: list[str]) -> Any:
    from miro_gen.live.remote import Robot
    from miro_gen.service.options import parse_common_options

    opts, _ = parse_common_options(words[2:])
    argv = ["miro", "--naming", opts.naming, "-MNC", opts.naming_context]
    robot = Robot(argv, timeout=TIMEOUT)
    naming = robot.naming  # miro's own (Robot refuses a CORBA naming service)
    naming.registry = naming.registry_stub(robot.client.invoker, TIMEOUT)
    return robot


def _with_robot(words: list[str], fn: Callable[[Any], list[str]]) -> list[str]:
    robot = _robot(words)
    try:
        return fn(robot)
    finally:
        robot.close()


def _object_names(words: list[str]) -> list[str]:
    from miro_gen.service.introspection import SERVICES
    from miro_gen.transport.events import CHANNEL_REPO_ID

    return _with_robot(
        words,
        lambda r: [
            e.name
            for e in r.entries()
            if e.repo_id != CHANNEL_REPO_ID and f"/{SERVICES}/" not in e.name
        ],
    )


def call_args(words: list[str], args: list[str]) -> list[str]:
    """`miro call NAME OPERATION`: the objects bound, then the object's operations."""
    if not args:
        return _object_names(words)
    if len(args) > 1:
        return []

    def operations(robot: Any) -> list[str]:
        from miro_gen.live.show import signatures

        entry = robot.resolve(args[0])
        return [s.name for s in signatures(robot.interface(entry), entry.repo_id)]

    return _with_robot(words, operations)


def _service_names(words: list[str]) -> list[str]:
    return _with_robot(
        words, lambda r: [n for s in r.services() for n in (s.name, s.name.split("/")[-1])]
    )


def param_args(words: list[str], args: list[str]) -> list[str]:
    """`miro param get|set|dump SERVICE NAME` (the sub-verb given): services, then the
    service's parameters."""
    if len(args) == 1:
        return _service_names(words)
    if len(args) > 2 or args[0] == "dump":
        return []

    def names(robot: Any) -> list[str]:
        from lxml import etree

        service = robot.service(args[1])
        stub = robot.service_at(service.entry.endpoint, timeout=TIMEOUT)
        out = []
        for ps in service.description.parameters if service.description else []:
            elem = etree.fromstring(stub.get_parameters(ps.section, ps.category).encode())
            out.append(ps.category)
            out += _paths(elem, ps.category)
        return out

    return _with_robot(words, names)


def _paths(elem: Any, prefix: str) -> list[str]:
    out = []
    for child in elem:
        name = child.get("name")
        if name:
            out.append(f"{prefix}.{name}")
            out += _paths(child, f"{prefix}.{name}")
    return out


def _offers(words: list[str]) -> list[Any]:
    return _with_robot(
        words, lambda r: [o for s in r.services() if s.description for o in s.description.offers]
    )


def pub_args(words: list[str], args: list[str]) -> list[str]:
    """`miro pub TOPIC`: the topics published now."""
    return _topics(words) if not args else []


def topic_args(words: list[str], args: list[str]) -> list[str]:
    """`miro echo|hz TOPIC...`: the topics published now."""
    return _topics(words)


def list_args(words: list[str], args: list[str]) -> list[str]:
    """`miro list PATTERN`: the services running."""
    return _service_names(words) if not args else []


def _topics(words: list[str]) -> list[str]:
    return [t for o in _offers(words) for t in (f"{o.domain}/{o.type_name}", o.type_name)]


def _payload_types(words: list[str]) -> list[str]:
    return [o.payload for o in _offers(words)]
