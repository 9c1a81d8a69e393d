"""miro-idl against ROS 2's own tools on ROS 2 interface files (the Kilted wheels from PyPI).

Shared by tests/ros2/test_ros2_interfaces.py and runnable on its own (with the ROS 2 environment of
tests/ros2_env.py, made if it is not there):

    python tests/rosidl_differential.py

For each interface of each package under the environment's `share/` (`<pkg>/msg/*.msg`, `srv/*.srv`,
`action/*.action`, and the `.idl` files rosidl_adapter made of them or that stand alone):
- the `.msg`/`.srv`/`.action` and its `.idl` (with `--ros2`) give the same AST JSON, apart from
  files and lines;
- the structs of the `.idl` agree with rosidl_parser's parse of it (Messages, Services with
  their events, Actions with their derived services and feedback message): names, members,
  member types (typedefs followed), default values and constants;
- every type hash in the package's `.json` file equals miro-idl's RIHS01 hash of the type.
Prints the counts.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

import ros2_env
from ros2_env import Ros2Env

from miro_gen.idl import ast, compile_idl
from miro_gen.idl.ast_json import specifications_json

KINDS = {"msg": ".msg", "srv": ".srv", "action": ".action"}
# rosidl_parser's names of the basic types, by the names miro-idl's AST gives them.
ROSIDL_BASIC = {
    "short": "int16", "unsigned short": "uint16", "long": "int32", "unsigned long": "uint32",
    "long long": "int64", "unsigned long long": "uint64",
}  # fmt: skip


def interface_files(share: Path) -> list[Path]:
    """The `.msg`, `.srv` and `.action` files of every package under `share`."""
    return sorted(f for kind, suffix in KINDS.items() for f in share.glob(f"*/{kind}/*{suffix}"))


def idl_files(share: Path) -> list[Path]:
    """The `.idl` files of every package's `msg`, `srv` and `action` folders."""
    return sorted(f for kind in KINDS for f in share.glob(f"*/{kind}/*.idl"))


def compile_file(path: Path, share: Path) -> ast.Specification:
    return compile_idl(str(path), [str(share)], ros2=True)


def ast_json_of_main(spec: ast.Specification) -> list[dict[str, Any]]:
    """The AST JSON declarations of the spec's main file, without files and lines."""
    doc = specifications_json([spec.main_file], [spec])
    return [
        {k: v for k, v in d.items() if k not in ("file", "line")}
        for d in doc["declarations"]
        if d["file"] == spec.main_file
    ]


def json_hashes(path: Path) -> dict[str, str]:
    """type name -> RIHS01 hash, from the `.json` rosidl shipped beside an interface file."""
    doc = json.loads(path.with_suffix(".json").read_text(encoding="utf-8"))
    return {h["type_name"]: h["hash_string"] for h in doc["type_hashes"]}


def miro_hashes(spec: ast.Specification) -> dict[str, str]:
    return {name.replace("::", "/"): h for name, h in spec.ros2_hashes.items()}


# ---- structs as both sides see them ---------------------------------------------------------


def miro_structs(spec: ast.Specification) -> dict[str, Any]:
    """The structs and constants of the main file: name -> (members, constants)."""
    consts: dict[str, list[Any]] = {}
    structs: dict[str, Any] = {}
    for d in spec.declarations:
        if d.pos.path != spec.main_file:
            continue
        if isinstance(d, ast.Const):
            owner = "::".join(d.scope_path[:-1]).removesuffix("_Constants")
            consts.setdefault(owner, []).append((d.name, _miro_type(d.type), _plain(d.value)))
        elif isinstance(d, ast.Struct):
            structs[d.scoped_name] = [
                (m.name, _miro_type(m.type, m.dims), _miro_default(m)) for m in d.members
            ]
    return {name: (members, consts.get(name, [])) for name, members in structs.items()}


def _miro_default(m: ast.Member) -> Any:
    for a in m.annotations:
        if a.short_name == "default":
            return _plain(a.params["value"])
    return None


def _plain(v: Any) -> Any:
    return v if isinstance(v, bool | int | float | str) else str(v)


