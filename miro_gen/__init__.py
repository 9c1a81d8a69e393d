"""miro-gen: Miro (Middleware for Robots) in Python.

The IDL compiler lives in `miro_gen.idl` (`miro-idl`); generated code uses `miro_gen.runtime`;
remote-call exceptions are in `miro_gen.exceptions`.
"""

__version__ = "0.1.0"
