"""Reading makeParams compile-time files into the model, includes first.

An include names a C++ header; it stands for the compile-time file or IDL file that header was
generated from: `miro/SvcParameters.h` is `SvcParameters.xml`, `idl/ScanDescriptionC.h` (TAO's
client header) is `ScanDescription.idl`. They are looked for as the C++ compiler looked for the
header: in the including file's folder, then in the `-I` folders; then in the folders above the
including file and their `src/` (where a Miro source tree holds `miro/`), and last in the
project's own `params/`. Other headers (`vector`, `ace/...`, hand-written
`BehaviourParameters.h`) are C++ matters and are ignored. An IDL header needs no IDL file: its
types are imported from the module miro-idl generated for it (`Miro.ScanDescription_idl`).

makeParams' reading is kept where it was lenient: `final` is false only when it says "false",
`dummy`, `extern` and `instance` are true only when they say "true" (other spellings are
warnings); `default=""` is C++'s value-initialisation (no default); `namespace` globals nest
(`Miro` then `BAP` is `Miro::BAP`).
"""

from __future__ import annotations

import re
from pathlib import Path

from lxml import etree

from miro_gen import resources
from miro_gen.diagnostics import Diagnostics, SourcePos
from miro_gen.params.compiler.model import Constructor, Include, ItemDecl, ParamDecl, ParamsFile
from miro_gen.params.runtime.xmlsafe import XmlError, read_xml

_ITEM_ATTRS = frozenset(["name", "parent", "final", "dummy", "extern", "instance"])
_GLOBAL_KINDS = frozenset(["forward", "local_forward"])
_PARAM_ATTRS = frozenset(
    ["name", "type", "default", "measure", "values", "static_const", "inherited", "fullname"]
)
_INCLUDE_KINDS = ("include", "Include", "src_Include")
# Files being read at once through includes (as the IDL preprocessor's limit): a chain of
# thousands of files would otherwise end in Python's recursion limit, with no position.
MAX_INCLUDE_DEPTH = 200
_IDENT = re.compile(r"[A-Za-z_]\w*$")
_SCOPED = re.compile(r"(::)?[A-Za-z_]\w*(::[A-Za-z_]\w*)*$")
_NAMESPACE = re.compile(r"[A-Za-z_]\w*(::[A-Za-z_]\w*)*$")


def display_path(path: Path, base: Path | None = None) -> str:
    """Relative to `base` (default: the working folder) when inside it, else the file name (no
    absolute paths in generated output)."""
    try:
        return path.resolve().relative_to((base or Path.cwd()).resolve()).as_posix()
    except ValueError:
        return path.name


def _flag(elem: etree._Element, attr: str, f: ParamsFile, diag: Diagnostics) -> bool | None:
    """makeParams' reading of a true/false attribute: None when absent. makeParams compared
    with one word (`final` is false only for "false", the others true only for "true"); other
    spellings of true and false are read as meant, anything else as makeParams did, with a
    warning."""
    text = elem.get(attr)
    if text is None:
        return None
    t = text.strip().lower()
    if t in ("true", "1", "yes"):
        return True
    if t in ("false", "0", "no"):
        return False
    as_makeparams = attr == "final"  # final: anything but "false"; the others: only "true"
    diag.warning(
        f.pos(elem.sourceline),
        f"{attr}={text!r}: expected true or false; read as {str(as_makeparams).lower()}, "
        "as makeParams did",
    )
    return as_makeparams


def _doc(elem: etree._Element) -> str | None:
    for child in elem:
        if child.tag == "documentation":
            text = "".join(child.itertext()).strip()
            lines = [line.strip() for line in text.splitlines()]
            return "\n".join(lines) or None
    return None


