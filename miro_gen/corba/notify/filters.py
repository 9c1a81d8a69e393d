"""Filters of a notification channel: the default filter factory, its filters, and the filter
lists that admins and proxies keep (CosNotifyFilter).

A filter holds constraints, each a list of event types (empty: any) and an expression in the
constraint language (`constraints.lark`: `$domain_name == 'robot1' and $type_name == 'Gps'`,
`or`, `not`, `~`, comparisons, the `$.header.fixed_header...` spellings). An event matches a
filter when one of its constraints matches it; a filter list passes an event when it is empty
or one of its filters matches. Expressions are compiled into Python closures once, when
added; nothing of them is executed. What a peer adds is bounded: constraints per filter,
expression length, filters per factory and per list.

Only filters of this channel's factory can be added to its admins and proxies (BAD_PARAM
otherwise): they are evaluated in-process, on the thread that routes the event, never through
a remote call that could stall the channel.
"""

from __future__ import annotations

import functools
import itertools
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any, ClassVar, NamedTuple

import lark

from miro_gen.corba.ior import IOR
from miro_gen.corba.notify.wire import (
    ANY_TYPE,
    FILTER,
    FILTER_ADMIN,
    FILTER_FACTORY,
    ConstraintNotFound,
    EventType,
    FilterNotFound,
    InvalidConstraint,
    InvalidGrammar,
    read_event_types,
    read_head,
    write_event_types,
)
from miro_gen.corba.servants import HandServant
from miro_gen.exceptions import BAD_PARAM, NO_IMPLEMENT, NO_RESOURCES
from miro_gen.runtime import rpc
from miro_gen.runtime.cdrstream import CdrInput, CdrOutput

GRAMMARS = ("EXTENDED_TCL", "TCL", "ETCL")
MAX_EXPRESSION = 4096  # characters of a constraint expression
MAX_CONSTRAINTS = 1000  # per filter
MAX_FILTERS = 1000  # per factory, and per filter list


class Fields(NamedTuple):
    """What a constraint can test of an event."""

    domain: str
    type_name: str
    event_name: str


Value = str | float | bool | None  # None: the event has no such field
Term = Callable[[Fields], Value]
Predicate = Callable[[Fields], bool]

_FIELDS: dict[str, Callable[[Fields], Value]] = {
    "$domain_name": lambda f: f.domain,
    "$type_name": lambda f: f.type_name,
    "$event_name": lambda f: f.event_name,
    "$.header.fixed_header.event_type.domain_name": lambda f: f.domain,
    "$.header.fixed_header.event_type.type_name": lambda f: f.type_name,
    "$.header.fixed_header.event_name": lambda f: f.event_name,
}
_COMPARE: dict[str, Callable[[Any, Any], bool]] = {
    "==": lambda a, b: bool(a == b),
    "!=": lambda a, b: bool(a != b),
    "<": lambda a, b: bool(a < b),
    "<=": lambda a, b: bool(a <= b),
    ">": lambda a, b: bool(a > b),
    ">=": lambda a, b: bool(a >= b),
    "~": lambda a, b: isinstance(a, str) and isinstance(b, str) and a in b,
}


def _truth(term: Term) -> Predicate:
    return lambda f: term(f) is True