def _miro_type(t: Any, dims: list[int] | None = None) -> str:
    if dims:
        return f"{_miro_type(t)}[{dims[0]}]"
    if isinstance(t, ast.NamedType):
        assert t.decl is not None
        return _miro_type(t.decl.resolved)
    if isinstance(t, ast.Typedef):
        return _miro_type(t.type, t.dims)
    if isinstance(t, ast.BaseType):
        return ROSIDL_BASIC.get(t.name, t.name)
    if isinstance(t, ast.StringType):
        name = "wstring" if t.wide else "string"
        return f"{name}<{t.bound}>" if t.bound is not None else name
    if isinstance(t, ast.SequenceType):
        bound = f", {t.bound}" if t.bound is not None else ""
        return f"sequence<{_miro_type(t.element)}{bound}>"
    if isinstance(t, ast.Struct):
        return t.scoped_name
    raise AssertionError(t)


def rosidl_structs(env: Ros2Env, paths: list[Path]) -> dict[Path, Any]:
    """The same, from rosidl_parser's parse of each `.idl` file (with the types it derives; the
    service and action structs of the type descriptions are miro-idl's alone), by file: run in
    the ROS 2 environment (tests/ros2/rosidl_structs.py), in JSON's shapes."""
    rel = [str(p.relative_to(env.share)) for p in paths]
    got = env.run_json("rosidl_structs.py", str(env.share), *rel)
    return {env.share / f: structs for f, structs in got.items()}


def as_json(structs: dict[str, Any]) -> Any:
    """miro's side in the shapes the JSON of rosidl's has (lists for tuples)."""
    return json.loads(json.dumps(structs))


def agrees(spec: ast.Specification, theirs: dict[str, Any]) -> bool:
    """miro-idl's structs of a file are rosidl_parser's (`theirs`, from `rosidl_structs`) and
    the service and action structs only miro-idl makes (for their type descriptions)."""
    return as_json(miro_structs(spec)) == theirs | as_json(service_structs(spec))


def compare(env: Ros2Env) -> dict[str, int]:
    """Run every check over the environment's `share`; the counts, and the problems printed."""
    share = env.share
    counts = {"interface files": 0, "idl files": 0, "same AST": 0, "rosidl agrees": 0}
    counts |= {"hashes": 0, "hashes equal": 0, "problems": 0}

    def problem(text: str) -> None:
        counts["problems"] += 1
        print(text)

    for f in interface_files(share):
        counts["interface files"] += 1
        if ast_json_of_main(compile_file(f, share)) == ast_json_of_main(
            compile_file(f.with_suffix(".idl"), share)
        ):
            counts["same AST"] += 1
        else:
            problem(f"{f}: the AST differs from its .idl's")
    idls = idl_files(share)
    theirs = rosidl_structs(env, idls)
    for f in idls:
        counts["idl files"] += 1
        spec = compile_file(f, share)
        if agrees(spec, theirs[f]):
            counts["rosidl agrees"] += 1
        else:
            problem(f"{f}: the structs differ from rosidl_parser's")
        mine = miro_hashes(spec)
        for name, want in json_hashes(f).items():
            counts["hashes"] += 1
            if mine.get(name) == want:
                counts["hashes equal"] += 1
            else:
                problem(f"{f}: {name}: {mine.get(name)} != {want}")
    return counts


def service_structs(spec: ast.Specification) -> dict[str, Any]:
    """miro-idl's structs for the services and actions themselves (type descriptions only)."""
    wanted = ("request_message", "send_goal_service")
    out = {}
    for name, (members, consts) in miro_structs(spec).items():
        if (
            members
            and members[0][0] in ("request_message", "goal")
            and any(m[0] in wanted for m in members)
        ):
            out[name] = (members, consts)
    return out


if __name__ == "__main__":
    try:
        ros2 = ros2_env.make()
    except ros2_env.Ros2EnvUnavailable as e:
        sys.exit(f"no ROS 2 environment: {e}")
    counts = compare(ros2)
    print(", ".join(f"{k}: {v}" for k, v in counts.items()))
    sys.exit(1 if counts["problems"] else 0)
