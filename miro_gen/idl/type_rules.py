"""Type references and constant values in IDL declarations: named types resolved to their
declarations (complete, not recursive without a sequence), bounds and array sizes, constant
expressions evaluated with names looked up from their scope, annotations checked.

`TypeRules` is the resolver's third layer, on `RepositoryIds`; inline struct, union and enum
definitions in a type spec are handed back to the resolver's `_definition`."""

from __future__ import annotations

from typing import Any

from miro_gen.diagnostics import Diagnostics, SourcePos
from miro_gen.idl import ast
from miro_gen.idl.constants import (
    ANY,
    ARRAY_BOUND_MAX,
    FLOAT_TYPES,
    INT_RANGES,
    EvalError,
    Evaluator,
    Target,
)
from miro_gen.idl.repository_ids import RepositoryIds
from miro_gen.idl.scopes import Frame, Scope
from miro_gen.idl.type_queries import (
    article,
    incomplete_forward,
    is_type,
    kind_of_const,
    type_text,
    unalias,
)

KNOWN_ANNOTATIONS = frozenset(
    [
        "id",
        "autoid",
        "optional",
        "position",
        "value",
        "extensibility",
        "final",
        "appendable",
        "mutable",
        "key",
        "must_understand",
        "default_literal",
        "default",
        "range",
        "min",
        "max",
        "unit",
        "bit_bound",
        "external",
        "nested",
        "verbatim",
        "service",
        "oneway",
        "ami",
        "hashid",
        "topic",
        "data_representation",
        "non_serialized",
        "ignore_literal_names",
        "try_construct",
        "choice",
        "empty",
    ]
)
# Integer-valued annotations and their ranges (DDS-XTypes 1.3: member ids have 28 bits).
_ANNOTATION_LIMITS = {"id": 0x0FFFFFFF, "position": 0xFFFF, "bit_bound": 64}