class _Compile(lark.Transformer[Any, Any]):
    """A constraint's tree as closures: operands to `Term`s, the rest to `Predicate`s."""

    def string(self, items: list[lark.Token]) -> Term:
        text = str(items[0])[1:-1].replace("\\'", "'").replace("\\\\", "\\")
        return lambda f: text

    def number(self, items: list[lark.Token]) -> Term:
        value = float(items[0])
        return lambda f: value

    def true(self, items: list[lark.Token]) -> Term:
        return lambda f: True

    def false(self, items: list[lark.Token]) -> Term:
        return lambda f: False

    def component(self, items: list[lark.Token]) -> Term:
        return _FIELDS.get(str(items[0]), lambda f: None)  # absent: comparisons are false

    def compare(self, items: list[Any]) -> Term:
        a, op, b = items
        test = _COMPARE[str(op)]

        def compare(f: Fields) -> bool:
            x, y = a(f), b(f)
            if x is None or y is None or isinstance(x, bool) != isinstance(y, bool):
                return False
            if isinstance(x, str) != isinstance(y, str):
                return False
            return test(x, y)

        return compare

    def and_(self, items: list[Term]) -> Term:
        a, b = _truth(items[0]), _truth(items[1])
        return lambda f: a(f) and b(f)

    def or_(self, items: list[Term]) -> Term:
        a, b = _truth(items[0]), _truth(items[1])
        return lambda f: a(f) or b(f)

    def not_(self, items: list[Term]) -> Term:
        a = _truth(items[0])
        return lambda f: not a(f)


@functools.cache
def _parser() -> lark.Lark:
    grammar = Path(__file__).with_name("constraints.lark").read_text()
    return lark.Lark(grammar, parser="lalr", transformer=_Compile())


def compile_constraint(expression: str) -> Predicate:
    """The predicate of a constraint expression; ValueError saying why it is not one."""
    if len(expression) > MAX_EXPRESSION:
        raise ValueError(f"longer than {MAX_EXPRESSION} characters")
    if not expression.strip():
        return lambda f: True  # an empty expression: every event of its types
    try:
        term: Term = _parser().parse(expression)  # type: ignore[assignment]
    except lark.exceptions.LarkError as e:
        raise ValueError(str(e).splitlines()[0]) from None
    return _truth(term)


class Constraint(NamedTuple):
    types: list[EventType]
    expression: str
    test: Predicate

    def matches(self, fields: Fields) -> bool:
        if self.types and not any(t.matches(fields.domain, fields.type_name) for t in self.types):
            return False
        return self.test(fields)


def _read_constraint(inp: CdrInput) -> tuple[list[EventType], str, Predicate]:
    types = read_event_types(inp)
    expression = inp.string("constraint")
    try:
        return types, expression, compile_constraint(expression)
    except ValueError as e:
        raise InvalidConstraint(types, expression[:MAX_EXPRESSION], str(e)) from None


def _write_info(out: CdrOutput, ident: int, c: Constraint) -> None:
    write_event_types(out, c.types)
    out.string(c.expression)
    out.long(ident)


