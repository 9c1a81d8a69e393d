"""From the compile-time model to the template context: classes, fields, defaults, parents
and a definition order in which every class comes after the classes it needs.

Parents and types are looked up as the C++ compiler looked them up: from the file's namespace
outwards, over every loaded file (the file itself and those its `include` globals reached).
makeParams appends `Parameters` to a parent's name (`parent="Dev"` is `DevParameters`), and
`Config` / `Miro::Config` is Miro's base class: `Miro::ConfigParameters` when a loaded file
declares it, else the runtime's `Config`.

A `dummy` item is declared for the tools and written by hand, so no class is generated for it.
Where a generated class derives from one or holds one, the class it stands for is, in order:
the runtime's (`ACE_TTY_IO::Serial_Params`, `ACE_Sched_Params`); the hand-written class named
by a `python_class` global (imported when the module is imported, with an error naming the
module and class to write when it is missing); the IDL struct of that name (a generated IDL
dataclass, read and written by a layout made from the item); else a stand-in made from the
item's declared parameters, private to the module that needs it.
"""

from __future__ import annotations

import contextlib
import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

from miro_gen.diagnostics import Diagnostics
from miro_gen.params.compiler.constructor import compile_constructor
from miro_gen.params.compiler.defaults import DefaultCompiler, value_literal
from miro_gen.params.compiler.expressions import Value
from miro_gen.params.compiler.model import ItemDecl, ParamDecl, ParamsFile
from miro_gen.params.compiler.ordering import order_classes
from miro_gen.params.compiler.pymodel import (
    RUNTIME_STRUCTS,
    HandWritten,
    PyClass,
    PyField,
    PyParamsModule,
    PyType,
    TypeMapper,
    UnsupportedType,
    alias_for,
    attr_name,
    idl_constant,
    idl_struct_of,
    module_for,
    package_for,
    runtime_struct,
)

CONFIG_BASES = frozenset(["Config", "Miro::Config", "ConfigParameters", "Miro::ConfigParameters"])


class Scope:
    """Every loaded item under its C++ names, and C++ name lookup from a file's namespace."""

    def __init__(self, files: list[ParamsFile], python_classes: dict[str, str]) -> None:
        self.items: dict[str, ItemDecl] = {}
        self.implicit: dict[str, ItemDecl] = {}  # parents only hand-written headers declare
        self.python_classes = dict(python_classes)  # -P TYPE=MODULE: before the files' own
        for f in files:
            for item in f.items:
                self.items.setdefault(item.scoped_name, item)
                if item.dummy and not item.scoped_name.endswith("Parameters"):
                    self.items.setdefault(item.scoped_name + "Parameters", item)
            for cxx, module in f.python_classes.items():
                self.python_classes.setdefault(cxx, module)

    def lookup(self, f: ParamsFile, name: str) -> ItemDecl | None:
        """The file's namespace and its enclosing ones, then the global one."""
        if name.startswith("::"):
            return self.items.get(name[2:])
        scopes = f.namespace.split("::") if f.namespace else []
        for i in range(len(scopes), -1, -1):
            found = self.items.get("::".join([*scopes[:i], name]))
            if found is not None:
                return found
        return None

    def parent_of(self, item: ItemDecl) -> ItemDecl | None:
        """The parent item (None for Miro's `Config` when no file declares it, or none).

        A parent no loaded file declares (`Arbiter`) whose header the file includes and no
        compile-time file stands for (`miro/ArbiterParameters.h`) was written by hand there,
        as for a dummy item: it becomes an implicit dummy item without parameters."""
        if not item.parent:
            return None
        found = self.lookup(item.file, item.parent + "Parameters") or self.lookup(
            item.file, item.parent
        )
        if found is None and item.parent.lstrip(":") not in CONFIG_BASES:
            found = self._implicit(item)
        return found if found is not item else None

    def _implicit(self, item: ItemDecl) -> ItemDecl | None:
        assert item.parent is not None
        f = item.file
        name = item.parent.removesuffix("::").lstrip(":")
        short = name.rsplit("::", 1)[-1].removesuffix("Parameters")
        if f"{short}Parameters" not in hand_written_headers(f):
            return None
        ns = "" if item.parent.startswith("::") or "::" in name else f.namespace
        key = f"{ns}::{name}" if ns else name
        found = self.implicit.get(key)
        if found is None:
            found = ItemDecl(
                name=name.removesuffix("Parameters"), pos=item.pos, file=f, namespace=ns, dummy=True
            )
            self.implicit[key] = found
        return found