class TypeRules(RepositoryIds):
    """Resolves type specs, evaluates constants, checks annotations."""

    def __init__(self, diag: Diagnostics, case_sensitive: bool = False) -> None:
        super().__init__(diag, case_sensitive)
        self.defining: list[ast.Decl] = []  # structs/unions whose bodies are being resolved
        self.in_typedef = 0
        self.user_annotations: set[str] = set()
        self.evaluator = Evaluator(self._lookup_constant, diag)

    def _definition(self, d: Any, scope: Scope, frame: Frame) -> None:
        """Resolve one definition (the resolver's; inline types in a type spec come here)."""
        raise NotImplementedError  # pragma: no cover - miro_gen.idl.resolver.Resolver

    def _type(
        self,
        t: Any,
        scope: Scope,
        role: str,
        *,
        frame: Frame | None = None,
        in_sequence: bool = False,
        allow_bare_fixed: bool = False,
    ) -> Any:
        """Resolve a type spec; inline struct/union/enum definitions are declared in `scope`."""
        if isinstance(t, ast.BaseType):
            return t
        if isinstance(t, ast.NamedType):
            entry = self.lookup(t.name, scope)
            if entry is None:
                return t
            node = entry.node
            if isinstance(node, ast.BaseType):  # CORBA::TypeCode and the other built-ins
                return node
            if not is_type(node):
                self.diag.error(t.name.pos, f"'{t.name}' is {article(entry.what)}, not a type")
                self.diag.note(entry.pos, f"'{entry.name}' declared here")
                return t
            t.decl = node
            self._check_complete(t, node, in_sequence)
            return t
        if isinstance(t, ast.StringType):
            if t.bound_expr is not None:
                t.bound = self._positive(t.bound_expr, "string bound", scope)
            return t
        if isinstance(t, ast.SequenceType):
            t.element = self._type(
                t.element, scope, "sequence element type", frame=frame, in_sequence=True
            )
            if t.bound_expr is not None:
                t.bound = self._positive(t.bound_expr, "sequence bound", scope)
            return t
        if isinstance(t, ast.FixedType):
            if t.digits_expr is None or t.scale_expr is None:
                if not allow_bare_fixed:
                    self.diag.error(
                        t.pos, "'fixed' needs digits and scale here: fixed<DIGITS, SCALE>"
                    )
                return t
            digits = self._eval(t.digits_expr, Target("int", "unsigned short"), scope)
            scale = self._eval(t.scale_expr, Target("int", "unsigned short"), scope)
            if isinstance(digits, int) and isinstance(scale, int):
                if not 1 <= digits <= 31:
                    self.diag.error(t.pos, f"fixed-point types have 1 to 31 digits, not {digits}")
                elif scale > digits:
                    self.diag.error(
                        t.pos, f"fixed-point scale {scale} is larger than its {digits} digits"
                    )
                t.digits, t.scale = digits, scale
            return t
        if isinstance(t, ast.MapType):
            t.key = self._type(t.key, scope, "map key type", frame=frame, in_sequence=True)
            t.value = self._type(t.value, scope, "map value type", frame=frame, in_sequence=True)
            if t.bound_expr is not None:
                t.bound = self._positive(t.bound_expr, "map bound", scope)
            return t
        if isinstance(t, (ast.Struct, ast.Union_, ast.Enum)):
            if frame is None:
                self.diag.error(t.pos, f"a {t.kind} cannot be defined in a {role}")
                return t
            self._definition(t, scope, frame)
            return ast.NamedType(ast.ScopedName(t.scope_path, True, t.pos), decl=t)
        raise TypeError(f"unexpected type node {type(t).__name__}")  # pragma: no cover

    def _check_complete(self, t: ast.NamedType, node: Any, in_sequence: bool) -> None:
        if isinstance(node, ast.Forward) and node.of in ("struct", "union"):
            if node.full is not None:
                return
            if not in_sequence:
                self.diag.error(
                    t.name.pos,
                    f"cannot use forward-declared {node.of} '{t.name}' before it is fully defined",
                )
            elif not self.in_typedef and not self._being_defined(node):
                self.diag.error(
                    t.name.pos,
                    f"cannot use a sequence of forward-declared {node.of} '{t.name}' outside "
                    "its own definition before it is fully defined",
                )
            return
        if isinstance(node, (ast.Struct, ast.Union_)) and node in self.defining and not in_sequence:
            self.diag.error(
                t.name.pos,
                f"{node.kind} '{node.name}' cannot contain itself (recursion needs a sequence)",
            )
            return
        if isinstance(node, ast.Typedef) and not self.in_typedef:
            fwd = incomplete_forward(node.type, set())
            if fwd is not None and not self._being_defined(fwd):
                self.diag.error(
                    t.name.pos,
                    f"cannot use '{t.name}' here: it holds forward-declared {fwd.of} "
                    f"'{fwd.scoped_name}', which is not yet fully defined",
                )

    def _being_defined(self, fwd: ast.Forward) -> bool:
        return any(d.scope_path == fwd.scope_path for d in self.defining)

    def _eval(self, expr: ast.Expr, target: Target, scope: Scope) -> ast.ConstValue | None:
        """Evaluate a constant expression whose names are looked up from `scope`."""
        prev = self._scope
        self._scope = scope
        try:
            return self.evaluator.evaluate(expr, target)
        finally:
            self._scope = prev

    def _positive(self, expr: ast.Expr, what: str, scope: Scope) -> int | None:
        v = self._eval(expr, ANY, scope)
        if v is not None and (not isinstance(v, int) or isinstance(v, bool)):
            shown = v.scoped_name if isinstance(v, ast.EnumValue) else repr(v)
            self.diag.error(expr.pos, f"{what} must be a positive integer, not {shown}")
            return None
        if isinstance(v, int):
            if v <= 0:
                self.diag.error(expr.pos, f"{what} must be positive, not {v}")
                return None
            if v > ARRAY_BOUND_MAX:
                self.diag.error(expr.pos, f"{what} {v} is too large (maximum {ARRAY_BOUND_MAX})")
                return None
            return v
        return None

    def _dims(self, exprs: list[ast.Expr], scope: Scope) -> list[int]:
        out: list[int] = []
        for e in exprs:
            v = self._positive(e, "array size", scope)
            out.append(v if v is not None else 1)
        return out

    def _const_target(self, typ: Any, pos: SourcePos) -> Target | None:
        t = unalias(typ)
        if isinstance(t, ast.NamedType) and t.decl is None:
            return None  # an unresolved name, already reported
        if isinstance(t, ast.Typedef):  # aliased array
            self.diag.error(pos, "a constant cannot have an array type")
            return None
        if isinstance(t, ast.BaseType):
            n = t.name
            if n in INT_RANGES:
                return Target("int", n)
            if n in FLOAT_TYPES:
                return Target("float", n)
            if n == "char":
                return Target("char", n)
            if n == "wchar":
                return Target("wchar", n)
            if n == "boolean":
                return Target("bool", n)
        elif isinstance(t, ast.StringType):
            return Target("wstring" if t.wide else "string", str(t), bound=t.bound)
        elif isinstance(t, ast.FixedType):
            return Target("fixed", "fixed", bound=t.digits, scale=t.scale)
        elif isinstance(t, ast.Enum):
            return Target("enum", t.scoped_name, enum=t)
        self.diag.error(pos, f"constants of type {type_text(typ)} are not allowed")
        return None

    def _lookup_constant(self, ref: ast.NameRef) -> tuple[str, ast.ConstValue]:
        entry = self.lookup(ref.name, self._scope)
        if entry is None:
            raise EvalError(ref.pos, "")  # already reported by lookup
        node = entry.node
        if isinstance(node, ast.Enumerator) and node.enum is not None:
            return "enum", ast.EnumValue(node.enum, node.name, node.ordinal)
        if isinstance(node, ast.Const):
            if node.value is None:
                raise EvalError(ref.pos, f"constant '{ref.name}' has no valid value")
            return kind_of_const(node, unalias(node.type)), node.value
        raise EvalError(ref.pos, f"'{ref.name}' is {article(entry.what)}, not a constant")

    def _annotations(self, anns: list[ast.Annotation], scope: Scope) -> None:
        if not anns:
            return
        prev = self._scope
        self._scope = scope
        try:
            self._annotations_in_scope(anns)
        finally:
            self._scope = prev

    def _annotations_in_scope(self, anns: list[ast.Annotation]) -> None:
        for a in anns:
            name = a.short_name
            if name not in KNOWN_ANNOTATIONS and name not in self.user_annotations:
                self.diag.warning(
                    a.pos, f"unknown annotation '@{a.name}' (kept, but it has no effect)"
                )
            for key, expr in a.args.items():
                value = self._annotation_arg(expr)
                if value is not None:
                    a.params[key] = value
            if name in _ANNOTATION_LIMITS:
                v = a.params.get("value")
                limit = _ANNOTATION_LIMITS[name]
                if not isinstance(v, int) or isinstance(v, bool) or not 0 <= v <= limit:
                    self.diag.error(a.pos, f"@{name} needs an integer from 0 to {limit}")

    def _annotation_arg(self, expr: ast.Expr) -> ast.ConstValue | None:
        # A bare identifier that names nothing is an enumerator-like word (FINAL, SEQUENTIAL, ...).
        if isinstance(expr, ast.NameRef) and len(expr.name.parts) == 1 and not expr.name.absolute:
            key = self._fold(expr.name.parts[0])
            s: Scope | None = self._scope
            found = False
            while s is not None and not found:
                found = bool(self._find_in(s, key))
                s = s.parent
            if not found:
                return expr.name.parts[0]
        return self.evaluator.evaluate(expr, ANY)