class Filter(HandServant):
    """A filter made by the channel's factory (CosNotifyFilter::Filter)."""

    _repo_id = FILTER
    _operations: ClassVar[tuple[str, ...]] = (
        "_get_constraint_grammar",
        "add_constraints",
        "modify_constraints",
        "get_constraints",
        "get_all_constraints",
        "remove_all_constraints",
        "destroy",
        "match",
        "match_structured",
        "match_typed",
        "attach_callback",
        "detach_callback",
        "get_callbacks",
    )

    def __init__(self, factory: FilterFactory, grammar: str, key: bytes) -> None:
        self.factory = factory
        self.grammar = grammar
        self.key = key
        self._constraints: dict[int, Constraint] = {}
        self._ids = itertools.count(1)
        self._lock = threading.Lock()

    def matches(self, fields: Fields) -> bool:
        """Whether one of the constraints matches (none: nothing matches)."""
        return any(c.matches(fields) for c in list(self._constraints.values()))

    @rpc.nonblocking
    def _get_constraint_grammar(self, inp: CdrInput) -> CdrOutput:
        out = CdrOutput()
        out.string(self.grammar)
        return out

    @rpc.nonblocking
    def add_constraints(self, inp: CdrInput) -> CdrOutput:
        n = inp.length(8, "constraints")
        parsed = [_read_constraint(inp) for _ in range(n)]  # all or none
        out = CdrOutput()
        with self._lock:
            if len(self._constraints) + n > MAX_CONSTRAINTS:
                raise NO_RESOURCES(f"a filter holds at most {MAX_CONSTRAINTS} constraints")
            out.ulong(n)
            for types, expression, test in parsed:
                ident = next(self._ids)
                c = self._constraints[ident] = Constraint(types, expression, test)
                _write_info(out, ident, c)
        return out

    @rpc.nonblocking
    def modify_constraints(self, inp: CdrInput) -> None:
        deleted = [inp.long() for _ in range(inp.length(4, "constraint ids"))]
        changed = []
        for _ in range(inp.length(12, "constraints")):
            types, expression, test = _read_constraint(inp)
            changed.append((inp.long(), Constraint(types, expression, test)))
        with self._lock:
            for ident in [*deleted, *(i for i, _ in changed)]:
                if ident not in self._constraints:
                    raise ConstraintNotFound(ident)
            for ident in deleted:
                del self._constraints[ident]
            for ident, c in changed:
                self._constraints[ident] = c

    @rpc.nonblocking
    def get_constraints(self, inp: CdrInput) -> CdrOutput:
        wanted = [inp.long() for _ in range(inp.length(4, "constraint ids"))]
        found = dict(self._constraints)
        for ident in wanted:
            if ident not in found:
                raise ConstraintNotFound(ident)
        out = CdrOutput()
        out.ulong(len(wanted))
        for ident in wanted:
            _write_info(out, ident, found[ident])
        return out

    @rpc.nonblocking
    def get_all_constraints(self, inp: CdrInput) -> CdrOutput:
        found = sorted(self._constraints.items())
        out = CdrOutput()
        out.ulong(len(found))
        for ident, c in found:
            _write_info(out, ident, c)
        return out

    @rpc.nonblocking
    def remove_all_constraints(self, inp: CdrInput) -> None:
        with self._lock:
            self._constraints.clear()

    @rpc.nonblocking
    def destroy(self, inp: CdrInput) -> None:
        self.factory.forget(self)

    @rpc.nonblocking
    def match(self, inp: CdrInput) -> CdrOutput:
        out = CdrOutput()  # a plain `any` has no header: type %ANY, no domain
        out.boolean(self.matches(Fields("", ANY_TYPE, "")))
        return out

    @rpc.nonblocking
    def match_structured(self, inp: CdrInput) -> CdrOutput:
        head = read_head(inp)
        out = CdrOutput()
        out.boolean(self.matches(Fields(head.domain, head.type_name, head.event_name)))
        return out

    def match_typed(self, inp: CdrInput) -> None:
        raise NO_IMPLEMENT("typed events are not supported")

    def attach_callback(self, inp: CdrInput) -> None:
        raise NO_IMPLEMENT("filter callbacks are not supported")

    def detach_callback(self, inp: CdrInput) -> None:
        raise NO_IMPLEMENT("filter callbacks are not supported")

    @rpc.nonblocking
    def get_callbacks(self, inp: CdrInput) -> CdrOutput:
        out = CdrOutput()
        out.ulong(0)
        return out


class Activator:
    """What filters need of their channel: serving objects under keys of its own."""

    def activate(self, servant: rpc.Servant, suffix: str) -> IOR:  # pragma: no cover
        raise NotImplementedError

    def deactivate(self, suffix: str) -> None:  # pragma: no cover
        raise NotImplementedError


