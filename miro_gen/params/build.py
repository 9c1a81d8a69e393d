"""From the compile-time model to the template context: classes, fields, defaults, inheritance
checks and a definition order in which every class comes after the classes it uses."""

from __future__ import annotations

from pathlib import Path

from miro_gen.diagnostics import Diagnostics
from miro_gen.params.model import ItemDecl, ParamDecl, ParamsFile
from miro_gen.params.pymodel import (
    CONFIG_BASES,
    PyClass,
    PyField,
    PyParamsModule,
    PyType,
    TypeMapper,
    UnsupportedType,
    attr_name,
    idl_module_of,
    literal,
    module_for,
    package_for,
    value_literal,
)


def all_items(files: list[ParamsFile]) -> dict[str, ItemDecl]:
    """Scoped class name -> item, over every loaded file."""
    out: dict[str, ItemDecl] = {}
    for f in files:
        for item in f.items:
            out.setdefault(item.scoped_name, item)
    return out


class ModuleBuilder:
    """Builds the module of one compile-time file."""

    def __init__(
        self,
        f: ParamsFile,
        items: dict[str, ItemDecl],
        modules: dict[Path, tuple[str, str]],
        diag: Diagnostics,
    ) -> None:
        self.f = f
        self.diag = diag
        package, name = modules[f.path.resolve()]
        self.module = PyParamsModule(
            source=f.display, namespace=f.namespace, package=package, name=name
        )
        self.mapper = TypeMapper(f, items, self.module, modules)
        self._field_types: dict[tuple[int, str], PyType] = {}

    def build(self) -> PyParamsModule:
        m = self.module
        classes = [self._class(item) for item in self.f.items if not item.extern]
        m.classes = self._ordered([c for c in classes if c is not None])
        for item in self.f.items:
            if item.group is not None and not item.dummy and not item.extern:
                m.sections.setdefault(item.group, []).append(item.class_name)
        ns = f" (namespace {self.f.namespace})" if self.f.namespace else ""
        m.doc = f"Parameter classes of {self.f.display}{ns}."
        return m

    # -- classes ----------------------------------------------------------------------------

    def _class(self, item: ItemDecl) -> PyClass | None:
        base = "_rt.Config"
        parent_item: ItemDecl | None = None
        if item.parent and item.parent not in CONFIG_BASES:
            parent_item = self.mapper.lookup_parent(item.parent)
            if parent_item is None or parent_item.dummy:
                self.diag.error(
                    item.pos,
                    f"parent {item.parent!r} of {item.class_name} is not a parameter class "
                    "declared in this file or an included one",
                )
                return None
            if parent_item.final:
                self.diag.error(
                    item.pos,
                    f"{item.class_name} inherits from {parent_item.class_name}, which is final "
                    f'(declared on {parent_item.pos}; give it final="false")',
                )
                return None
            base = self.mapper.class_ref(parent_item)
        cls = PyClass(
            decl=item,
            name=item.class_name,
            base=base,
            final=item.final,
            instance=item.instance,
        )
        if item.dummy:
            cls.dummy_target = self.mapper.class_ref(item)
            self._check_idl_type(item)
        cls.doc = item.doc or (
            f"The parameters of {item.file.namespace + '::' if item.file.namespace else ''}"
            f"{item.class_name}" + (f" (section {item.group!r})." if item.group else ".")
        )
        for p in item.params:
            if p.name.startswith("_"):
                self.diag.error(p.pos, f"parameter name {p.name!r} starts with an underscore")
                continue
            if p.inherited:
                t = self._inherited_type(parent_item, p.attr)
                if t is None:
                    self.diag.error(
                        p.pos,
                        f"{p.name} is marked inherited but no parent of {item.class_name} "
                        "declares it",
                    )
                    continue
            else:
                try:
                    t = self.mapper.map(p.type, p)
                except UnsupportedType as e:
                    self.diag.error(p.pos, f"parameter {p.name}: {e}")
                    continue
            if p.values is not None and not t.choices and not (t.element and t.element.choices):
                self.diag.warning(p.pos, f"values= is read for Enumeration types only ({p.name})")
            self._field_types[(id(item), p.attr)] = t
            f = self._field(p, t)
            if f is None:
                continue
            if p.static_const:
                f.constant = True
                cls.constants.append(f)
            else:
                cls.fields.append(f)
        if item.constructor is not None and item.dummy:
            self.diag.error(item.constructor.pos, "a dummy item has no constructor")
        elif item.constructor is not None:
            from miro_gen.params.constructor import compile_constructor

            cls.construct = compile_constructor(item, self, self.diag)
        return cls

    def _check_idl_type(self, item: ItemDecl) -> None:
        """A dummy item names an IDL struct: it must be a dataclass of the generated IDL
        package (a warning when that package cannot be imported here)."""
        import dataclasses
        import importlib

        name = item.scoped_name.split("::")[-1]
        package = idl_module_of(item)
        try:
            module = importlib.import_module(package)
        except ImportError:
            self.diag.warning(
                item.pos, f"cannot import the IDL package {package} to check {item.scoped_name}"
            )
            return
        target = getattr(module, name, None)
        if not (isinstance(target, type) and dataclasses.is_dataclass(target)):
            self.diag.error(
                item.pos,
                f"dummy item {item.scoped_name} names no IDL struct of the generated package "
                f"{package} (compile its IDL file with miro-idl)",
            )
            return
        members = {f.name for f in dataclasses.fields(target)}
        for p in item.params:
            if p.attr not in members:
                self.diag.error(
                    p.pos,
                    f"{item.scoped_name} has no member {p.attr!r} (it has: "
                    + ", ".join(sorted(members))
                    + ")",
                )

    def _inherited_type(self, parent: ItemDecl | None, attr: str) -> PyType | None:
        while parent is not None:
            for p in parent.params:
                if p.attr == attr and not p.inherited:
                    try:
                        return TypeMapper(
                            parent.file, self.mapper.items, self.module, self.mapper.modules
                        ).map(p.type, p)
                    except UnsupportedType:
                        return None
            if not parent.parent or parent.parent in CONFIG_BASES:
                return None
            parent = TypeMapper(
                parent.file, self.mapper.items, self.module, self.mapper.modules
            ).lookup_parent(parent.parent)
        return None

    def field_type(self, item: ItemDecl, attr: str) -> PyType | None:
        """A parameter's type, for the constructor compiler (inherited ones included)."""
        t = self._field_types.get((id(item), attr))
        if t is not None:
            return t
        for p in item.params:
            if p.attr == attr:
                try:
                    return TypeMapper(
                        item.file, self.mapper.items, self.module, self.mapper.modules
                    ).map(p.type, p)
                except UnsupportedType:
                    return None
        if item.parent and item.parent not in CONFIG_BASES:
            parent = TypeMapper(
                item.file, self.mapper.items, self.module, self.mapper.modules
            ).lookup_parent(item.parent)
            if parent is not None:
                return self.field_type(parent, attr)
        return None

    def _field(self, p: ParamDecl, t: PyType) -> PyField | None:
        """A field (or class constant) with its default checked and rendered."""
        default: str | None = None
        factory: str | None = None
        if p.default is not None:
            default = literal(t, p.default, p.pos, self.diag)
            if default is None:
                return None
            if t.is_vector:
                factory, default = f"lambda: {default}", None
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
            attr=attr_name(p.name),
            xml=p.xml_name,
            type=t,
            default=default,
            factory=factory,
            description=description,
            measure=p.measure,
            decl=p,
        )

    def _ordered(self, classes: list[PyClass]) -> list[PyClass]:
        """Source order, except that a class comes after the local classes it uses."""
        by_name = {c.name: c for c in classes}
        done: list[PyClass] = []
        state: dict[str, int] = {}

        def uses(c: PyClass) -> list[str]:
            names = [c.base] if c.base in by_name else []  # (extern items have no class)
            for f in c.fields + c.constants:
                t: PyType | None = f.type
                while t is not None:
                    if t.item is not None and t.item.class_name in by_name:
                        names.append(t.item.class_name)
                    t = t.element
            return names

        def visit(c: PyClass) -> None:
            mark = state.get(c.name)
            if mark == 2:
                return
            if mark == 1:
                self.diag.error(c.decl.pos, f"{c.name} contains itself (recursive parameter types)")
                return
            state[c.name] = 1
            for name in uses(c):
                visit(by_name[name])
            state[c.name] = 2
            done.append(c)

        for c in classes:
            visit(c)
        return done


def build_modules(
    files: list[ParamsFile],
    targets: list[ParamsFile],
    names: dict[Path, str],
    diag: Diagnostics,
) -> list[PyParamsModule]:
    """The modules of `targets` (the files named on the command line); `files` are all loaded
    files (includes too), `names` the `-n` module names given."""
    modules = {
        f.path.resolve(): (package_for(f), module_for(f, names.get(f.path.resolve())))
        for f in files
    }
    items = all_items(files)
    out = []
    for f in targets:
        out.append(ModuleBuilder(f, items, modules, diag).build())
    return out
