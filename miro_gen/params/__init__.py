"""makeParams in Python: the run-time side that generated parameter modules and services use.

`ConfigDocument` reads a run-time document; generated classes derive from `Config`; problems in
a document raise `ParamsError`. The compiler itself (`loader`, `build`, `generate`) is imported
by `miro-params` only.
"""

from __future__ import annotations

from miro_gen.params.document import ConfigDocument, Instance, read_parameters
from miro_gen.params.runtime import Config, InetAddr, ParamsError, SchedParams, SerialParams

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
