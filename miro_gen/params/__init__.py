"""makeParams in Python.

`miro_gen.params.runtime` is what generated parameter modules and services import (`Config`,
`ConfigDocument`, `ParamsError`, the codecs); `miro_gen.params.compiler` is `miro-params` itself,
imported only by the tools. The names below are the run-time ones services use.
"""

from __future__ import annotations

from miro_gen.params.runtime import (
    Config,
    ConfigDocument,
    InetAddr,
    Instance,
    ParamsError,
    SchedParams,
    SerialParams,
    read_parameters,
)

__all__ = [
    "Config",
    "ConfigDocument",
    "InetAddr",
    "Instance",
    "ParamsError",
    "SchedParams",
    "SerialParams",
    "read_parameters",
]
