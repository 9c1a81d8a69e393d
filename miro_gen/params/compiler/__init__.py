"""The compile-time half of makeParams: `miro-params` and the tools that compile parameter files
in memory (`miro params show/validate`, `--xsd`).

Data flows one way: `loader` reads compile-time files (and the files their includes reach) into
`model`; `build` makes the template context, with `pymodel` (types and context classes),
`expressions` and `defaults` (`default=` as C++ evaluated it), `constructor` and `ctor_exprs`
(`<constructor>` blocks) and `ordering` (the order of a module's classes); `generate` renders and
writes it; `dynamic` loads it in memory for the tools. The compiler imports the run-time half
(`miro_gen.params.runtime`), never the reverse.
"""