@dataclass
class DummyKind:
    """What a dummy item stands for (see the module docstring)."""

    kind: Literal["runtime", "python", "idl", "stand-in"]
    module: str = ""  # python: the module; idl: the dataclass's module
    cls: str = ""  # the class's name in that module


class ModuleBuilder:
    """Builds the module of one compile-time file."""

    def __init__(
        self,
        f: ParamsFile,
        scope: Scope,
        modules: dict[Path, tuple[str, str]],
        diag: Diagnostics,
        tools: bool = False,
        skip_untranslatable: bool = False,
    ) -> None:
        self.f = f
        self.scope = scope
        self.modules = modules
        self.diag = diag
        self.tools = tools  # for --xsd and show/validate: every dummy item gets a stand-in
        # constructors beyond the translated C++ subset: left out with a warning, not errors
        self.skip_untranslatable = skip_untranslatable or tools
        package, name = modules[f.path.resolve()]
        self.module = PyParamsModule(
            source=f.display, namespace=f.namespace, package=package, name=name
        )
        self._field_types: dict[tuple[int, str], PyType | None] = {}
        self._stand_ins: dict[int, PyClass | None] = {}
        self._kinds: dict[int, DummyKind] = {}
        self._classes: list[PyClass] = []

    def mapper(self, f: ParamsFile) -> TypeMapper:
        """Maps types as `f` spells them; imports go to this module."""
        return TypeMapper(f, self.module, self._resolve)

    def build(self) -> PyParamsModule:
        m = self.module
        for item in self.f.items:
            if item.extern:
                continue
            if not item.dummy:
                c = self._class(item)
                if c is not None:
                    self._classes.append(c)
            elif self.kind(item).kind == "idl":
                self._classes.append(self._layout(item))
            elif self.tools and self.kind(item).kind == "stand-in":
                self.stand_in(item)
        m.classes = order_classes(self._classes, self.diag)
        for item in self.f.items:
            if item.group is not None and not item.dummy and not item.extern:
                m.sections.setdefault(item.group, []).append(item.class_name)
        ns = f" (namespace {self.f.namespace})" if self.f.namespace else ""
        m.doc = f"Parameter classes of {self.f.display}{ns}."
        return m

    # -- names of classes ---------------------------------------------------------------------

    def _resolve(self, f: ParamsFile, name: str) -> PyType | None:
        item = self.scope.lookup(f, name)
        return None if item is None else self.item_type(item)

    def item_type(self, item: ItemDecl) -> PyType:
        """The type of a field holding an item's class."""
        if not item.dummy:
            ref = self.class_ref(item)
            return PyType(item.scoped_name, ref, factory=ref, item=item, struct_target=ref)
        kind = self.kind(item)
        if kind.kind == "runtime":
            t = runtime_struct(item.scoped_name)
            assert t is not None
            return t
        if kind.kind == "idl":
            ref = f"{self.mapper(self.f).import_module(kind.module)}.{kind.cls}"
            layout = self._local_or_imported(item, f"{kind.cls}_xml")
            return PyType(item.scoped_name, ref, factory=ref, item=item, struct_target=layout)
        hand = self.dummy_ref(item)
        if hand is None:
            raise UnsupportedType(f"{item.scoped_name} (a dummy item) cannot be used here")
        return PyType(item.scoped_name, hand, factory=hand, item=item, struct_target=hand)

    def class_ref(self, item: ItemDecl) -> str:
        """How this module names a generated item's class (importing its module)."""
        if item.extern:
            package = package_for(item.file)
            return f"{self.mapper(self.f).import_module(package)}.{item.class_name}"
        return self._local_or_imported(item, item.class_name)

    def _local_or_imported(self, item: ItemDecl, name: str) -> str:
        if item.file is self.f:
            return name
        package, module = self.modules[item.file.path.resolve()]
        full = f"{package}.{module}"
        self.module.sources[full] = item.file.display
        return f"{self.mapper(self.f).import_module(full)}.{name}"

    def kind(self, item: ItemDecl) -> DummyKind:
        """What a dummy item stands for (cached)."""
        found = self._kinds.get(id(item))
        if found is None:
            found = self._kinds[id(item)] = self._kind(item)
        return found

    def _kind(self, item: ItemDecl) -> DummyKind:
        name = item.scoped_name
        if name in RUNTIME_STRUCTS:
            return DummyKind("runtime", cls=RUNTIME_STRUCTS[name])
        named = None if self.tools else self.scope.python_classes.get(name)
        if named is not None:
            module, _, cls = named.partition(":")
            return DummyKind("python", module, cls or item.hand_written_name)
        idl = idl_struct_of(item)
        if idl is not None:
            return DummyKind("idl", idl[0], idl[1].__name__)
        return DummyKind("stand-in")

    def dummy_ref(self, item: ItemDecl) -> str | None:
        """How this module names the class a dummy item stands for as a parent."""
        kind = self.kind(item)
        if kind.kind == "runtime":
            return f"_rt.{kind.cls}"
        if kind.kind == "python":
            alias = "_h_" + alias_for(f"{kind.module}.{kind.cls}").removeprefix("_m_")
            self.module.hand_written[alias] = HandWritten(
                alias, kind.module, kind.cls, item.scoped_name, str(item.pos)
            )
            return alias
        if kind.kind == "stand-in":
            c = self.stand_in(item)
            return None if c is None else c.name
        return None  # an IDL struct is no parameter class

    def parent_ref(self, item: ItemDecl) -> tuple[str, ItemDecl | None] | None:
        """(base class expression, parent item) of a generated class; None after an error."""
        parent = self.scope.parent_of(item)
        if parent is None:
            if item.parent and item.parent.lstrip(":") not in CONFIG_BASES:
                self.diag.error(
                    item.pos,
                    f"parent {item.parent!r} of {item.class_name} is not a parameter class "
                    "declared in this file or an included one",
                )
                return None
            return "_rt.Config", None
        if not parent.dummy:
            return self.class_ref(parent), parent
        if parent in self.scope.implicit.values() and id(parent) not in self._kinds:
            self.diag.warning(
                item.pos,
                f"{item.class_name}'s parent {item.parent} is declared in no compile-time file; "
                f"it is written by hand in a header this file includes, as for a dummy item",
            )
        ref = self.dummy_ref(parent)
        if ref is None:
            self.diag.error(
                item.pos,
                f"{item.class_name} derives from {parent.scoped_name}, an IDL struct "
                f"(dummy item declared on {parent.pos}); a parameter class cannot",
            )
            return None
        return ref, parent

    # -- classes ------------------------------------------------------------------------------

    def _class(
        self, item: ItemDecl, stand_in: bool = False, name: str | None = None
    ) -> PyClass | None:
        base = self.parent_ref(item)
        if base is None:
            return None
        cls = PyClass(
            decl=item,
            name=name or item.class_name,
            base=base[0],
            abstract=not item.final,
            instance=item.instance and item.final and not stand_in,
            stand_in=stand_in,
        )
        if item.instance and not item.final:
            self.diag.warning(
                item.pos, f'{item.class_name} is abstract (final="false"): no instance()'
            )
        ns = item.namespace if item.dummy else item.file.namespace
        scoped = f"{ns}::{item.name}" if ns else item.name or "(unnamed)"
        if stand_in:
            cls.doc = (
                f"Stand-in for the hand-written class of the dummy item {scoped} "
                f"({item.pos}), made from its declared parameters. Name your own class with "
                f'<config_global name="python_class" type="{item.scoped_name}" value="module"/>.'
            )
        else:
            where = f" (section {item.group!r})" if item.group else ""
            cls.doc = item.doc or f"The parameters of {scoped}{where}."
            if cls.abstract:
                cls.doc += '\n\nAbstract (final="false"): a base of other parameter classes.'
        self._members(item, cls, base[1])
        if item.constructors and not stand_in:
            cls.construct = compile_constructor(item, self, self.diag, self.skip_untranslatable)
        return cls

    def _members(self, item: ItemDecl, cls: PyClass, parent: ItemDecl | None) -> None:
        for p in item.params:
            defaults = DefaultCompiler(self.diag, ConstantLookup(self, item, p))
            if p.name.startswith("_"):
                self.diag.error(p.pos, f"parameter name {p.name!r} starts with an underscore")
                continue
            t = self._param_type(item, p, parent)
            if t is None:
                continue
            if p.inherited:  # the parent's unit and description, unless given again
                declared = self._declared_in(parent, p.attr)
                if declared is not None:
                    original = next(q for q in declared[0].params if q.attr == p.attr)
                    p = dataclasses.replace(
                        p, measure=p.measure or original.measure, doc=p.doc or original.doc
                    )
            if p.values is not None and not t.choices and not (t.element and t.element.choices):
                self.diag.warning(p.pos, f"values= is read for Enumeration types only ({p.name})")
            f = self._field(p, t, defaults)
            if f is None:
                continue
            if p.static_const:
                f.constant = True
                cls.constants.append(f)
            else:
                cls.fields.append(f)

    def _param_type(self, item: ItemDecl, p: ParamDecl, parent: ItemDecl | None) -> PyType | None:
        if p.inherited:
            declared = self._declared_in(parent, p.attr)
            if declared is not None:
                return self.field_type(*declared)
            if self._known_chain(parent):
                self.diag.error(
                    p.pos,
                    f"{p.name} is marked inherited but no parent of {item.class_name} declares it",
                )
                return None
        try:
            t = self.mapper(item.file).map(p.type, p)
        except UnsupportedType as e:
            self.diag.error(p.pos, f"parameter {p.name}: {e}")
            return None
        self._field_types[(id(item), p.attr)] = t
        return t

    def _field(self, p: ParamDecl, t: PyType, defaults: DefaultCompiler) -> PyField | None:
        """A field (or class constant) with its default checked and rendered."""
        default: str | None = None
        factory: str | None = None
        if p.default is not None:
            default, factory = defaults.expression(t, p.default, p.pos)
            if default is None and factory is None:
                return None
        elif t.factory is not None:
            factory = t.factory
        elif t.runtime is not None:
            default = value_literal(t.runtime, t.runtime.default())
        else:  # pragma: no cover - every type has one or the other
            self.diag.error(p.pos, f"no default for {t.spelling}")
            return None
        parts = [p.doc or ""]
        if p.measure:
            parts.append(f"[{p.measure}]")
        description = " ".join(x for x in parts if x) or None
        return PyField(
            attr=p.attr if p.static_const else attr_name(p.name),
            xml=p.xml_name,
            type=t,
            default=default,
            factory=factory,
            description=description,
            measure=p.measure,
            decl=p,
        )

    def _constant_lookup(self, item: ItemDecl) -> ConstantLookup:
        return ConstantLookup(self, item)

    def _layout(self, item: ItemDecl) -> PyClass:
        """The run-time layout of an IDL struct a dummy item describes."""
        kind = self.kind(item)
        target = f"{self.mapper(self.f).import_module(kind.module)}.{kind.cls}"
        cls = PyClass(decl=item, name=kind.cls, base="", dummy_target=target)
        self._check_idl_members(item)
        defaults = DefaultCompiler(self.diag)
        for p in item.params:
            t = self._param_type(item, p, None)
            if t is None:
                continue
            f = self._field(p, t, defaults)
            if f is not None:
                f.attr = p.attr  # the IDL member's own name
                cls.fields.append(f)
        return cls

    def _check_idl_members(self, item: ItemDecl) -> None:
        import dataclasses

        found = idl_struct_of(item)
        assert found is not None
        members = {f.name for f in dataclasses.fields(found[1])}
        for p in item.params:
            if p.attr not in members:
                self.diag.error(
                    p.pos,
                    f"{item.scoped_name} has no member {p.attr!r} (it has: "
                    + ", ".join(sorted(members))
                    + ")",
                )

    def stand_in(self, item: ItemDecl) -> PyClass | None:
        """This module's stand-in for a dummy item (made once, when first needed)."""
        if id(item) in self._stand_ins:
            return self._stand_ins[id(item)]
        self._stand_ins[id(item)] = None  # a dummy deriving from itself finds no class
        taken = {c.name for c in self._classes} | {i.class_name for i in self.f.items}
        name = item.hand_written_name
        while name in taken:
            name = "_" + name
        c = self._class(item, stand_in=True, name=name)
        self._stand_ins[id(item)] = c
        if c is not None:
            self._classes.append(c)
        return c

    # -- what the constructor compiler asks ---------------------------------------------------

    def _declared_in(self, item: ItemDecl | None, attr: str) -> tuple[ItemDecl, str] | None:
        """The item (this one or a parent) that declares a parameter, by member name."""
        seen: set[int] = set()
        while item is not None and id(item) not in seen:
            seen.add(id(item))
            for p in item.params:
                if p.attr == attr and not p.inherited and not p.static_const:
                    return item, attr
            item = self.scope.parent_of(item)
        return None

    def _known_chain(self, item: ItemDecl | None) -> bool:
        """Whether every class above is declared here (not hand-written or an IDL struct)."""
        seen: set[int] = set()
        while item is not None and id(item) not in seen:
            seen.add(id(item))
            if item.extern or (item.dummy and self.kind(item).kind != "stand-in"):
                return False
            item = self.scope.parent_of(item)
        return True

    def field_type(self, item: ItemDecl, attr: str) -> PyType | None:
        """The type of a parameter an item declares (mapped as its file spells it)."""
        key = (id(item), attr)
        if key not in self._field_types:
            self._field_types[key] = None
            for p in item.params:
                if p.attr == attr and not p.inherited:
                    with contextlib.suppress(UnsupportedType):
                        self._field_types[key] = self.mapper(item.file).map(p.type, p)
        return self._field_types[key]

    def member(self, item: ItemDecl, name: str) -> tuple[str, PyType] | None:
        """(Python attribute, type) of a member of an item or of its parents."""
        want = name[:1].lower() + name[1:]
        found = self._declared_in(item, want)
        if found is None:
            return None
        owner, attr = found
        t = self.field_type(owner, attr)
        if t is None:
            return None
        idl = owner.dummy and self.kind(owner).kind == "idl"
        p = next(p for p in owner.params if p.attr == attr and not p.inherited)
        return (p.attr if idl else attr_name(p.name)), t

    def import_module(self, module: str) -> str:
        return self.mapper(self.f).import_module(module)

    def singleton(self, item: ItemDecl, name: str) -> tuple[str, ItemDecl] | None:
        """A parameter class with `instance()`, as `item`'s file names it."""
        found = self.scope.lookup(item.file, name) or self.scope.lookup(
            item.file, name + "Parameters"
        )
        if found is None or found.dummy or not found.instance or not found.final:
            return None
        if found is item:
            return None  # its own instance() is being made
        return self.class_ref(found), found


