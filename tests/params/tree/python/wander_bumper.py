"""Written by hand: the class of the dummy item BumperStop (tree/botsvcs/examples/wander)."""

from __future__ import annotations

import typing

import pydantic

from miro_gen.params.runtime import BOOL, XmlField
from miro_gen.params.runtime.config import Config


class BumperStopParameters(Config):
    """A behaviour's parameters with run-time state of its own, as Miro's hand-written ones."""

    halt: bool = pydantic.Field(default=True)
    _xml_fields: typing.ClassVar[tuple[XmlField, ...]] = (XmlField("Halt", "halt", BOOL),)

    def stops(self) -> bool:
        return self.halt
