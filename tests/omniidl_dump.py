#!/usr/bin/python3
"""Compile IDL files with omniidl's front end and print them in miro-idl's `--ast-json` shape.

Run with the system Python whose version matches omniidl's `_omniidl` extension module
(Debian: `/usr/bin/python3`), not with the project's Python:

    /usr/bin/python3 tests/omniidl_dump.py [-I DIR]... FILE...

Each FILE is preprocessed with `omnicpp` (as `omniidl` does) and compiled with
`_omniidl.compile`, in a forked child process (omniidl keeps global state between compilations
and aborts on some inputs). The output is one JSON object mapping each FILE to its result:

    {"FILE": {"ok": true, "files": [FILE], "declarations": [...], "errors": [], "warnings": [...]},
     "FILE2": {"ok": false, "declarations": null, "errors": [{"file", "line", "message"}], ...}}

`declarations` follows DESIGN.md's "AST JSON" contract (kind, name, repo_id, file, line and the
per-kind fields) so that tests/idl/test_differential_omniidl.py can compare it with miro-idl's
output.
`file` is the basename of the file the declaration comes from; `doc` is always null and
`annotations` always empty (omniidl has neither doc comments in miro's sense nor annotations).

With `--probe` it only checks that omniidl's front end can be imported (exit status 0) and
prints its version.

This script is deliberately self-contained (standard library + omniidl only) and written for the
Python that omniidl is built for; it never imports miro_gen.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import tempfile
import traceback

OMNIIDL_DIR = "/usr/lib/omniidl"
if os.path.isdir(OMNIIDL_DIR):
    sys.path.insert(0, OMNIIDL_DIR)

import _omniidl  # noqa: E402  (needs the sys.path entry above)
from omniidl import idlast, idltype  # noqa: E402

# ---- types --------------------------------------------------------------------------------

_BASE_NAMES = {
    idltype.tk_void: "void",
    idltype.tk_short: "short",
    idltype.tk_long: "long",
    idltype.tk_ushort: "unsigned short",
    idltype.tk_ulong: "unsigned long",
    idltype.tk_float: "float",
    idltype.tk_double: "double",
    idltype.tk_boolean: "boolean",
    idltype.tk_char: "char",
    idltype.tk_octet: "octet",
    idltype.tk_any: "any",
    idltype.tk_TypeCode: "TypeCode",
    idltype.tk_Principal: "Principal",
    idltype.tk_longlong: "long long",
    idltype.tk_ulonglong: "unsigned long long",
    idltype.tk_longdouble: "long double",
    idltype.tk_wchar: "wchar",
}

# omniidl's built-in declarations and the IDL keyword miro-idl spells them with.
_BUILTIN_NAMES = {
    ("CORBA", "Object"): "Object",
    ("CORBA", "ValueBase"): "ValueBase",
}


def scoped(name_parts):
    return "::".join(name_parts)


def type_string(t):
    """An omniidl type in miro-idl's spelling (DESIGN.md, "AST JSON")."""
    if t is None:
        return "void"
    if isinstance(t, idltype.Base):
        return _BASE_NAMES[t.kind()]
    if isinstance(t, idltype.String):
        return f"string<{t.bound()}>" if t.bound() else "string"
    if isinstance(t, idltype.WString):
        return f"wstring<{t.bound()}>" if t.bound() else "wstring"
    if isinstance(t, idltype.Sequence):
        elem = type_string(t.seqType())
        return f"sequence<{elem}, {t.bound()}>" if t.bound() else f"sequence<{elem}>"
    if isinstance(t, idltype.Fixed):
        if t.digits() == 0:  # the bare `fixed` of a constant declaration
            return "fixed"
        return f"fixed<{t.digits()}, {t.scale()}>"
    if isinstance(t, idltype.Declared):
        sn = tuple(t.scopedName())
        return _BUILTIN_NAMES.get(sn, scoped(sn))
    raise TypeError(f"unexpected omniidl type {t!r}")


