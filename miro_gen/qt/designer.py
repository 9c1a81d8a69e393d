"""Qt Designer forms at run time (the manual's §11.1 without uic): load a `.ui` file with
QUiLoader and bind its widgets to events and polled calls by their object names, so there is
no generated code to keep in sync with the form.

Object names (Designer allows letters, digits and `_`; `__` separates the parts):

    event__TYPE__FIELD__...     shows a field of the latest TYPE event (`event__Gps__latitude`,
                                indices as numbers: `event__Scan__points__3__x`); a FieldsView
                                named `event__TYPE` shows them all, a PlotWidget plots the field
    call__OBJECT__OP            a button that calls operation OP of the object bound as OBJECT
    arg__OBJECT__OP__PARAM      where the call's argument PARAM comes from (spin box, line edit,
                                check box, combo box)
    result__OBJECT__OP[__FIELD] shows the call's result (or a field of it)
    status / statusbar          a QLabel or QStatusBar that shows failed calls

A last part `_N` (`event__Gps__latitude___2`) is ignored, so that two widgets may show the same
thing. Other names are left alone. Anything a name promises that the form cannot do (a button
named like a display, a misspelt operation) is a `UiError` naming the file and the widget.
"""

from __future__ import annotations

import inspect
import re
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from PySide6.QtCore import QFile, QIODevice, QObject, Signal, qInstallMessageHandler
from PySide6.QtUiTools import QUiLoader
from PySide6.QtWidgets import (
    QAbstractButton,
    QCheckBox,
    QComboBox,
    QDial,
    QDoubleSpinBox,
    QLabel,
    QLCDNumber,
    QLineEdit,
    QPlainTextEdit,
    QProgressBar,
    QSlider,
    QSpinBox,
    QStatusBar,
    QTextEdit,
    QWidget,
)

from miro_gen.log import logger
from miro_gen.qt.bridge import QtEventBridge
from miro_gen.qt.calls import CallRunner
from miro_gen.qt.fields import (
    FieldError,
    format_path,
    get_field,
    is_number,
    leaves,
    parse_path,
    show,
)
from miro_gen.qt.widgets import FieldsView, PlotWidget
from miro_gen.runtime.rpc import Stub
from miro_gen.service.server import Client
from miro_gen.transport.events import StructuredEvent

_log = logger("QT")
_COPY = re.compile(r"_\d+")
KINDS = ("event", "call", "arg", "result")


class UiError(Exception):
    """A form that cannot be loaded or bound; the message names the file (and widget)."""


def load_ui(path: str | Path, parent: QWidget | None = None) -> QWidget:
    """The form of a Designer `.ui` file, with miro_gen.qt.widgets available to it."""
    loader = QUiLoader()
    for cls in (PlotWidget, FieldsView):
        loader.registerCustomWidget(cls)
    file = QFile(str(path))
    if not file.open(QIODevice.OpenModeFlag.ReadOnly):
        raise UiError(f"{path}: cannot open: {file.errorString()}")
    said: list[str] = []  # what Qt's form builder reports, kept for the error instead of printed
    previous = qInstallMessageHandler(lambda _kind, _context, message: said.append(message))
    try:
        form = loader.load(file, parent)
    except RuntimeError:  # PySide's way of saying that load() returned nothing
        form = None
    finally:
        qInstallMessageHandler(previous)
        file.close()
    if form is None:
        why = said[-1] if said else loader.errorString()
        raise UiError(f"{path}: not a Qt Designer form: {why.removeprefix('Designer: ')}")
    for message in said:  # loaded, with remarks (a promoted class it does not know, ...)
        _log.warning("%s: %s", path, message.removeprefix("Designer: "))
    return form


@dataclass
class _Name:
    kind: str
    target: str  # the event type, or the object's name
    op: str = ""  # the operation (calls)
    rest: str = ""  # the field path, or the parameter


