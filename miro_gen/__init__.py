"""miro-gen: Miro (Middleware for Robots) in Python.

The IDL compiler lives in `miro_gen.idl` (`miro-idl`); the runtime API arrives with the transport.
"""
