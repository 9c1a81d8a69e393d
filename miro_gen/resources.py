"""Where miro-gen's data files are, in a checkout or installed from the wheel: the templates,
the SvcParameters.xml that `miro/SvcParameters.h` includes find, and the shipped services (the
manual's examples, the drivers).

The wheel has them inside the package (`miro_gen/templates`, `miro_gen/params/xml`,
`miro_gen/services`); in a checkout those are links to the top-level `templates/`, `params/`
and `services/`, so that an editable install sees the wheel's layout. Where the links are not
links (a checkout without symlinks), the top-level folders are used. Paths only, no imports
beyond the standard library: `miro run` asks before anything starts.
"""

from __future__ import annotations

from pathlib import Path

PACKAGE = Path(__file__).resolve().parent


def _inside_or_beside(inside: Path, beside: Path, marker: str) -> Path | None:
    """`inside` the package when it holds `marker`, else the checkout's folder `beside` it (its
    real path: in a checkout, the top-level folder the link names)."""
    for folder in (inside, beside):
        if (folder / marker).exists():
            return folder.resolve()
    return None


def template_dir() -> Path:
    """The Jinja templates: `idl/`, `params/` and `service/` (the patterns of `miro new`)."""
    found = _inside_or_beside(PACKAGE / "templates", PACKAGE.parent / "templates", "idl")
    return found if found is not None else PACKAGE / "templates"


def params_dir() -> Path | None:
    """The folder of the shipped SvcParameters.xml (Miro's standard parameter types)."""
    xml = PACKAGE / "params" / "xml"
    return _inside_or_beside(xml, PACKAGE.parent / "params", "SvcParameters.xml")


def services_dir() -> Path | None:
    """The shipped services."""
    return _inside_or_beside(PACKAGE / "services", PACKAGE.parent / "services", "exampleA.py")
