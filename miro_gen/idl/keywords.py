"""IDL keywords, for the checks on identifiers (the grammar's lexer is contextual)."""

from __future__ import annotations

# CORBA 2.x/3.0 core keywords: reserved; an identifier equal to one of them, ignoring case, is an
# error (CORBA 3.0 section 3.2.4). `_name` escapes a keyword.
RESERVED = frozenset(
    [
        "abstract",
        "any",
        "attribute",
        "boolean",
        "case",
        "char",
        "const",
        "context",
        "custom",
        "default",
        "double",
        "enum",
        "exception",
        "factory",
        "FALSE",
        "fixed",
        "float",
        "in",
        "inout",
        "interface",
        "local",
        "long",
        "module",
        "native",
        "Object",
        "octet",
        "oneway",
        "out",
        "private",
        "public",
        "raises",
        "readonly",
        "sequence",
        "short",
        "string",
        "struct",
        "supports",
        "switch",
        "TRUE",
        "truncatable",
        "typedef",
        "unsigned",
        "union",
        "ValueBase",
        "valuetype",
        "void",
        "wchar",
        "wstring",
    ]
)
RESERVED_FOLDED = {k.lower(): k for k in RESERVED}

# CORBA 3 component-model keywords: accepted as identifiers with a warning (as omniidl does).
CORBA3_KEYWORDS = frozenset(
    [
        "component",
        "consumes",
        "emits",
        "eventtype",
        "finder",
        "getraises",
        "home",
        "import",
        "multiple",
        "primarykey",
        "provides",
        "publishes",
        "setraises",
        "typeid",
        "typeprefix",
        "uses",
    ]
)
CORBA3_FOLDED = {k.lower(): k for k in CORBA3_KEYWORDS}

# Constructs recognised only to refuse them with a clear message.
UNSUPPORTED_CONSTRUCTS = {
    "component": "CCM component declarations",
    "home": "CCM home declarations",
    "eventtype": "CCM event types",
    "porttype": "IDL 4 port types",
    "connector": "IDL 4 connectors",
    "import": "CORBA 3 import declarations",
    "bitset": "IDL 4 bitsets",
    "bitmask": "IDL 4 bitmasks",
}
