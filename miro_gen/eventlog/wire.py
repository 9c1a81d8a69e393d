"""Event frames as raw bytes, for the log tools: their one definition is
`miro_gen.transport.events.frames` (the layout table is in its docstring); this module keeps the
names the log tools imported from here before."""

from miro_gen.transport.events.frames import BATCH_HEADER as BATCH_HEADER
from miro_gen.transport.events.frames import EVENT_HEADER as EVENT_HEADER
from miro_gen.transport.events.frames import MAX_EVENTS as MAX_EVENTS
from miro_gen.transport.events.frames import VERSION as VERSION
from miro_gen.transport.events.frames import FrameError as FrameError
from miro_gen.transport.events.frames import RawEvent as RawEvent
from miro_gen.transport.events.frames import pack_batch as pack_batch
from miro_gen.transport.events.frames import parse_batch as parse_batch
from miro_gen.transport.events.frames import split_topic as split_topic
