"""`miro params show` and `miro params validate`: run-time documents against parameter classes.

The classes come from compile-time files (`-p FILE`, default: every compile-time file in
`./params/`), compiled in memory. A `<parameter name="CATEGORY">` of a section is matched to the
class whose item is called so (`My`, `MyParameters`, `Test::MyParameters`), or else to the only
class of the section (config_group) whose namespace is CATEGORY (the manual's `"Test"`); an
`<instance type="...">` to the class of that name.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from miro_gen.cli.common import internal_error
from miro_gen.cli.verbs import verb
from miro_gen.diagnostics import CompileError, Diagnostic, Diagnostics, SourcePos

if TYPE_CHECKING:
    from miro_gen.params.compiler.dynamic import ParamClass

DESCRIPTION = """\
Check or print run-time parameter documents (<config><section><parameter name=...>) against the
parameter classes of compile-time files. Problems are reported as `path:line: error: message`;
validate exits 1 when there is any.
"""


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="miro params", description=DESCRIPTION)
    sub = p.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name, help_text in ((v.name, v.help) for v in verb("params").subs):
        s = sub.add_parser(name, help=help_text, description=help_text)
        s.add_argument(
            "documents",
            nargs="+" if name == "validate" else 1,
            metavar="FILE",
            help="run-time document(s)",
        )
        s.add_argument(
            "-p",
            dest="params",
            action="append",
            default=[],
            metavar="PARAMS.xml",
            help="a compile-time file declaring the classes (default: params/*.xml); repeatable",
        )
        s.add_argument(
            "-I",
            dest="include_dirs",
            action="append",
            default=[],
            metavar="DIR",
            help="search path of included compile-time files; repeatable",
        )
        if name == "show":
            s.add_argument("--section", metavar="S", help="only this section")
            s.add_argument(
                "--all",
                action="store_true",
                help='also list abstract classes (final="false") among the known ones',
            )
    return p


def show_main(argv: Sequence[str]) -> int:
    """`miro params show`."""
    return main(["show", *argv])


def validate_main(argv: Sequence[str]) -> int:
    """`miro params validate`."""
    return main(["validate", *argv])


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    diag = Diagnostics()
    try:
        return _run(args, diag)
    except CompileError:
        diag.print()
        return 1
    except Exception as e:  # a bug, not a problem of the input
        return internal_error("miro params", e)


def _compile_time_files(folder: Path) -> list[str]:
    """The compile-time files of a folder (run-time documents there are skipped)."""
    out = []
    for f in sorted(folder.glob("*.xml")):
        try:
            head = f.read_text(encoding="utf-8", errors="replace")
        except OSError:
            continue
        if "<config_item" in head or "<config_global" in head:
            out.append(str(f))
    return out


def _run(args: argparse.Namespace, diag: Diagnostics) -> int:
    from miro_gen.params.compiler import dynamic

    params = args.params or _compile_time_files(Path("params"))
    if not params:
        print("miro params: no compile-time files: give them with -p PARAMS.xml", file=sys.stderr)
        return 1
    include_dirs = args.include_dirs or [str(Path(p).parent) for p in params]
    classes = dynamic.load(params, include_dirs, diag)
    problems: list[Diagnostic] = []
    for doc_path in args.documents:
        problems += _check(doc_path, classes, args, show=args.command == "show")
    for d in problems:
        print(d, file=sys.stderr)
    if args.command == "validate" and not problems:
        print(f"miro params: {len(args.documents)} document(s) valid")
    return 1 if problems else 0


def _check(
    doc_path: str, typed: list[ParamClass], args: argparse.Namespace, show: bool
) -> list[Diagnostic]:
    """The problems of one document (and its values printed, for show)."""
    from miro_gen.params.runtime import ParamsError
    from miro_gen.params.runtime.document import ConfigDocument

    try:
        doc = ConfigDocument(path=doc_path)
    except ParamsError as e:
        return list(e.diagnostics)
    problems: list[Diagnostic] = []
    for section in doc.root:
        name = section.get("name", "")
        if section.tag != "section" or (show and args.section and name != args.section):
            continue
        if show:
            print(f"[{name}]")
        for elem in section:
            if not isinstance(elem.tag, str):
                continue
            pos = SourcePos(doc_path, elem.sourceline or 0, 0)
            if elem.tag == "parameter":
                label = elem.get("name", "")
                matches = [c for c in typed if label in c.names] or [
                    c
                    for c in typed
                    if c.item.file.namespace == label
                    and c.item.group in (name, None)
                    and not c.abstract
                ]
            elif elem.tag == "instance":
                label = elem.get("type", "")
                matches = [c for c in typed if label in c.names]
            else:
                problems.append(Diagnostic("error", pos, f"unexpected element <{elem.tag!s}>"))
                continue
            if len(matches) != 1:
                listed = [c for c in typed if not c.abstract or getattr(args, "all", False)]
                known = ", ".join(sorted({c.item.class_name for c in listed})) or "none"
                why = "no" if not matches else "more than one"
                problems.append(
                    Diagnostic(
                        "error",
                        pos,
                        f"{why} parameter class for {elem.tag} {label!r} in section {name!r} "
                        f"(classes: {known})",
                    )
                )
                continue
            params = matches[0].cls()
            try:
                params.from_xml(elem, doc_path)
            except ParamsError as e:
                problems += e.diagnostics
                continue
            if show:
                title = f"{label} ({matches[0].item.scoped_name})"
                if elem.tag == "instance":
                    title = f"instance {elem.get('name', '')!r}: {title}"
                print(f"{title}:")
                for line in str(params).splitlines():
                    print(f"  {line}")
    return problems


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
