"""Reading makeParams compile-time files into the model, includes first.

An include names a C++ header; it stands for the compile-time file or IDL file that header was
generated from: `miro/SvcParameters.h` is `SvcParameters.xml`, `idl/ScanDescriptionC.h` (TAO's
client header) is `ScanDescription.idl`. They are looked for in the including file's folder, then
in the `-I` folders, then in the project's own `params/`. Other headers (`vector`, `ace/...`) are
C++ matters and are ignored. An IDL header needs no IDL file: its types are imported from the
module miro-idl generated for it (`Miro.ScanDescription_idl`).
"""

from __future__ import annotations

import re
from pathlib import Path

from lxml import etree

from miro_gen.diagnostics import Diagnostics, SourcePos
from miro_gen.params.model import Constructor, Include, ItemDecl, ParamDecl, ParamsFile
from miro_gen.params.xmlsafe import XmlError, read_xml

_ITEM_ATTRS = frozenset(["name", "parent", "final", "dummy", "extern", "instance"])
_PARAM_ATTRS = frozenset(
    ["name", "type", "default", "measure", "values", "static_const", "inherited", "fullname"]
)
_INCLUDE_KINDS = ("include", "Include", "src_Include")
_IDENT = re.compile(r"[A-Za-z_]\w*$")
_NAMESPACE = re.compile(r"[A-Za-z_]\w*(::[A-Za-z_]\w*)*$")


def builtin_params_dir() -> Path | None:
    """The project's `params/` (SvcParameters.xml): the checkout's, or the installed copy."""
    here = Path(__file__).resolve()
    for candidate in (here.parents[2] / "params", here.parent / "xml"):
        if (candidate / "SvcParameters.xml").is_file():
            return candidate
    return None


def display_path(path: Path) -> str:
    """Relative to the working folder when inside it, else the file name (no absolute paths
    in generated output)."""
    try:
        return path.resolve().relative_to(Path.cwd().resolve()).as_posix()
    except ValueError:
        return path.name


def _bool(elem: etree._Element, attr: str, default: bool, f: ParamsFile, diag: Diagnostics) -> bool:
    text = elem.get(attr)
    if text is None:
        return default
    t = text.strip().lower()
    if t in ("true", "1", "yes"):
        return True
    if t in ("false", "0", "no"):
        return False
    diag.error(f.pos(elem.sourceline), f"{attr}={text!r}: expected true or false")
    return default


def _doc(elem: etree._Element) -> str | None:
    for child in elem:
        if child.tag == "documentation":
            text = "".join(child.itertext()).strip()
            lines = [line.strip() for line in text.splitlines()]
            return "\n".join(lines) or None
    return None


class Loader:
    """Reads compile-time files (each once) with the files they include."""

    def __init__(self, include_dirs: list[str], diag: Diagnostics) -> None:
        self.include_dirs = [Path(d) for d in include_dirs]
        builtin = builtin_params_dir()
        if builtin is not None:
            self.include_dirs.append(builtin)
        self.diag = diag
        self.files: dict[Path, ParamsFile] = {}
        self._loading: set[Path] = set()

    def load(self, path: Path, pos: SourcePos | None = None) -> ParamsFile | None:
        key = path.resolve()
        if key in self.files:
            return self.files[key]
        if key in self._loading:
            self.diag.error(pos, f"'{path}' is included again while it is read (an include cycle)")
            return None
        self._loading.add(key)
        try:
            tree = read_xml(path)
        except XmlError as e:
            self.diag.items.extend(e.diagnostics)
            return None
        f = ParamsFile(path=path, display=display_path(path))
        self._read(f, tree.getroot())
        self.files[key] = f
        self._loading.discard(key)
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
            if not _NAMESPACE.match(value):
                self.diag.error(pos, f"namespace {value!r} is not a C++ namespace name")
            elif f.namespace:
                self.diag.error(
                    pos, f"a second namespace ({value!r}; the first is {f.namespace!r})"
                )
            else:
                f.namespace = value
        elif name in _INCLUDE_KINDS:
            inc = Include(value, pos, name)
            self._resolve_include(f, inc)
            f.includes.append(inc)
        elif name == "forward":
            f.forwards.append(value)
        elif name == "python_helper":
            # <config_global name="python_helper" type="Miro::Polygon" value="my_pkg.polygon"/>
            cxx = (elem.get("type") or "").strip()
            if not cxx or not re.match(r"[A-Za-z_][\w.]*$", value):
                self.diag.error(pos, 'python_helper needs type="C++ type" and value="module"')
            else:
                f.helpers[cxx] = value
                f.helper_pos[cxx] = pos
        else:
            self.diag.warning(pos, f"config_global {name!r} is not known; ignored")

    def _resolve_include(self, f: ParamsFile, inc: Include) -> None:
        header = inc.value.strip('<>" ')
        base = header.rsplit("/", 1)[-1]
        stem, dot, ext = base.rpartition(".")
        if not dot or ext not in ("h", "hh", "hpp", "xml"):
            return  # <vector>, <set>: C++ only
        folders = [f.path.parent, *self.include_dirs]
        if stem.endswith("C") and ext == "h":  # TAO's client header of an IDL file
            # its types come from the module miro-idl generated for it (<stem>_idl)
            inc.idl_stem = stem[:-1]
            idl = stem[:-1] + ".idl"
            for folder in folders:
                for candidate in (folder / idl, folder / header.rsplit("/", 1)[0] / idl):
                    if candidate.is_file():
                        inc.idl_file = candidate
                        return
            return
        xml = stem + ".xml"
        sub = header.rsplit("/", 1)[0] + "/" + xml if "/" in header else xml
        for folder in folders:
            for candidate in (folder / sub, folder / xml):
                if candidate.is_file() and candidate.resolve() != f.path.resolve():
                    loaded = self.load(candidate, inc.pos)
                    if loaded is not None:
                        inc.params_file = candidate
                    return

    def _item(self, f: ParamsFile, elem: etree._Element, group: str | None) -> None:
        pos = f.pos(elem.sourceline)
        for attr in elem.attrib:
            if attr not in _ITEM_ATTRS:
                self.diag.warning(pos, f"config_item attribute {attr!r} is not known; ignored")
        name = (elem.get("name") or "").strip()
        if name and not _IDENT.match(name):
            self.diag.error(pos, f"config_item name {name!r} is not an identifier")
            return
        item = ItemDecl(
            name=name,
            pos=pos,
            file=f,
            parent=(elem.get("parent") or "").strip() or None,
            final=_bool(elem, "final", True, f, self.diag),
            dummy=_bool(elem, "dummy", False, f, self.diag),
            extern=_bool(elem, "extern", False, f, self.diag),
            instance=_bool(elem, "instance", False, f, self.diag),
            group=group,
            doc=_doc(elem),
        )
        if item.dummy and not name:
            self.diag.error(pos, "a dummy config_item needs the name of the type it describes")
            return
        for other in f.items:
            if other.class_name == item.class_name:
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
                item.constructor = Constructor(text, f.pos(child.sourceline, 1))
            else:
                self._unexpected(f, child, "config_item")
        f.items.append(item)

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
        return ParamDecl(
            name=name,
            type=type_,
            pos=pos,
            default=elem.get("default"),
            measure=(elem.get("measure") or "").strip() or None,
            values=[v.strip() for v in re.split(r"[,|]", values) if v.strip()]
            if values is not None
            else None,
            static_const=_bool(elem, "static_const", False, f, self.diag),
            inherited=_bool(elem, "inherited", False, f, self.diag),
            doc=_doc(elem),
        )
