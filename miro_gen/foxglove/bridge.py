"""`miro foxglove`: a running robot in Foxglove (and Lichtblick), over the Foxglove SDK's
WebSocket server (subprotocol `foxglove.sdk.v1`).

Every `refresh` seconds a discovery round asks the naming service and the services' objects
(miro_gen.live) what runs: the offered event topics become Foxglove channels
(foxglove.topics), the objects' operations Foxglove services (foxglove.services), the services'
parameter sets Foxglove parameters (foxglove.parameters); what clients publish goes into the
event channel (foxglove.publish). The server's clock (`--clock log` follows a player) is sent as
the Foxglove time, and stamps every message forwarded.

Threads: the miro reactor (taps, suppliers, the clock), the discovery thread, and the SDK's
own, whose callbacks (the listener below) only record and hand work over.
"""

from __future__ import annotations

import ipaddress
import threading
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import foxglove
from foxglove.websocket import (
    Capability,
    ChannelView,
    Client,
    ClientChannel,
    StatusLevel,
    WebSocketServer,
)

from miro_gen import clock
from miro_gen.exceptions import ActionableError, SystemException
from miro_gen.foxglove import DEFAULT_BACKLOG, DEFAULT_PORT
from miro_gen.foxglove.parameters import Parameters
from miro_gen.foxglove.publish import ClientPublishing
from miro_gen.foxglove.services import Services
from miro_gen.foxglove.topics import Topic, Topics, topics_of
from miro_gen.live.remote import SERVICE_REPO_ID, LiveError, Robot, Running
from miro_gen.log import logger
from miro_gen.transport.buffers import keep_large_buffers
from miro_gen.transport.events import CHANNEL_REPO_ID, EventChannel

if TYPE_CHECKING:
    from miro_gen import Server

_log = logger("MIRO")
TIME_PERIOD = 0.1  # seconds between Foxglove time messages


class BridgeError(ActionableError):
    """The bridge cannot start as asked (one line)."""


def is_loopback(host: str) -> bool:
    host = host.strip("[]")
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


@dataclass
class Listen:
    """Where the WebSocket server listens and how: beyond loopback only with TLS (`cert`,
    `key`: PEM) or `insecure`."""

    address: str = "127.0.0.1"
    port: int = DEFAULT_PORT
    cert: bytes | None = None
    key: bytes | None = None
    insecure: bool = False
    backlog: int = DEFAULT_BACKLOG

    def check(self) -> None:
        if (self.cert is None) != (self.key is None):
            raise BridgeError("--tls-cert and --tls-key go together")
        if not is_loopback(self.address) and self.cert is None and not self.insecure:
            raise BridgeError(
                f"{self.address} is not loopback: give --tls-cert and --tls-key (wss://), or "
                "--insecure to serve the robot in the clear to anyone who can reach it"
            )
        if self.backlog < 1:
            raise BridgeError("--client-queue must be 1 or more")

    def start(self, name: str, **kwargs: Any) -> WebSocketServer:
        keep_large_buffers()  # the process forwards what the robot sends: images too
        try:
            return foxglove.start_server(
                name=name,
                host=self.address,
                port=self.port,
                message_backlog_size=self.backlog,
                tls_cert=self.cert,
                tls_key=self.key,
                **kwargs,
            )
        except RuntimeError as e:
            raise BridgeError(f"cannot serve on {self.address}:{self.port}: {e}") from None


class _Listener:
    """The SDK's callbacks (its threads): handed to the bridge's parts."""

    def __init__(self, bridge: Bridge) -> None:
        self.bridge = bridge

    def on_subscribe(self, client: Client, channel: ChannelView) -> None:
        self.bridge.topics.subscribe(client.id, channel.id)

    def on_unsubscribe(self, client: Client, channel: ChannelView) -> None:
        self.bridge.topics.unsubscribe(client.id, channel.id)

    def on_client_advertise(self, client: Client, channel: ClientChannel) -> None:
        self.bridge.publishing.advertise(
            client.id,
            channel.id,
            channel.topic,
            channel.encoding,
            channel.schema_name,
            channel.schema,
        )

    def on_client_unadvertise(self, client: Client, client_channel_id: int) -> None:
        self.bridge.publishing.unadvertise(client.id, client_channel_id)

    def on_message_data(self, client: Client, client_channel_id: int, data: bytes) -> None:
        self.bridge.publishing.message(client.id, client_channel_id, data)

    def on_get_parameters(
        self, client: Client, param_names: list[str], request_id: str | None = None
    ) -> list[foxglove.Parameter]:
        return self.bridge.parameters.values(param_names)

    def on_set_parameters(
        self,
        client: Client,
        parameters: list[foxglove.Parameter],
        request_id: str | None = None,
    ) -> list[foxglove.Parameter]:
        now = self.bridge.parameters.set(parameters)
        self.bridge.parameters.sent(now)  # the server sends them to the subscribers
        return now

    def on_parameters_subscribe(self, param_names: list[str]) -> None:
        self.bridge.parameters.subscribe(param_names)
        self.bridge.wake.set()

    def on_parameters_unsubscribe(self, param_names: list[str]) -> None:
        self.bridge.parameters.unsubscribe(param_names)


