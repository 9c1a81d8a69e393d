"""Python names for IDL names: escaping, packages, modules and classes.

Rules (documented in docs/CODEGEN.md):

* an IDL identifier that is a Python keyword gets a leading underscore (`_from`, `_None`), as the
  OMG IDL-to-Python mapping says; so do the few builtins that generated code names in annotations
  (`str`, `int`, `list`, ...) and names that generated classes already use (`serialize`);
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

# Builtins that generated code uses by name: a class, field or parameter with one of these names
# would shadow them (and confuse type checkers).
SHADOWING = frozenset(
    [
        "bool",
        "bytes",
        "dict",
        "float",
        "int",
        "list",
        "object",
        "str",
        "tuple",
        "type",
        "len",
        "range",
        "super",
        "isinstance",
        "property",
        "staticmethod",
        "classmethod",
        "Exception",
    ]
)
# Attributes that generated classes define.
STRUCT_ATTRIBUTES = frozenset(["serialize", "deserialize"])
EXCEPTION_ATTRIBUTES = STRUCT_ATTRIBUTES | {"args", "with_traceback", "add_note"}
PARAMETER_NAMES = frozenset(["self"])


def py_name(name: str, taken: frozenset[str] = frozenset()) -> str:
    """The Python identifier for an IDL identifier (keywords and shadowing names escaped)."""
    if keyword.iskeyword(name) or name in SHADOWING or name in taken:
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
    """`idl/Example.idl` -> "Example_idl"."""
    base = re.sub(r"\.idl$", "", idl_path.replace("\\", "/").rsplit("/", 1)[-1], flags=re.I)
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
