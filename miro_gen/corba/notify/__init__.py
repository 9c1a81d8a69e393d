"""A CosNotification channel served over IIOP (CosNotifyChannelAdmin::EventChannel), as TAO's
Notify_Service serves Miro's C++ services: the other door of a miro-gen event channel
(transport.events.notify_door joins the two; docs/CORBA.md, "Mixing C++ and Python services").

`NotifyChannel` is one channel's objects (`admins`: the channel, its admins; `proxies`: what
suppliers push into and what pushes to consumers; `filters`: the default filter factory and
its constraint language), `Hub` where its events are routed, `EventChannelFactory` a process's
channels. The bytes are in `wire`, QoS in `qos`, the calls back to clients in `delivery`.
"""

from miro_gen.corba.notify.admins import EventChannelFactory, NotifyChannel
from miro_gen.corba.notify.core import ChannelCore
from miro_gen.corba.notify.hub import Backbone, Hub, Outgoing
from miro_gen.corba.notify.wire import EVENT_CHANNEL, EVENT_CHANNEL_FACTORY, EventType

__all__ = [
    "EVENT_CHANNEL",
    "EVENT_CHANNEL_FACTORY",
    "Backbone",
    "ChannelCore",
    "EventChannelFactory",
    "EventType",
    "Hub",
    "NotifyChannel",
    "Outgoing",
]
