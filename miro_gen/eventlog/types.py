"""Naming topics, and making the types of a log decodable.

Which generated class has a type hash is miro_gen.runtime.registry's: the log tools use its
`find`, which imports, once, every generated package on the module search path, so that a log
of any type compiled on this machine decodes without configuration. Types that are not compiled
here are compiled from the data schemas in the log (`types_from_schemas`).
"""

from __future__ import annotations

ANY = "*"


def topic_name(domain: str, type_name: str) -> str:
    """The MCAP topic of events of `type_name` from `domain`: `domain/type`."""
    return f"{domain}/{type_name}"


def parse_topic(text: str) -> tuple[str, str]:
    """(domain, type) of `domain/type`; the domain may be a path (`lab/robot1/Odometry`), either
    part may be `*`. A bare `TYPE` means `*/TYPE`. A ROS 2 topic (`/chatter`, of a rosbag2
    file, whose domain it is) means `/chatter` of any type."""
    if text.startswith("/") and len(text) > 1:
        return text, ANY
    domain, sep, type_name = text.rpartition("/")
    if not sep:
        return ANY, text
    if not domain or not type_name:
        raise ValueError(f"{text!r} is not DOMAIN/TYPE")
    return domain, type_name


def matches(pattern: tuple[str, str], domain: str, type_name: str) -> bool:
    d, t = pattern
    return d in (ANY, domain) and t in (ANY, type_name)


def types_from_schemas(schemas: list[str]) -> str | None:
    """Make the types of these data schemas (read from a log) decodable here: compile them as
    schemas from elsewhere (miro_gen.compile.foreign: no directives, capped, in a process of
    its own) into a temporary folder, and import the packages. The log's schemas are the very
    text the types' hashes were made from, so the compiled types have the recorded hashes.
    Returns why it could not (None when it did): the schemas are refused or do not compile,
    or a package of that name exists here already."""
    if not any(s.strip() for s in schemas):
        return None
    # Imported here: naming and matching topics is all that most log tools need of this
    # module, and the compiler's imports would cost every `miro log info` its start-up.
    import atexit
    import importlib
    import importlib.util
    import shutil
    import sys
    import tempfile
    from pathlib import Path

    from miro_gen.compile.foreign import PACKAGES, ForeignSchemaError, compile_foreign

    folder = Path(tempfile.mkdtemp(prefix="miro-log-types-"))
    atexit.register(shutil.rmtree, folder, True)
    try:
        compile_foreign(schemas, folder)
    except ForeignSchemaError as e:
        return str(e)
    out = folder / PACKAGES
    packages = sorted(p.name for p in out.iterdir() if p.is_dir()) if out.is_dir() else []
    taken = [n for n in packages if importlib.util.find_spec(n) is not None]
    if taken:
        return f"a package {taken[0]} without these types exists here already"
    sys.path.insert(0, str(out))
    for name in packages:
        try:
            importlib.import_module(name)
        except Exception as e:  # types too large to exist (an array of 10^20 elements)
            return f"its compiled types cannot be loaded: {type(e).__name__}: {e}"
    return None