def parse_name(name: str) -> _Name | None:
    """What a widget's object name asks for; None for names that ask nothing."""
    parts = name.split("__")
    if parts[0] not in KINDS or len(parts) < 2:
        return None
    if len(parts) > 2 and _COPY.fullmatch(parts[-1]):
        parts = parts[:-1]
    kind, target, more = parts[0], parts[1], parts[2:]
    if kind == "event":
        return _Name(kind, target, rest="__".join(more))
    if not more:
        return _Name(kind, target)
    return _Name(kind, target, more[0], "__".join(more[1:]))


def stub_class(repo_id: str) -> type[Stub] | None:
    """The generated stub class of an interface: one imported already, or one that a generated
    package imported already offers (its module is imported then, as packages do lazily)."""
    seen: set[type[Stub]] = set()
    todo: list[type[Stub]] = [Stub]
    while todo:
        cls = todo.pop()
        if cls in seen:
            continue
        seen.add(cls)
        if cls is not Stub and cls.__dict__.get("_repo_id") == repo_id:
            return cls
        todo.extend(cls.__subclasses__())
    # IDL:Miro/Example:1.0 -> Miro.Example (or, under a #pragma prefix, a shorter path)
    path = repo_id.split(":")[1].split("/") if repo_id.count(":") == 2 else []
    for i in range(len(path) - 1):
        package = sys.modules.get(".".join(path[i:-1]))
        if package is not None and isinstance(getattr(package, "_EXPORTS", None), dict):
            found = getattr(package, path[-1], None)
            if (
                isinstance(found, type)
                and issubclass(found, Stub)
                and found.__dict__.get("_repo_id") == repo_id
            ):
                return found
    return None


def display(widget: QWidget, value: Any) -> None:
    """Show `value` in `widget` as that kind of widget shows values."""
    if isinstance(widget, PlotWidget):
        if is_number(value):
            widget.add(float(value))
    elif isinstance(widget, FieldsView):
        widget.show_payload(value)
    elif isinstance(widget, QLCDNumber):
        widget.display(float(value) if is_number(value) else show(value))
    elif isinstance(widget, QProgressBar | QSlider | QDial | QSpinBox):
        if is_number(value):
            widget.setValue(round(value))
    elif isinstance(widget, QDoubleSpinBox):
        if is_number(value):
            widget.setValue(float(value))
    elif isinstance(widget, QCheckBox):
        widget.setChecked(bool(value))
    elif isinstance(widget, QLabel | QLineEdit | QTextEdit | QPlainTextEdit):
        text = show(value) if not list(leaves(value))[1:] else _summary(value)
        if isinstance(widget, QPlainTextEdit):
            widget.setPlainText(text)
        else:
            widget.setText(text)


def _summary(value: Any) -> str:
    return ", ".join(f"{path} = {show(v)}" for path, v in leaves(value))


def _shows_values(widget: QWidget) -> bool:
    kinds = (PlotWidget, FieldsView, QLCDNumber, QProgressBar, QSlider, QDial, QSpinBox)
    more = (QDoubleSpinBox, QCheckBox, QLabel, QLineEdit, QTextEdit, QPlainTextEdit)
    return isinstance(widget, kinds + more)


def _read(widget: QWidget, annotation: str) -> Any:
    """The argument a widget holds, as the parameter's type wants it."""
    if isinstance(widget, QDoubleSpinBox | QSpinBox | QSlider | QDial):
        raw: Any = widget.value()
    elif isinstance(widget, QCheckBox):
        raw = widget.isChecked()
    elif isinstance(widget, QComboBox):
        raw = widget.currentText()
    elif isinstance(widget, QLineEdit):
        raw = widget.text()
    else:
        raise ValueError(f"a {type(widget).__name__} holds no argument")
    try:
        if annotation == "float":
            return float(raw)
        if annotation == "int":
            return int(raw)
        if annotation == "bool":
            return raw if isinstance(raw, bool) else str(raw).lower() in ("1", "true", "yes")
        if annotation == "str":
            return str(raw)
    except ValueError:
        raise ValueError(f"{raw!r} is not a {annotation}") from None
    raise ValueError(f"a widget cannot give a {annotation}")


