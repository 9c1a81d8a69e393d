"""The run-time half of makeParams: what generated parameter modules and services import.

Generated modules `import miro_gen.params.runtime as _rt` and use only the names below: the base
class `Config`, the codecs that read, write and print each C++ type, struct layouts, the C++
arithmetic of `<constructor>` blocks, and `ConfigDocument` for run-time documents. Nothing here
imports the compiler (`miro_gen.params.compiler`), so a service starts without Lark or Jinja.
"""

from __future__ import annotations

from miro_gen.params.runtime.codecs import (
    ANGLE,
    BOOL,
    CHAR,
    DOUBLE,
    FAIL,
    FLOAT,
    INET_ADDR,
    INT,
    LONG,
    SHORT,
    STRING,
    TIME,
    UINT,
    ULONG,
    USHORT,
    Codec,
    Enum,
    Scalar,
    Vector,
    enum_multiple,
)
from miro_gen.params.runtime.config import (
    Config,
    Layout,
    ParamsError,
    SchedParams,
    SerialParams,
    Struct,
    XmlField,
    cxx_div,
    cxx_mod,
    instance_of,
    layout_of,
    resize,
    show_lines,
)
from miro_gen.params.runtime.document import ConfigDocument, Instance, read_parameters
from miro_gen.params.runtime.linking import hand_written, missing_module, package_path
from miro_gen.params.runtime.values import InetAddr, deg2rad, rad2deg, time_value

__all__ = [
    "ANGLE",
    "BOOL",
    "CHAR",
    "DOUBLE",
    "FAIL",
    "FLOAT",
    "INET_ADDR",
    "INT",
    "LONG",
    "SHORT",
    "STRING",
    "TIME",
    "UINT",
    "ULONG",
    "USHORT",
    "Codec",
    "Config",
    "ConfigDocument",
    "Enum",
    "InetAddr",
    "Instance",
    "Layout",
    "ParamsError",
    "Scalar",
    "SchedParams",
    "SerialParams",
    "Struct",
    "Vector",
    "XmlField",
    "cxx_div",
    "cxx_mod",
    "deg2rad",
    "enum_multiple",
    "hand_written",
    "instance_of",
    "layout_of",
    "missing_module",
    "package_path",
    "rad2deg",
    "read_parameters",
    "resize",
    "show_lines",
    "time_value",
]
