"""The Python back end of `miro-idl`: resolved IDL -> contexts -> Jinja templates -> files.

Stages, each a module with one job (docs/ARCHITECTURE.md draws the whole pipeline):
`shapes` (an IDL type as the back end sees it), `scope` (where each declaration lives in Python
and how to refer to it), `hints` (annotations and defaults), `steps` and `codec` (the codec's
typed steps and their planner), `contexts` (one class per generated kind), `lower`,
`lower_data` and `lower_interface` (declarations -> contexts), `packages` (package `__init__`s),
`layout` and `render` (line breaking, Jinja), `generate` (the files `miro-idl` writes).
"""
