"""The design patterns `miro new` scaffolds: their files, parameters and default interface."""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass(frozen=True)
class Parameter:
    name: str
    type: str
    default: str
    doc: str
    measure: str = ""
    inherited: bool = False


@dataclass(frozen=True)
class Pattern:
    summary: str  # what a service of this pattern does ({camel} is the service's class name)
    doc: str  # the manual's name for it
    modules: tuple[tuple[str, str], ...]  # (module file, what it holds) besides __main__.py
    parameters: tuple[Parameter, ...]
    interface: str = ""  # the default --interface, when the pattern serves or calls one
    parent: str = "Miro::Config"
    extra: dict[str, str] = field(default_factory=dict)


CHANNEL = Parameter("ChannelName", "std::string", "EventChannel", "The event channel.")
OBJECT = Parameter("ObjectName", "std::string", "{camel}", "Its name in the naming service.")
EVENT_OUT = Parameter("EventName", "std::string", "{camel}", "The type name of its events.")

PATTERNS: dict[str, Pattern] = {
    "basic": Pattern(
        "A service that starts, reads its parameters, logs and says hello.",
        "the manual's section 8 service: a Base",
        (),
        (Parameter("Greeting", "std::string", "Hello", "What it says when it starts."),),
    ),
    "server": Pattern(
        "A server: implements {interface} and binds it in the naming service.",
        "Polling Server: Base + Implementation",
        (("implementation.py", "the Implementation: the interface's operations"),),
        (OBJECT,),
        interface="Miro::Example",
    ),
    "client": Pattern(
        "A client: finds {interface} in the naming service and polls it.",
        "Polling Client: Base",
        (),
        (
            Parameter("ServerName", "std::string", "{server}", "The object to poll."),
            Parameter("Period", "ACE_Time_Value", "0, 500000", "Time between polls.", "s"),
            Parameter("Wait", "ACE_Time_Value", "30, 0", "How long to wait for it at start.", "s"),
        ),
        interface="Miro::Example",
    ),
    "publisher": Pattern(
        "A publisher: serves Miro::Example and publishes each new value as an event.",
        "Publish-Subscribe Server: Base + Consumer + Implementation",
        (
            ("implementation.py", "the Implementation: latest value, waiters, events"),
            ("consumer.py", "the Consumer: where new values come from (a timer here)"),
        ),
        (
            OBJECT,
            CHANNEL,
            EVENT_OUT,
            Parameter("Period", "ACE_Time_Value", "0, 500000", "Time between values.", "s"),
        ),
    ),
    "subscriber": Pattern(
        "A subscriber: receives the events it subscribes to.",
        "Publish-Subscribe Client: Base + Consumer (push_structured_event)",
        (("consumer.py", "the Consumer: what it does with each event"),),
        (
            CHANNEL,
            Parameter("EventName", "std::string", "ExampleEvent", "The type of events wanted."),
            Parameter("Domain", "std::string", "*", "Whose events (naming context; * for any)."),
        ),
    ),
    "device": Pattern(
        "A device driver: reads lines from a serial device, serves and publishes the values.",
        "Publish Server and Reactor: Connection + EventHandler + Message + Consumer + "
        "Implementation",
        (("device.py", "the Consumer (messages to values) and the Implementation"),),
        (
            Parameter("Device", "std::string", "loop://", "The device.", inherited=True),
            OBJECT,
            CHANNEL,
            EVENT_OUT,
        ),
        parent="Miro::Tty",
    ),
    "timed": Pattern(
        "A timed publisher: consumes events at any rate, publishes at a fixed rate.",
        "Timed Event Publication: Consumer + reactor timer",
        (("filter.py", "the Consumer and the timer handler"),),
        (
            CHANNEL,
            Parameter("InputEvent", "std::string", "ExampleEvent", "The events consumed."),
            Parameter("OutputEvent", "std::string", "{camel}", "The events published."),
            Parameter("Rate", "double", "10", "Events published per second.", "Hz"),
        ),
    ),
}
