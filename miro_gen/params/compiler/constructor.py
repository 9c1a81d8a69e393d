"""`<constructor>` blocks: C++-like default-building statements compiled into Python.

The statements are parsed with `constructor.lark` and translated, statement by statement, into
Python source that the template puts into the class's `_construct` method: the input text is
never executed. Names are resolved at compile time (members of the item and its parents, local
constants, loop variables, `M_PI`, IDL constants such as `Miro::RangeSensor::GROUPWISE`), paths
are typed through the parameter classes and IDL structs, and anything outside the subset is an
error naming the file, the line and the construct.
"""

from __future__ import annotations

from typing import Any

import lark

from miro_gen.diagnostics import Diagnostics, SourcePos
from miro_gen.params.compiler.ctor_exprs import (
    ConstructorError,
    ExprTranslator,
    Members,
    Val,
    annotation_of,
    bare_arg,
    kind_of,
    source_text,
)
from miro_gen.params.compiler.cxx_numbers import parse_number
from miro_gen.params.compiler.expressions import parser
from miro_gen.params.compiler.model import ItemDecl
from miro_gen.params.compiler.nesting import MAX_NESTING, too_deep


def compile_constructor(
    item: ItemDecl, builder: Members, diag: Diagnostics, skip_untranslatable: bool = False
) -> list[str]:
    """The Python statements of an item's `<constructor>` blocks (errors in `diag`): one
    C++ constructor body, so a block sees the locals of the blocks before it.

    makeParams pasted the blocks into C++, so a real file may hold C++ beyond the subset
    translated here. That is an error (with a note on the way out), or, with
    `skip_untranslatable`, a warning and a class without its constructor: its declared defaults."""
    own = Diagnostics(max_errors=1 << 30)  # the limit is checked in `diag`
    translator: Translator | None = None
    out: list[str] = []
    for block in item.constructors:
        deep = too_deep(block.text)
        if deep is not None:
            own.error(
                _pos(block.pos, *deep), f"constructor: brackets nested more than {MAX_NESTING} deep"
            )
            continue
        try:
            tree = parser().parse(block.text, start="start")
            if translator is None:
                translator = Translator(item, builder, block.pos, own)
            translator.start = block.pos
            out += translator.statements(tree.children, 0)
        except lark.exceptions.UnexpectedInput as e:
            got = _describe(e)
            own.error(_pos(block.pos, e.line, e.column), f"constructor: unexpected {got}")
        except RecursionError:
            own.error(block.pos, "constructor: the block is nested too deeply")
    errors = [d for d in own.items if d.severity == "error"]
    if not errors:
        diag.items += own.items
        return out
    name = item.scoped_name or item.name or "the item"
    if skip_untranslatable:
        first = errors[0]
        diag.warning(
            first.pos,
            f"{first.message}; the constructor of {name} is left out "
            "(--skip-untranslatable): its members keep their declared defaults",
        )
        return []
    beyond = [d for d in errors if "unexpected" in d.message or "not supported" in d.message]
    for d in own.items:
        diag.items.append(d)
        if beyond and d is beyond[0]:  # C++ the subset lacks, not a mistake in the block
            diag.note(
                d.pos,
                "miro-params translates a subset of C++ (docs/PARAMS.md, Constructor blocks): "
                "rewrite the block in it, or pass --skip-untranslatable to generate "
                f"{name} without its constructor",
            )
    diag.check_limit()
    return out


def _describe(e: lark.exceptions.UnexpectedInput) -> str:
    token = getattr(e, "token", None)
    if token is not None:
        return "end of block" if token.type == "$END" else repr(str(token))
    char = getattr(e, "char", None)
    return repr(char) if char else "input"


def _pos(start: SourcePos, line: int, col: int) -> SourcePos:
    """Lark's position inside the block -> the file's: the block starts on the tag's line."""
    line = max(line, 1)
    return SourcePos(start.path, start.line + line - 1, col if line > 1 else 0)