class Bridge:
    """The live bridge of the robot that `server` (a miro Server) and `robot` (the live tools'
    client) reach, serving `channel`'s topics."""

    def __init__(
        self,
        server: Server,
        robot: Robot,
        channel: EventChannel,
        listen: Listen,
        refresh: float = 1.0,
    ) -> None:
        listen.check()
        self.server = server
        self.robot = robot
        self.channel = channel
        self.refresh = refresh
        self.context = foxglove.Context()
        self._schemas: dict[str, str] = {}  # type hash -> data schema text
        self._offer_service: dict[str, Running] = {}  # type hash -> a service offering it
        self._offers: dict[str, list[Any]] = {}  # service -> its offers (MiroService.Offer)
        self.topics = Topics(channel, self.context, self._schema_of_topic)
        self.publishing = ClientPublishing(
            channel, server.options.naming_context, self._offered_schema
        )
        self.ws: WebSocketServer | None = None
        self.services = Services(robot, self._ws)
        self.parameters = Parameters(robot, self._status)
        self.stopped = threading.Event()
        self.wake = threading.Event()
        self.rounds = 0
        self.ws = listen.start(
            "miro-gen",
            context=self.context,
            capabilities=[
                Capability.ClientPublish,
                Capability.Parameters,
                Capability.Services,
                Capability.Time,
            ],
            server_listener=_Listener(self),
            supported_encodings=["cdr", "json"],
        )
        self._thread = threading.Thread(target=self._discover, name="foxglove-discovery")
        self._thread.daemon = True

    @property
    def port(self) -> int:
        return int(self._ws().port)

    def _ws(self) -> WebSocketServer:
        assert self.ws is not None
        return self.ws

    def _status(self, text: str) -> None:
        _log.warning("foxglove: %s", text)
        self._ws().publish_status(text, StatusLevel.Error)

    # ---- schemas ---------------------------------------------------------------------------------

    def _schema_of_topic(self, t: Topic) -> str | None:
        text = self._schemas.get(t.type_hash)
        if text is None:
            service = self._offer_service.get(t.type_hash)
            if service is None:
                return None
            try:
                text = self._schemas[t.type_hash] = self.robot.data_schema(service, t.type_hash)
            except LiveError as e:
                _log.warning("foxglove: %s: %s", t.name, e)
                return None
        return text

    def _offered_schema(self, name: str) -> tuple[str, str] | None:
        t = self.topics.topic(name)
        if t is None:
            return None
        text = self._schemas.get(t.type_hash)
        return None if text is None else (t.payload, text)

    # ---- discovery -------------------------------------------------------------------------------

    def discover_once(self) -> None:
        """One round: topics, services, parameters as they are now."""
        services = self.robot.services()
        offers = []
        known = {}
        for s in services:
            # A service still bound that did not answer this time (busy, a lost reply) keeps
            # the topics it offered: they go when it does.
            found = self._offers.get(s.name, []) if s.description is None else s.description.offers
            known[s.name] = found
            for o in found:
                offers.append(o)
                self._offer_service.setdefault(o.type_hash, s)
        self._offers = known
        self.topics.update(topics_of(offers, self.channel.name))
        entries = [
            e
            for e in self.robot.entries()
            if e.repo_id not in (SERVICE_REPO_ID, CHANNEL_REPO_ID) and e.endpoint
        ]
        self.services.update(entries)
        self.parameters.update(services)
        changed = self.parameters.changed()
        if changed:
            self._ws().publish_parameter_values(changed)
        self.rounds += 1

    def _discover(self) -> None:
        while not self.stopped.is_set():
            try:
                self.discover_once()
            except (LiveError, SystemException) as e:
                _log.warning("foxglove: %s", e)
            except Exception:  # a defect: said, and the bridge goes on serving
                _log.exception("foxglove: discovery failed")
            self.wake.wait(self.refresh)
            self.wake.clear()

    def _tick(self, _: object = None) -> None:
        if self.ws is not None:
            self.ws.broadcast_time(clock.current().time_ns())

    # ---- running ---------------------------------------------------------------------------------

    def start(self) -> None:
        """Discover in the background and send the time (the reactor must run)."""
        self._thread.start()
        self.server.reactor().schedule_timer(0.0, TIME_PERIOD, self._tick)

    def close(self) -> None:
        self.stopped.set()
        self.wake.set()
        if self._thread.is_alive():
            self._thread.join(10)
        if self.ws is not None:
            self.ws.stop()
        self.topics.close()
        self.publishing.close()
