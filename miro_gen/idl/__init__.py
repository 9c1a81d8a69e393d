"""The OMG IDL front end: preprocessor, LALR grammar, resolver and AST JSON.

`compile_idl(path, include_dirs, defines)` returns the resolved `ast.Specification` of one file
or raises `miro_gen.diagnostics.CompileError` carrying every problem found.
"""

from miro_gen.idl.frontend import compile_idl

__all__ = ["compile_idl"]