class FormBinding(QObject):
    """Binds a form's widgets by object name (see the module's doc) to the events of `bridge`
    and to calls made through `client`, on `runner`'s workers. `bind()` does the work; failed
    calls and fields that events lack go to `error` (and the form's status widget)."""

    error = Signal(str)

    def __init__(
        self,
        form: QWidget,
        bridge: QtEventBridge,
        *,
        channel: str = "EventChannel",
        domain: str = "*",
        client: Client | None = None,
        runner: CallRunner | None = None,
        interfaces: dict[str, type[Stub]] | None = None,
        source: str = "form",
    ) -> None:
        super().__init__(form)
        self.form = form
        self.bridge = bridge
        self.channel = channel
        self.domain = domain
        self.client = client if client is not None else _client_of(bridge)
        self.runner = runner if runner is not None else CallRunner(parent=self)
        self.interfaces = dict(interfaces or {})
        self.source = source
        self.bound: list[str] = []
        self._events: dict[str, list[tuple[QWidget, str]]] = {}
        self._results: dict[tuple[str, str], list[tuple[QWidget, str]]] = {}
        self._stubs: dict[str, Stub] = {}
        self._reported: set[str] = set()
        self.status = form.findChild(QWidget, "status") or form.findChild(QWidget, "statusbar")
        self.error.connect(self._show_error)

    # ---- binding --------------------------------------------------------------------------------

    def bind(self) -> list[str]:
        """Bind every widget whose name asks for it; the names bound. Raises UiError (listing
        every problem) when a name asks for something its widget cannot do."""
        problems: list[str] = []
        calls: list[tuple[QAbstractButton, _Name]] = []
        for widget in self.form.findChildren(QWidget):
            name = widget.objectName()
            what = parse_name(name)
            if what is None:
                continue
            try:
                self._check(widget, what)
            except UiError as e:
                problems.append(f"{self.source}: {name}: {e}")
                continue
            if what.kind == "event":
                self._events.setdefault(what.target, []).append((widget, what.rest))
                if isinstance(widget, PlotWidget) and not widget.title:
                    widget.title = f"{what.target} {format_path(parse_path(what.rest))}"
            elif what.kind == "result":
                key = (what.target, what.op)
                self._results.setdefault(key, []).append((widget, what.rest))
            elif what.kind == "call":
                assert isinstance(widget, QAbstractButton)
                calls.append((widget, what))
            self.bound.append(name)
        for button, what in calls:
            try:
                self._check_call(what)
            except UiError as e:
                problems.append(f"{self.source}: {button.objectName()}: {e}")
        if problems:
            raise UiError("\n".join(problems))
        for button, what in calls:
            button.clicked.connect(self._caller(what.target, what.op))
        for type_name in self._events:
            sub = self.bridge.subscribe([(self.domain, type_name)], self.channel)
            sub.received.connect(self._on_event)
        return list(self.bound)

    def _check(self, widget: QWidget, what: _Name) -> None:
        if what.kind in ("call", "arg", "result") and not what.op:
            raise UiError(f"names no operation ({what.kind}__OBJECT__OPERATION...)")
        try:
            parse_path(what.rest)
        except ValueError as e:
            raise UiError(str(e)) from None
        if what.kind == "call" and not isinstance(widget, QAbstractButton):
            raise UiError(f"a {type(widget).__name__} cannot be clicked: use a button")
        if what.kind == "arg" and not isinstance(
            widget, QDoubleSpinBox | QSpinBox | QSlider | QDial | QCheckBox | QComboBox | QLineEdit
        ):
            raise UiError(f"a {type(widget).__name__} holds no argument")
        if what.kind in ("event", "result") and not _shows_values(widget):
            raise UiError(f"a {type(widget).__name__} cannot show values")
        if what.kind == "event" and not what.rest and not isinstance(widget, FieldsView):
            raise UiError("names no field (event__TYPE__FIELD; only a FieldsView shows all)")

    def _check_call(self, what: _Name) -> None:
        """With the interface known (given, or found now), the operation and its arguments."""
        cls = self.interfaces.get(what.target)
        if cls is None:
            return  # checked when clicked, once the object's interface is known
        self._signature(cls, what.target, what.op)

    def _signature(self, cls: type[Stub], obj: str, op: str) -> list[tuple[str, str, QWidget]]:
        method = getattr(cls, op, None)
        if method is None or op.startswith("_"):
            raise UiError(f"{obj} is a {cls._repo_id}, which has no operation {op}")
        args = []
        for param in list(inspect.signature(method).parameters.values())[1:]:
            wanted = f"arg__{obj}__{op}__{param.name}"
            widget = self.form.findChild(QWidget, wanted)
            if widget is None:
                raise UiError(f"{op} takes {param.name}: the form has no widget {wanted}")
            args.append((param.name, str(param.annotation), widget))
        return args

    # ---- events ---------------------------------------------------------------------------------

    def _on_event(self, event: StructuredEvent) -> None:
        for widget, path in self._events.get(event.type_name, []):
            self._show(widget, event.payload, path)

    def _show(self, widget: QWidget, value: Any, path: str) -> None:
        try:
            display(widget, get_field(value, path) if path else value)
        except (FieldError, ValueError, TypeError, OverflowError) as e:
            key = widget.objectName()
            if key not in self._reported:  # once per widget, not once per event
                self._reported.add(key)
                self.error.emit(f"{key}: {e}")

    # ---- calls ----------------------------------------------------------------------------------

    def _caller(self, obj: str, op: str) -> Callable[[], None]:
        def click() -> None:
            self.call(obj, op)

        return click

    def call(self, obj: str, op: str) -> None:
        """Call `op` on `obj` with the arguments its arg__ widgets hold (as its button does)."""
        try:
            cls = self.interfaces.get(obj)
            if cls is None:  # the arguments need the interface: find it in the naming service
                self.runner.call(
                    self._interface,
                    obj,
                    on_result=lambda _: self.call(obj, op),
                    on_error=lambda e: self.error.emit(f"{obj}: {e}"),
                )
                return
            args = [_read(w, ann) for _, ann, w in self._signature(cls, obj, op)]
        except (UiError, ValueError) as e:
            self.error.emit(f"call__{obj}__{op}: {e}")
            return
        self.runner.call(
            self._invoke,
            cls,
            obj,
            op,
            args,
            on_result=lambda value: self._on_result(obj, op, value),
            on_error=lambda e: self.error.emit(f"{obj}.{op}: {e}"),
        )

    def _interface(self, obj: str) -> type[Stub]:
        """Worker: the stub class of the object bound as `obj` (UiError if not imported)."""
        entry = self.client.naming.resolve(obj)
        cls = stub_class(entry.repo_id)
        if cls is None:
            raise UiError(f"is a {entry.repo_id}: import its generated module to call it")
        self.interfaces.setdefault(obj, cls)
        return cls

    def _invoke(self, cls: type[Stub], obj: str, op: str, args: list[Any]) -> Any:
        """Worker: the call itself, on a stub resolved once."""
        stub = self._stubs.get(obj)
        if stub is None:
            stub = self._stubs[obj] = self.client.resolve_name(obj, cls)
        return getattr(stub, op)(*args)

    def _on_result(self, obj: str, op: str, value: Any) -> None:
        for widget, path in self._results.get((obj, op), []):
            self._show(widget, value, path)

    def _show_error(self, message: str) -> None:
        _log.warning("%s: %s", self.source, message)
        if isinstance(self.status, QStatusBar):
            self.status.showMessage(message, 10_000)
        elif isinstance(self.status, QLabel):
            self.status.setText(message)


def _client_of(bridge: QtEventBridge) -> Client:
    if isinstance(bridge.server, Client):
        return bridge.server
    raise TypeError("a bridge over a bare Reactor has no naming service: pass client=")