def value_json(kind, value):
    """A constant or union label value as miro-idl writes it."""
    if kind == idltype.tk_alias:  # pragma: no cover - omniidl reports the unaliased kind
        raise TypeError("aliased constant kind")
    if kind == idltype.tk_enum:
        return scoped(value.scopedName())
    if kind == idltype.tk_boolean:
        return bool(value)
    if kind == idltype.tk_wchar:
        return chr(value)
    if kind == idltype.tk_wstring:
        return "".join(chr(c) for c in value)
    if kind == idltype.tk_fixed:
        return str(value)
    if kind in (idltype.tk_float, idltype.tk_double, idltype.tk_longdouble):
        return float(value)
    if kind in (idltype.tk_char, idltype.tk_string):
        return value
    return int(value)


# ---- declarations -------------------------------------------------------------------------


class Dumper:
    def __init__(self):
        self.out = []

    def head(self, kind, d, name=None, repo_id=None, line=None):
        return {
            "kind": kind,
            "name": name if name is not None else scoped(d.scopedName()),
            "repo_id": repo_id if repo_id is not None else d.repoId(),
            "file": os.path.basename(d.file()),
            "line": line if line is not None else d.line(),
            "doc": None,
            "annotations": [],
        }

    def decls(self, decls):
        for d in decls:
            self.decl(d)

    def members(self, members, nested, with_public=False):
        out = []
        for m in members:
            if m.constrType():
                nested.append(m.memberType().decl())
            for dcl in m.declarators():
                j = {
                    "name": dcl.identifier(),
                    "type": type_string(m.memberType()),
                    "dims": list(dcl.sizes()),
                    "annotations": [],
                }
                if with_public:
                    j["public"] = m.memberAccess() == 0
                out.append(j)
        return out

    def callables(self, contents):
        ops, attrs = [], []
        for c in contents:
            if isinstance(c, idlast.Operation):
                ops.append(
                    {
                        "name": c.identifier(),
                        "oneway": bool(c.oneway()),
                        "returns": type_string(c.returnType()),
                        "params": [
                            {
                                "mode": ("in", "out", "inout")[p.direction()],
                                "name": p.identifier(),
                                "type": type_string(p.paramType()),
                            }
                            for p in c.parameters()
                        ],
                        "raises": [scoped(e.scopedName()) for e in c.raises()],
                        "contexts": list(c.contexts()),
                    }
                )
            elif isinstance(c, idlast.Attribute):
                for ident in c.identifiers():
                    attrs.append(
                        {
                            "name": ident,
                            "type": type_string(c.attrType()),
                            "readonly": bool(c.readonly()),
                            # omniidl 4.2 has no getraises/setraises
                            "get_raises": [],
                            "set_raises": [],
                        }
                    )
        return ops, attrs

    def nested_of(self, contents):
        return [
            c
            for c in contents
            if not isinstance(
                c, (idlast.Operation, idlast.Attribute, idlast.StateMember, idlast.Factory)
            )
        ]

    def decl(self, d):
        out = self.out
        if isinstance(d, idlast.Module):
            out.append(self.head("module", d))
            self.decls(d.definitions())
        elif isinstance(d, idlast.Interface):
            j = self.head("interface", d)
            j["bases"] = [scoped(b.scopedName()) for b in d.inherits()]
            j["abstract"] = bool(d.abstract())
            j["local"] = bool(d.local())
            j["operations"], j["attributes"] = self.callables(d.contents())
            out.append(j)
            self.decls(self.nested_of(d.contents()))
        elif isinstance(d, idlast.Forward):
            j = self.head("forward", d)
            j["of"] = "interface"
            out.append(j)
        elif isinstance(d, idlast.StructForward):
            j = self.head("forward", d)
            j["of"] = "struct"
            out.append(j)
        elif isinstance(d, idlast.UnionForward):
            j = self.head("forward", d)
            j["of"] = "union"
            out.append(j)
        elif isinstance(d, idlast.ValueForward):
            j = self.head("forward", d)
            j["of"] = "valuetype"
            out.append(j)
        elif isinstance(d, idlast.Const):
            j = self.head("const", d)
            j["type"] = type_string(d.constType())
            j["value"] = value_json(d.constKind(), d.value())
            out.append(j)
        elif isinstance(d, idlast.Typedef):
            if d.constrType():
                self.decl(d.aliasType().decl())
            for dcl in d.declarators():
                j = self.head("typedef", dcl)
                j["type"] = type_string(d.aliasType())
                j["dims"] = list(dcl.sizes())
                out.append(j)
        elif isinstance(d, idlast.Struct):
            j = self.head("struct", d)
            nested = []
            j["members"] = self.members(d.members(), nested)
            j["base"] = None
            out.append(j)
            self.decls(nested)
        elif isinstance(d, idlast.Exception):
            j = self.head("exception", d)
            nested = []
            j["members"] = self.members(d.members(), nested)
            out.append(j)
            self.decls(nested)
        elif isinstance(d, idlast.Union):
            j = self.head("union", d)
            nested = []
            if d.constrType():
                nested.append(d.switchType().decl())
            j["discriminator"] = type_string(d.switchType())
            cases = []
            for c in d.cases():
                if c.constrType():
                    nested.append(c.caseType().decl())
                dcl = c.declarator()
                cases.append(
                    {
                        "labels": [
                            "default" if lab.default() else value_json(lab.labelKind(), lab.value())
                            for lab in c.labels()
                        ],
                        "name": dcl.identifier(),
                        "type": type_string(c.caseType()),
                        "dims": list(dcl.sizes()),
                    }
                )
            j["cases"] = cases
            out.append(j)
            self.decls(nested)
        elif isinstance(d, idlast.Enum):
            j = self.head("enum", d)
            j["enumerators"] = [e.identifier() for e in d.enumerators()]
            out.append(j)
        elif isinstance(d, idlast.Native):
            out.append(self.head("native", d))
        elif isinstance(d, (idlast.Value, idlast.ValueAbs)):
            j = self.head("valuetype", d)
            j["bases"] = [scoped(b.scopedName()) for b in d.inherits()]
            j["supports"] = [scoped(s.scopedName()) for s in d.supports()]
            concrete = isinstance(d, idlast.Value)
            j["abstract"] = not concrete
            j["custom"] = bool(d.custom()) if concrete else False
            j["truncatable"] = bool(d.truncatable()) if concrete else False
            nested = []
            j["members"] = self.members(d.statemembers(), nested, with_public=True)
            j["operations"], j["attributes"] = self.callables(d.contents())
            j["factories"] = [
                {
                    "name": f.identifier(),
                    "params": [
                        {"mode": "in", "name": p.identifier(), "type": type_string(p.paramType())}
                        for p in f.parameters()
                    ],
                    "raises": [scoped(e.scopedName()) for e in f.raises()],
                }
                for f in (d.factories() if concrete else [])
            ]
            out.append(j)
            self.decls(nested)
            self.decls(self.nested_of(d.contents()))
        elif isinstance(d, idlast.ValueBox):
            j = self.head("valuebox", d)
            j["type"] = type_string(d.boxedType())
            out.append(j)
            if d.constrType():
                self.decl(d.boxedType().decl())
        else:  # pragma: no cover - every idlast declaration class is handled above
            raise TypeError(f"unexpected omniidl declaration {d!r}")


