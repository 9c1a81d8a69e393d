"""Each running service's live parameters as Foxglove parameters, through its service object
(`miro param`'s way): `SERVICE/Section/Category.Parameter` (SERVICE as `miro list` names it,
robot1/gps), its value as the run-time document writes it (a string; a list or a mapping for
vectors and structures).

A set is checked and applied by the service as a run-time document would be: all or nothing
per parameter set (a Category); a refused change leaves the set as it was, and the client is
told why (a status message). Subscribed parameters are read again at every discovery round
and sent when they changed.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any

import foxglove
import MiroService
from lxml import etree

from miro_gen.exceptions import SystemException
from miro_gen.launch.documents import fill_element
from miro_gen.live.remote import Robot, Running
from miro_gen.log import logger

_log = logger("MIRO")
ParamKey = tuple[str, str, str, str]  # service, section, category, parameter


def plain(elem: etree._Element) -> Any:
    """A `<parameter>` element as plain data: its value, a mapping of its named children, or a
    list of its unnamed ones."""
    children = [c for c in elem if isinstance(c.tag, str)]
    if not children:
        return str(elem.get("value", ""))
    if all(c.get("name") is None for c in children):
        return [plain(c) for c in children]
    return {str(c.get("name")): plain(c) for c in children}


def param_name(key: ParamKey) -> str:
    service, section, category, name = key
    return f"{service}/{section}/{category}.{name}"


class Parameters:
    """The Foxglove side of the services' parameter sets."""

    def __init__(self, robot: Robot, report: Callable[[str], object]) -> None:
        self.robot = robot
        self.report = report  # tells the clients why a set was refused
        self._lock = threading.Lock()
        self._services: dict[str, Running] = {}
        self._subscribed: set[str] = set()
        self._last: dict[str, Any] = {}

    def update(self, services: list[Running]) -> None:
        with self._lock:
            self._services = {
                s.name: s
                for s in services
                if s.description is not None and s.description.parameters
            }

    # ---- reading ---------------------------------------------------------------------------------

    def _sets(self) -> list[tuple[Running, str, str]]:
        with self._lock:
            services = list(self._services.values())
        return [
            (s, p.section, p.category)
            for s in services
            if s.description is not None
            for p in s.description.parameters
        ]

    def _read(self, service: Running, section: str, category: str) -> etree._Element | None:
        try:
            stub = self.robot.service_at(service.entry.endpoint)
            text = stub.get_parameters(section, category)
        except (MiroService.NotFound, SystemException) as e:
            _log.debug("foxglove: parameters of %s: %s", service.name, e)
            return None
        return etree.fromstring(str(text).encode())

    def values(self, names: list[str] | None = None) -> list[foxglove.Parameter]:
        """The current value of `names` (every parameter when None or empty)."""
        wanted = set(names or ())
        out = []
        for service, section, category in self._sets():
            prefix = f"{service.name}/{section}/{category}."
            if wanted and not any(n.startswith(prefix) for n in wanted):
                continue
            elem = self._read(service, section, category)
            if elem is None:
                continue
            for child in elem:
                if not isinstance(child.tag, str) or child.get("name") is None:
                    continue
                name = prefix + str(child.get("name"))
                if not wanted or name in wanted:
                    out.append(foxglove.Parameter(name, value=plain(child)))
        return out

    # ---- changing --------------------------------------------------------------------------------

    def set(self, changes: list[foxglove.Parameter]) -> list[foxglove.Parameter]:
        """Apply `changes`, a document per parameter set (all or nothing each); the values of
        the parameters named, as they are after."""
        by_set: dict[tuple[str, str, str], list[tuple[str, Any]]] = {}
        unknown = []
        for p in changes:
            service, _, rest = p.name.rpartition("/")
            service, _, section = service.rpartition("/")
            category, _, name = rest.partition(".")
            if not (service and section and category and name):
                unknown.append(p.name)
                continue
            by_set.setdefault((service, section, category), []).append((name, p.get_value()))
        with self._lock:
            services = dict(self._services)
        for (service_name, section, category), values in by_set.items():
            running = services.get(service_name)
            if running is None:
                unknown.extend(f"{service_name}/{section}/{category}.{n}" for n, _ in values)
                continue
            root = etree.Element("parameter", name=category)
            for name, value in values:
                fill_element(etree.SubElement(root, "parameter", name=name), _text(value))
            try:
                stub = self.robot.service_at(running.entry.endpoint)
                stub.set_parameters(section, category, etree.tostring(root, encoding="unicode"))
            except MiroService.InvalidParameters as e:
                self.report(
                    f"{service_name} refused {section}/{category}: " + "; ".join(e.problems)
                )
            except (MiroService.NotFound, SystemException) as e:
                self.report(f"{service_name}: {section}/{category}: {e}")
        if unknown:
            self.report(f"no such parameters: {', '.join(sorted(unknown))}")
        return self.values([p.name for p in changes])

    # ---- subscriptions ---------------------------------------------------------------------------

    def subscribe(self, names: list[str]) -> None:
        with self._lock:
            self._subscribed.update(names)

    def unsubscribe(self, names: list[str]) -> None:
        with self._lock:
            self._subscribed.difference_update(names)
            for n in names:
                self._last.pop(n, None)

    def changed(self) -> list[foxglove.Parameter]:
        """The subscribed parameters whose value changed since they were last sent."""
        with self._lock:
            names = sorted(self._subscribed)
        if not names:
            return []
        out = []
        for p in self.values(names):
            value = p.get_value()
            with self._lock:
                if p.name not in self._subscribed or self._last.get(p.name) == value:
                    continue
                self._last[p.name] = value
            out.append(p)
        return out

    def sent(self, params: list[foxglove.Parameter]) -> None:
        """`params` were sent to the clients: a later change is measured from them."""
        with self._lock:
            for p in params:
                if p.name in self._subscribed:
                    self._last[p.name] = p.get_value()


def _text(value: Any) -> Any:
    """A client's value as a document writes it (booleans as true/false; lists and mappings
    as they are, their items likewise)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, dict):
        return {k: _text(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_text(v) for v in value]
    return value
