"""Python names for IDL names: escaping, packages, modules and classes.

Rules (documented in docs/CODEGEN.md):

* an IDL identifier that is a Python keyword gets a leading underscore (`_from`, `_None`), as the
  OMG IDL-to-Python mapping says (which counts `print` and `exec` as keywords: `_print`); so do
  the few builtins that generated code uses where the name would shadow them (a member `str` or
  `list`, a parameter `len`; a member `range` stays), and names that generated classes already
  use (`serialize`);
* IDL module `Miro` is package `Miro`, nested modules are subpackages, the global scope is
  `_GlobalIDL`; skeletons are in the package with `__POA` appended to its top-level name;
* declarations nested in an interface, struct or union live at module level as `Outer_Inner`
  and are also reachable as `Outer.Inner`;
* an IDL file `Example.idl` yields module `Example_idl` in each package it declares things in.
"""

from __future__ import annotations

import keyword
import re

from miro_gen.idl import ast

GLOBAL_PACKAGE = "_GlobalIDL"
POA_SUFFIX = "__POA"

# Builtins that generated code names, by where a name would shadow them. Only these are escaped:
# a struct member called `range` stays `range`.
#  - class bodies (fields, union branches, methods): annotations and decorators there;
CLASS_BODY = frozenset(
    ["bool", "bytes", "dict", "float", "int", "list", "str", "tuple"]
) | frozenset(["classmethod", "property", "staticmethod"])
#  - function parameters: what generated method bodies call;
PARAMETERS = frozenset(
    ["self", "bytearray", "bytes", "chr", "len", "list", "map", "ord", "range", "tuple"]
)
#  - module level (types, constants): everything generated code names.
SHADOWING = (
    CLASS_BODY
    | (PARAMETERS - {"self"})
    | frozenset(["Exception", "isinstance", "iter", "object", "super", "type"])
)
# Attributes that generated classes define.
STRUCT_ATTRIBUTES = CLASS_BODY | {"serialize", "deserialize"}
EXCEPTION_ATTRIBUTES = STRUCT_ATTRIBUTES | {"args", "with_traceback", "add_note"}
PARAMETER_NAMES = PARAMETERS


# Keywords of the Python the OMG mapping was written for: it (and omniORBpy) escape them too.
OMG_KEYWORDS = frozenset(["exec", "print"])


def py_name(name: str, taken: frozenset[str] = SHADOWING) -> str:
    """The Python identifier for an IDL identifier: Python keywords (and the mapping's `print`,
    `exec`), and the names in `taken` (builtins that would be shadowed where the name lives),
    get a leading underscore."""
    if keyword.iskeyword(name) or name in OMG_KEYWORDS or name in taken:
        return "_" + name
    return name


def package_name(modules: tuple[str, ...]) -> str:
    """`("Miro", "Sub")` -> "Miro.Sub"; `()` -> "_GlobalIDL"."""
    if not modules:
        return GLOBAL_PACKAGE
    return ".".join(py_name(m) for m in modules)


def poa_package_name(modules: tuple[str, ...]) -> str:
    """The skeleton package: "Miro__POA.Sub" for IDL module Miro::Sub."""
    parts = package_name(modules).split(".")
    return ".".join([parts[0] + POA_SUFFIX, *parts[1:]])


def module_stem(idl_path: str) -> str:
    """`idl/Example.idl` -> "Example_idl"; a ROS 2 interface file too (`msg/Header.msg` ->
    "Header_idl", as rosidl's `Header.idl` of it)."""
    base = re.sub(
        r"\.(idl|msg|srv|action)$", "", idl_path.replace("\\", "/").rsplit("/", 1)[-1], flags=re.I
    )
    stem = re.sub(r"\W", "_", base)
    if not stem or stem[0].isdigit():
        stem = "_" + stem
    return stem + "_idl"


def class_name(decl: ast.Decl, nesting: int) -> str:
    """Module-level class name: the declaration's name, prefixed by its enclosing interfaces,
    structs or unions (`nesting` of them): `Odometry_Status` for Miro::Odometry::Status."""
    parts = decl.scope_path[len(decl.scope_path) - 1 - nesting :]
    return py_name("_".join(parts))


def module_alias(module: str) -> str:
    """A private, unique alias for importing a generated module: `_m_Miro_Time_idl`."""
    return "_m_" + module.replace(".", "_")