# ---- running omniidl ----------------------------------------------------------------------

_DIAG = re.compile(r"^(?P<file>.*?):(?P<line>\d+): (?P<message>.*)$")


def _parse_diagnostics(text):
    """omniidl's `file:line: message` lines; notes are indented (`file:line:  (...)`)."""
    errors, warnings = [], []
    for line in text.splitlines():
        m = _DIAG.match(line)
        if not m or m.group("message").startswith(" "):
            continue
        msg = m.group("message").strip()
        item = {
            "file": os.path.basename(m.group("file")),
            "line": int(m.group("line")),
            "message": msg,
        }
        (warnings if msg.startswith("Warning:") else errors).append(item)
    return errors, warnings


def _capture_fd2(fn):
    """Run fn() with file descriptor 2 redirected to a temporary file; return (result, text)."""
    sys.stderr.flush()
    saved = os.dup(2)
    with tempfile.TemporaryFile() as tmp:
        os.dup2(tmp.fileno(), 2)
        try:
            result = fn()
        finally:
            sys.stderr.flush()
            os.dup2(saved, 2)
            os.close(saved)
        tmp.seek(0)
        text = tmp.read().decode("utf-8", "replace")
    return result, text


def compile_file(path, include_dirs):
    """omniidl's verdict on one file, as a JSON-able dict."""
    cmd = ["omnicpp", "-lang-c++", "-undef", "-D__OMNIIDL__=" + _omniidl.version]
    cmd += ["-I" + d for d in include_dirs]
    cmd.append(path)
    cpp = subprocess.run(cmd, capture_output=True)
    result = {"ok": False, "files": [path], "declarations": None, "errors": [], "warnings": []}
    if cpp.returncode != 0:
        errors, _ = _parse_diagnostics(cpp.stderr.decode("utf-8", "replace"))
        result["errors"] = errors or [
            {"file": os.path.basename(path), "line": 0, "message": "preprocessor failed"}
        ]
        result["stderr"] = cpp.stderr.decode("utf-8", "replace")
        return result
    with tempfile.NamedTemporaryFile("wb", suffix=".idl", delete=False) as pre:
        pre.write(cpp.stdout)
    try:
        tree, text = _capture_fd2(lambda: _omniidl.compile(pre.name, path))
        errors, warnings = _parse_diagnostics(text)
        result["errors"], result["warnings"] = errors, warnings
        result["stderr"] = text
        if tree is not None:
            dumper = Dumper()
            dumper.decls(tree.declarations())
            result["ok"] = True
            result["declarations"] = dumper.out
        elif not errors:
            result["errors"] = [{"file": os.path.basename(path), "line": 0, "message": "rejected"}]
    finally:
        os.unlink(pre.name)
    return result


