"""Compiling into an importable package: the one owner of it.

`idl.idl_package` compiles IDL files and `params.params_package` compile-time parameter files
into a folder of Python packages, with the checks of `checks.py`; `miro-idl`, `miro-params`,
`miro new`, `miro build` (and the freshness check of `miro run` and `miro launch`) all call
them, and show the `Outcome` (`outcome.py`) as they need.

Schema text from elsewhere (a log's, a running service's) is foreign: `foreign.py` says whether
it may be compiled at all (no preprocessor directives, a size cap) and compiles it in a process
of its own (`python -m miro_gen.compile`) with a time and a memory cap. `foreign.py` imports no
compiler, so that the run time (the log reader) can use it; this file imports nothing either.
"""