def hand_written_headers(f: ParamsFile) -> list[str]:
    """The stems of the headers a file includes that stand for no compile-time or IDL file:
    where classes written by hand come from (`ArbiterParameters` for
    `botsvcs/BAP/ArbiterParameters.h`)."""
    return [
        i.value.rsplit("/", 1)[-1].split(".")[0]
        for i in f.includes
        if i.params_file is None and i.idl_stem is None
    ]


class ConstantLookup:
    """Names a `default=` may use beyond the built-in constants, as C++ member initialisers
    saw them: the item's `static_const` parameters and its parents', the numbers and bools
    declared before it (and its parents'), and IDL constants (`Miro::RangeSensor::GROUPWISE`)."""

    _NUMERIC = frozenset(
        ["bool", "short", "unsigned short", "int", "unsigned int", "unsigned", "long",
         "unsigned long", "long long", "unsigned long long", "float", "double"]
    )  # fmt: skip

    def __init__(self, builder: ModuleBuilder, item: ItemDecl, before: ParamDecl | None = None):
        self.builder = builder
        self.item = item
        self.before = before  # members declared before this one are initialised already
        self._busy: set[str] = set()

    def __call__(self, name: str) -> Value | None:
        item: ItemDecl | None = self.item
        seen: set[int] = set()
        while item is not None and id(item) not in seen:
            seen.add(id(item))
            for p in item.params:
                if item is self.item and p is self.before:
                    break  # not yet initialised
                usable = p.static_const or (p.type in self._NUMERIC and not p.inherited)
                if p.attr == name and p.default and name not in self._busy and usable:
                    return self._value(p)
            item = self.builder.scope.parent_of(item)
        if "::" in name:  # an IDL constant: Miro::RangeSensor::GROUPWISE
            found = idl_constant(name)
            if found is not None and isinstance(found[2], (bool, int, float, str)):
                return found[2]
        return None

    def _value(self, p: ParamDecl) -> Value | None:
        from miro_gen.params.compiler.expressions import ExprError, evaluate_args

        self._busy.add(p.attr)
        try:
            values = evaluate_args(p.default or "", self)
        except ExprError:
            return None
        finally:
            self._busy.discard(p.attr)
        return values[0] if len(values) == 1 else None


def build_modules(
    files: list[ParamsFile],
    targets: list[ParamsFile],
    names: dict[Path, str],
    diag: Diagnostics,
    python_classes: dict[str, str] | None = None,
    tools: bool = False,
    skip_untranslatable: bool = False,
) -> list[PyParamsModule]:
    """The modules of `targets` (the files named on the command line); `files` are all loaded
    files (includes too), `names` the `-n` module names given; `skip_untranslatable`: see
    `compile_constructor`."""
    modules = {
        f.path.resolve(): (package_for(f), module_for(f, names.get(f.path.resolve())))
        for f in files
    }
    first: dict[tuple[str, str], ParamsFile] = {}
    clash = False
    for f in files:
        key = modules[f.path.resolve()]
        other = first.setdefault(key, f)
        if other is not f:
            clash = True
            same = other.display == f.display
            a, b = (other.path, f.path) if same else (other.display, f.display)
            diag.error(
                None,
                f"{a} and {b} would both be the module {'.'.join(key)} "
                "(its namespace and file name); rename one, or give it another name with -n",
            )
    if clash:
        diag.check()
    scope = Scope(files, python_classes or {})
    return [
        ModuleBuilder(f, scope, modules, diag, tools, skip_untranslatable).build() for f in targets
    ]