def compile_isolated(path, include_dirs):
    """compile_file() in a forked child: omniidl keeps global state between runs and aborts
    the whole process on some inputs (IDL 4 annotations, for instance)."""
    rfd, wfd = os.pipe()
    pid = os.fork()
    if pid == 0:  # child
        os.close(rfd)
        code = 0
        try:
            data = json.dumps(compile_file(path, include_dirs), ensure_ascii=False)
            with os.fdopen(wfd, "w", encoding="utf-8") as w:
                w.write(data)
        except BaseException:  # report anything to the parent
            traceback.print_exc()
            code = 2
        finally:
            os._exit(code)
    os.close(wfd)
    with os.fdopen(rfd, "r", encoding="utf-8") as r:
        data = r.read()
    _, status = os.waitpid(pid, 0)
    if os.WIFEXITED(status) and os.WEXITSTATUS(status) == 0 and data:
        return json.loads(data)
    why = (
        f"omniidl crashed (signal {os.WTERMSIG(status)})"
        if os.WIFSIGNALED(status)
        else f"omniidl_dump failed (exit status {os.WEXITSTATUS(status)})"
    )
    return {
        "ok": False,
        "crashed": True,
        "files": [path],
        "declarations": None,
        "errors": [{"file": os.path.basename(path), "line": 0, "message": why}],
        "warnings": [],
    }


def main(argv):
    include_dirs, files = [], []
    it = iter(argv)
    for a in it:
        if a == "--probe":
            print(json.dumps({"version": _omniidl.version}))
            return 0
        if a == "-I":
            include_dirs.append(next(it))
        elif a.startswith("-I"):
            include_dirs.append(a[2:])
        else:
            files.append(a)
    results = {f: compile_isolated(f, include_dirs) for f in files}
    json.dump(results, sys.stdout, ensure_ascii=False, indent=1)
    sys.stdout.write("\n")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