class Translator(ExprTranslator):
    """Translates the statements of one item's blocks (expressions: `ExprTranslator`)."""

    def __init__(
        self, item: ItemDecl, builder: Members, start: SourcePos, diag: Diagnostics
    ) -> None:
        super().__init__(item, builder, diag)
        self.start = start

    # -- statements ---------------------------------------------------------------------------

    def statements(self, nodes: list[Any], depth: int) -> list[str]:
        out: list[str] = []
        for node in nodes:
            if not isinstance(node, lark.Tree):
                continue
            try:
                out += self.statement(node, depth)
            except ConstructorError as e:
                self.diag.error(_pos(self.start, e.line, e.col), f"constructor: {e}")
        return out

    def statement(self, node: lark.Tree[Any], depth: int) -> list[str]:
        pad = "    " * depth
        kind = node.data
        if kind == "empty":
            return []
        if kind == "block":
            self.scopes.append({})
            try:
                return self.statements(node.children, depth)
            finally:
                self.scopes.pop()
        if kind == "array_decl":
            return [pad + line for line in self.array_decl(node)]
        if kind == "var_decl":
            return [pad + line for line in self.var_decl(node)]
        if kind == "assign":
            return [pad + self.assign(node)]
        if kind == "call_stmt":
            return [pad + self.call_stmt(node)]
        if kind == "incdec":
            return [pad + self.incdec(node)]
        if kind == "for_stmt":
            return self.for_stmt(node, depth)
        if kind == "if_stmt":
            return self.if_stmt(node, depth)
        raise ConstructorError(node.meta, f"{kind} statements are not supported")

    def _local_name(self, name: str, meta: Any) -> str:
        if "::" in name:
            raise ConstructorError(meta, f"a local variable cannot be called {name!r}")
        return f"_l_{name}"

    def array_decl(self, node: lark.Tree[Any]) -> list[str]:
        children = [c for c in node.children if c is not None]
        ctype = next(c for c in children if isinstance(c, lark.Tree) and c.data == "ctype")
        rest = children[children.index(ctype) + 1 :]
        name = str(rest[0])
        size_tokens = [c for c in rest[1:] if isinstance(c, lark.Token) and c.type == "NUMBER"]
        values = [self.expr(c) for c in rest[1:] if isinstance(c, lark.Tree)]
        kind = self.ctype(ctype)
        codes = [self.convert(v, kind, node.meta, f"an element of {name}") for v in values]
        if size_tokens:
            size = parse_number(str(size_tokens[0]))
            if not isinstance(size, int) or size < len(values):
                raise ConstructorError(
                    node.meta, f"{name}[{size_tokens[0]}] is given {len(values)} values"
                )
            if size > 100_000:
                raise ConstructorError(node.meta, f"{name}[{size}] is too large")
            # C++ value-initialises the elements not given
            zero = {"int": "0", "float": "0.0", "bool": "False", "str": '""'}.get(kind, "0")
            codes += [zero] * (size - len(codes))
        local = self._local_name(name, node.meta)
        self.scopes[-1][name] = Val(local, "array", element=kind)
        if not codes:
            return [f"{local}: tuple[{annotation_of(kind)}, ...] = ()"]
        body = ", ".join(codes) + ("," if len(codes) == 1 else "")
        return [f"{local} = ({body})"]

    def var_decl(self, node: lark.Tree[Any]) -> list[str]:
        children = [c for c in node.children if c is not None]
        ctype = next(c for c in children if isinstance(c, lark.Tree) and c.data == "ctype")
        name_token, value_node = children[children.index(ctype) + 1 :]
        kind = self.ctype(ctype)
        value = self.expr(value_node)
        code = self.convert(value, kind, node.meta, str(name_token))
        local = self._local_name(str(name_token), node.meta)
        self.scopes[-1][str(name_token)] = Val(local, kind)
        return [f"{local}: {annotation_of(kind)} = {code}"]

    def assign(self, node: lark.Tree[Any]) -> str:
        path_node, op, value_node = node.children
        target = self.path(path_node)
        value = self.expr(value_node)
        op = str(op)
        if target.kind == "array":
            raise ConstructorError(node.meta, "a local array cannot be assigned to")
        if target.type is None and target.kind not in ("int", "float", "bool", "str", "parity"):
            raise ConstructorError(node.meta, f"cannot assign to {source_text(path_node)}")
        if op == "=":
            code = self.convert(value, target.kind, node.meta, source_text(path_node), target.type)
            return f"{target.code} = {code}"
        if target.kind not in ("int", "float") and not (target.kind == "str" and op == "+="):
            raise ConstructorError(node.meta, f"{op} needs a number (got {source_text(path_node)})")
        if op == "/=" and target.kind == "int":
            return f"{target.code} = _rt.cxx_div({target.code}, {value.code})"
        rhs = self.convert(value, target.kind, node.meta, source_text(path_node), target.type)
        return f"{target.code} {op} {rhs}"

    def incdec(self, node: lark.Tree[Any]) -> str:
        tokens = [c for c in node.children if isinstance(c, lark.Token)]
        path_node = next(c for c in node.children if isinstance(c, lark.Tree))
        target = self.path(path_node)
        if target.kind != "int":
            raise ConstructorError(node.meta, f"{tokens[0]} needs an integer")
        return f"{target.code} {'+' if str(tokens[0]) == '++' else '-'}= 1"

    def call_stmt(self, node: lark.Tree[Any]) -> str:
        path_node = node.children[0]
        args = [self.expr(a) for a in node.children[1:] if isinstance(a, lark.Tree)]
        segments = path_node.children
        if len(segments) < 2 or not (
            isinstance(segments[-1], lark.Tree) and segments[-1].data == "member"
        ):
            raise ConstructorError(
                node.meta, f"calling {source_text(path_node)}() is not supported"
            )
        method = str(segments[-1].children[0])
        owner_node = lark.Tree("path", segments[:-1], path_node.meta)
        owner = self.path(owner_node)
        t = owner.type
        if t is None or t.element is None:
            raise ConstructorError(
                node.meta, f"{source_text(owner_node)}.{method}() needs a vector or set member"
            )
        if method in ("length", "resize") and not t.unique:
            if len(args) != 1 or args[0].kind != "int":
                raise ConstructorError(node.meta, f"{method}() takes one integer")
            return f"_rt.resize({owner.code}, {args[0].code}, {self.factory(t.element)})"
        if method in ("push_back", "insert") and len(args) == 1:
            code = self.convert(args[0], kind_of(t.element), node.meta, method, t.element)
            return f"{owner.code}.{'add' if t.unique else 'append'}({bare_arg(code)})"
        if method == "clear" and not args:
            return f"{owner.code}.clear()"
        raise ConstructorError(node.meta, f"{method}() is not supported on {t.spelling}")

    def for_stmt(self, node: lark.Tree[Any], depth: int) -> list[str]:
        init, var, cmp, bound_node, step, body = node.children
        init_children = [c for c in init.children if not isinstance(c, lark.Tree)]
        name, start_node = str(init_children[0]), init.children[-1]
        if str(var) != name:
            raise ConstructorError(node.meta, f"the loop tests {var}, not its variable {name}")
        start = self.expr(start_node)
        bound = self.expr(bound_node)
        step_value = self.step(step, name)
        for v, what in ((start, "start"), (bound, "bound")):
            if v.kind != "int":
                raise ConstructorError(node.meta, f"the loop's {what} must be an integer")
        cmp = str(cmp)
        down = step_value.startswith("-")
        if (cmp in ("<", "<=") and down) or (cmp in (">", ">=") and not down):
            raise ConstructorError(node.meta, "the loop never ends")
        end = {
            "<": bound.code,
            "<=": f"{bound.code} + 1",
            ">": bound.code,
            ">=": f"{bound.code} - 1",
        }.get(cmp)
        if end is None:
            raise ConstructorError(node.meta, f"a loop condition with {cmp} is not supported")
        local = self._local_name(name, node.meta)
        step_arg = "" if step_value == "1" else f", {step_value}"
        self.scopes.append({name: Val(local, "int")})
        try:
            inner = self.statements([body], depth + 1)
        finally:
            self.scopes.pop()
        pad = "    " * depth
        return [f"{pad}for {local} in range({start.code}, {end}{step_arg}):"] + (
            inner or [pad + "    pass"]
        )

    def if_stmt(self, node: lark.Tree[Any], depth: int) -> list[str]:
        cond_node, then, *rest = [c for c in node.children if c is not None]
        cond = self.expr(cond_node)
        if cond.kind not in ("bool", "int", "float"):
            raise ConstructorError(node.meta, f"an if needs a condition (got a {cond.kind})")
        pad = "    " * depth
        out = [f"{pad}if {cond.code}:"] + (self.statements([then], depth + 1) or [pad + "    pass"])
        if rest:
            out += [f"{pad}else:"] + (self.statements(rest, depth + 1) or [pad + "    pass"])
        return out

    def step(self, node: lark.Tree[Any], name: str) -> str:
        tokens = [c for c in node.children if isinstance(c, lark.Token)]
        names = [str(t) for t in tokens if t.type == "NAME"]
        if names != [name]:
            raise ConstructorError(node.meta, f"the loop must step its variable {name}")
        if node.data == "step_incdec":
            op = next(str(t) for t in tokens if t.type == "INCDEC")
            return "1" if op == "++" else "-1"
        op = next(str(t) for t in tokens if t.type == "STEP_ASSIGN")
        amount = self.expr(node.children[-1])
        if amount.constant is None or amount.kind != "int" or amount.constant == 0:
            raise ConstructorError(node.meta, "a loop steps by a non-zero integer constant")
        return amount.code if op == "+=" else f"-{amount.code}"
