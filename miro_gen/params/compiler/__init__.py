"""The compile-time half of makeParams: `miro-params` and the tools that compile parameter files
in memory (`miro params show/validate`, `--xsd`).

Data flows one way: `loader` reads compile-time files into `model`; `build` (with `pymodel`'s type
mapping, `expressions` for `default=` and `constructor` for `<constructor>` blocks) makes the
template context; `generate` renders and writes it. The compiler imports the run-time half
(`miro_gen.params.runtime`), never the reverse.
"""