class FilterFactory(HandServant):
    """The channel's default filter factory (CosNotifyFilter::FilterFactory)."""

    _repo_id = FILTER_FACTORY
    _operations: ClassVar[tuple[str, ...]] = ("create_filter", "create_mapping_filter")

    def __init__(self, activator: Activator) -> None:
        self.activator = activator
        self._filters: dict[bytes, Filter] = {}
        self._ids = itertools.count(1)
        self._lock = threading.Lock()

    @rpc.nonblocking
    def create_filter(self, inp: CdrInput) -> CdrOutput:
        grammar = inp.string("grammar")
        if grammar not in GRAMMARS:
            raise InvalidGrammar()
        with self._lock:
            if len(self._filters) >= MAX_FILTERS:
                raise NO_RESOURCES(f"at most {MAX_FILTERS} filters per channel")
            suffix = f"F{next(self._ids)}"
            f = Filter(self, grammar, suffix.encode())
            ior = self.activator.activate(f, suffix)
            key = ior.iiop_profile().key  # type: ignore[union-attr]
            self._filters[key] = f
        out = CdrOutput()
        ior.write(out)
        return out

    def create_mapping_filter(self, inp: CdrInput) -> None:
        raise NO_IMPLEMENT("mapping filters are not supported")

    def local(self, ior: IOR) -> Filter | None:
        """The filter of this factory that `ior` names, if any."""
        profile = ior.iiop_profile()
        return None if profile is None else self._filters.get(profile.key)

    def forget(self, f: Filter) -> None:
        with self._lock:
            for key, known in list(self._filters.items()):
                if known is f:
                    del self._filters[key]
        self.activator.deactivate(f.key.decode())


class FilterList:
    """The filters an admin or a proxy holds (CosNotifyFilter::FilterAdmin's state)."""

    def __init__(self, factory: FilterFactory) -> None:
        self.factory = factory
        self._filters: dict[int, tuple[Filter, IOR]] = {}
        self._ids = itertools.count(1)
        self._lock = threading.Lock()

    def __bool__(self) -> bool:
        return bool(self._filters)

    def passes(self, fields: Fields) -> bool:
        """Whether an event passes: no filters, or one of them matches it."""
        filters = list(self._filters.values())
        return not filters or any(f.matches(fields) for f, _ in filters)

    def add(self, ior: IOR) -> int:
        f = self.factory.local(ior)
        if f is None:
            raise BAD_PARAM("only filters made by this channel's default_filter_factory")
        with self._lock:
            if len(self._filters) >= MAX_FILTERS:
                raise NO_RESOURCES(f"at most {MAX_FILTERS} filters here")
            ident = next(self._ids)
            self._filters[ident] = (f, ior)
        return ident

    def remove(self, ident: int) -> None:
        with self._lock:
            if self._filters.pop(ident, None) is None:
                raise FilterNotFound()

    def get(self, ident: int) -> IOR:
        found = self._filters.get(ident)
        if found is None:
            raise FilterNotFound()
        return found[1]

    def ids(self) -> list[int]:
        return sorted(self._filters)

    def clear(self) -> None:
        with self._lock:
            self._filters.clear()


class FilterAdmin(HandServant):
    """CosNotifyFilter::FilterAdmin's operations, on `self.filters`."""

    _interfaces = frozenset({FILTER_ADMIN})
    _operations: ClassVar[tuple[str, ...]] = (
        "add_filter",
        "remove_filter",
        "get_filter",
        "get_all_filters",
        "remove_all_filters",
    )
    filters: FilterList

    @rpc.nonblocking
    def add_filter(self, inp: CdrInput) -> CdrOutput:
        ident = self.filters.add(IOR.read(inp))
        self.filters_changed()
        out = CdrOutput()
        out.long(ident)
        return out

    @rpc.nonblocking
    def remove_filter(self, inp: CdrInput) -> None:
        self.filters.remove(inp.long())
        self.filters_changed()

    @rpc.nonblocking
    def get_filter(self, inp: CdrInput) -> CdrOutput:
        out = CdrOutput()
        self.filters.get(inp.long()).write(out)
        return out

    @rpc.nonblocking
    def get_all_filters(self, inp: CdrInput) -> CdrOutput:
        ids = self.filters.ids()
        out = CdrOutput()
        out.ulong(len(ids))
        for ident in ids:
            out.long(ident)
        return out

    @rpc.nonblocking
    def remove_all_filters(self, inp: CdrInput) -> None:
        self.filters.clear()
        self.filters_changed()

    def filters_changed(self) -> None:
        """The filters changed (the channel routes anew)."""