class Loader:
    """Reads compile-time files (each once) with the files they include; generated files name
    them relative to `base` (default: the working folder)."""

    def __init__(
        self, include_dirs: list[str], diag: Diagnostics, base: Path | None = None
    ) -> None:
        self.include_dirs = [Path(d) for d in include_dirs]
        self.base = base
        self.builtin = resources.params_dir()  # Miro's SvcParameters.xml, shipped
        self.diag = diag
        self.files: dict[Path, ParamsFile] = {}
        self._loading: set[Path] = set()
        # each file's items by class name (the test for an item defined twice)
        self._classes: dict[Path, dict[str, ItemDecl]] = {}

    def load(self, path: Path, pos: SourcePos | None = None) -> ParamsFile | None:
        key = path.resolve()
        if key in self.files:
            return self.files[key]
        if key in self._loading:
            # C++'s include guards: a header included again while it is read adds nothing
            return None
        self._loading.add(key)
        try:
            tree = read_xml(path)
        except XmlError as e:
            self.diag.items.extend(e.diagnostics)
            return None
        finally:
            self._loading.discard(key)
        f = ParamsFile(path=path, display=display_path(path, self.base))
        self._loading.add(key)
        try:
            self._read(f, tree.getroot())
        finally:
            self._loading.discard(key)
        self.files[key] = f
        return f

    def _read(self, f: ParamsFile, root: etree._Element) -> None:
        if root.tag != "config":
            self.diag.error(f.pos(root.sourceline), f"expected <config>, found <{root.tag!s}>")
            return
        for elem in root:
            if not isinstance(elem.tag, str):
                continue
            if elem.tag == "config_global":
                self._global(f, elem)
            elif elem.tag == "config_group":
                group = elem.get("name")
                if group is None:
                    self.diag.error(f.pos(elem.sourceline), "a config_group needs a name")
                elif group not in f.groups:
                    f.groups.append(group)
                for item in elem:
                    if item.tag == "config_item":
                        self._item(f, item, group)
                    elif item.tag == "documentation" or not isinstance(item.tag, str):
                        continue
                    else:
                        self._unexpected(f, item, "config_group")
            elif elem.tag == "config_item":
                self._item(f, elem, None)
            elif elem.tag == "documentation":
                continue
            else:
                self._unexpected(f, elem, "config")

    def _unexpected(self, f: ParamsFile, elem: etree._Element, where: str) -> None:
        self.diag.error(f.pos(elem.sourceline), f"unexpected element <{elem.tag!s}> in <{where}>")

    def _global(self, f: ParamsFile, elem: etree._Element) -> None:
        name = elem.get("name")
        value = (elem.get("value") or "").strip()
        pos = f.pos(elem.sourceline)
        if name == "namespace":
            if not value:
                self.diag.warning(pos, "a namespace global without a value; ignored")
            elif not _NAMESPACE.match(value):
                self.diag.error(pos, f"namespace {value!r} is not a C++ namespace name")
            else:  # makeParams nests them: Miro, then BAP, is Miro::BAP
                f.namespace = f"{f.namespace}::{value}" if f.namespace else value
        elif name in _INCLUDE_KINDS:
            if not value:
                self.diag.warning(pos, f"a {name} global without a file name; ignored")
                return
            inc = Include(value, pos, name)
            self._resolve_include(f, inc)
            f.includes.append(inc)
        elif name in _GLOBAL_KINDS:
            f.forwards.append(value)
        elif name in ("python_helper", "python_class"):
            # <config_global name="python_helper" type="Miro::Polygon" value="my_pkg.polygon"/>
            # <config_global name="python_class" type="Miro::BAP::Behaviour" value="my_bap"/>
            cxx = (elem.get("type") or "").strip().lstrip(":")
            if not cxx or not re.match(r"[A-Za-z_][\w.]*(:[A-Za-z_]\w*)?$", value):
                self.diag.error(pos, f'{name} needs type="C++ type" and value="module"')
            elif name == "python_helper":
                f.helpers[cxx] = value
                f.helper_pos[cxx] = pos
            else:
                f.python_classes[cxx] = value
        else:
            self.diag.warning(pos, f"config_global {name!r} is not known; ignored")

    def _resolve_include(self, f: ParamsFile, inc: Include) -> None:
        header = inc.value.strip('<>" ')
        folder_part, _, base = header.rpartition("/")
        stem, dot, ext = base.rpartition(".")
        if not dot or ext not in ("h", "hh", "hpp", "xml"):
            return  # <vector>, <set>: C++ only
        if stem.endswith("C") and ext == "h":  # TAO's client header of an IDL file
            # its types come from the module miro-idl generated for it (<stem>_idl)
            inc.idl_stem = stem[:-1]
            inc.idl_file = self._find(f, folder_part, stem[:-1] + ".idl")
            return
        found = self._find(f, folder_part, stem + ".xml")
        if found is not None and len(self._loading) >= MAX_INCLUDE_DEPTH:
            self.diag.error(inc.pos, f"includes nested more than {MAX_INCLUDE_DEPTH} deep")
        elif found is not None:
            loaded = self.load(found, inc.pos)
            if loaded is not None:
                inc.params_file = found

    def _find(self, f: ParamsFile, folder_part: str, name: str) -> Path | None:
        """Where the C++ compiler would have found the header's source: the including file's
        folder and the -I folders; then the folders above the including file and their
        `src/` (Miro's builds gave `-I$MIRO_ROOT -I$MIRO_ROOT/src`), with the header's folder
        (`miro/X.xml`); then the first folders without it. `SvcParameters.xml` last of all in a
        `params/` folder above the including file (the project's own, as in a clone of
        miro-gen, which compiles it too), else in the copy miro-gen ships."""
        sub = f"{folder_part}/{name}" if folder_part else name
        here = f.path.resolve().parent
        near = [here, *self.include_dirs]
        candidates = [d / sub for d in near]
        candidates += [d / sub for up in here.parents for d in (up, up / "src")]
        if folder_part:
            candidates += [d / name for d in near]
        if name == "SvcParameters.xml":
            candidates += [up / "params" / name for up in (here, *here.parents)]
            if self.builtin is not None:
                candidates.append(self.builtin / name)
        me = f.path.resolve()
        for candidate in candidates:
            if candidate.is_file() and candidate.resolve() != me:
                return candidate
        return None

    def _item(self, f: ParamsFile, elem: etree._Element, group: str | None) -> None:
        pos = f.pos(elem.sourceline)
        for attr in elem.attrib:
            if attr not in _ITEM_ATTRS:
                self.diag.warning(pos, f"config_item attribute {attr!r} is not known; ignored")
        name = (elem.get("name") or "").strip()
        dummy = _flag(elem, "dummy", f, self.diag) is True
        # a dummy item names an existing type, which may be scoped (ACE_TTY_IO::Serial_Params)
        if name and not (_SCOPED if dummy else _IDENT).match(name):
            self.diag.error(pos, f"config_item name {name!r} is not an identifier")
            return
        item = ItemDecl(
            name=name.lstrip(":"),
            pos=pos,
            file=f,
            namespace=f.namespace,
            parent=(elem.get("parent") or "").strip() or None,
            final=_flag(elem, "final", f, self.diag) is not False,
            dummy=dummy,
            extern=_flag(elem, "extern", f, self.diag) is True,
            instance=_flag(elem, "instance", f, self.diag) is True,
            group=group,
            doc=_doc(elem),
        )
        if item.dummy and not name:
            self.diag.error(pos, "a dummy config_item needs the name of the type it describes")
            return
        # `parent="Mcp::"`: the item without a name of namespace Mcp (Mcp::Parameters)
        if item.parent and not _SCOPED.match(item.parent.removesuffix("::")):
            self.diag.error(pos, f"parent {item.parent!r} is not a C++ class name")
            return
        classes = self._classes.setdefault(f.path, {})
        other = classes.get(item.class_name)
        if other is not None:
            self.diag.error(
                pos, f"{item.class_name} is defined twice (first on line {other.pos.line})"
            )
            return
        seen: dict[str, ParamDecl] = {}
        for child in elem:
            if not isinstance(child.tag, str) or child.tag == "documentation":
                continue
            if child.tag == "config_parameter":
                p = self._param(f, child)
                if p is None:
                    continue
                if p.attr in seen:
                    self.diag.error(
                        p.pos,
                        f"parameter {p.name!r} is declared twice in {item.class_name} "
                        f"(first on line {seen[p.attr].pos.line})",
                    )
                    continue
                seen[p.attr] = p
                item.params.append(p)
            elif child.tag == "constructor":
                text = child.text or ""
                # the statements start where the text starts: on the <constructor> line
                item.constructors.append(Constructor(text, f.pos(child.sourceline, 1)))
            else:
                self._unexpected(f, child, "config_item")
        f.items.append(item)
        classes[item.class_name] = item

    def _param(self, f: ParamsFile, elem: etree._Element) -> ParamDecl | None:
        pos = f.pos(elem.sourceline)
        for attr in elem.attrib:
            if attr not in _PARAM_ATTRS:
                self.diag.warning(pos, f"config_parameter attribute {attr!r} is not known; ignored")
        name = (elem.get("name") or "").strip()
        type_ = (elem.get("type") or "").strip()
        if not _IDENT.match(name):
            self.diag.error(pos, f"config_parameter name {name!r} is not an identifier")
            return None
        if not type_:
            self.diag.error(pos, f"config_parameter {name!r} needs a type")
            return None
        values = elem.get("values")
        default = elem.get("default")
        if default is not None and not default.strip() and not _is_text_type(type_):
            default = None  # `member()`: C++ value-initialises it, as without a default
        return ParamDecl(
            name=name,
            type=type_,
            pos=pos,
            default=default,
            measure=(elem.get("measure") or "").strip() or None,
            # Miro's Enumeration splits them at spaces; commas and bars are read too
            values=[v for v in re.split(r"[\s,|]+", values) if v] if values is not None else None,
            static_const=_flag(elem, "static_const", f, self.diag) is True,
            inherited=_flag(elem, "inherited", f, self.diag) is True,
            doc=_doc(elem),
        )


def _is_text_type(cxx: str) -> bool:
    """Types whose `default=` makeParams quoted (an empty one is an empty string)."""
    return cxx in ("string", "std::string", "QString", "CORBA::String")
