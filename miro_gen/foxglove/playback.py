"""A replay in Foxglove: `miro log play --foxglove` serves what the log player plays, and
Foxglove's playback controls (play, pause, seek, speed) drive the player.

Every topic of the file set is a Foxglove channel from the start (its schema as the log
has it: `omgidl` for miro-gen's logs), each event played is sent with its log time, and the
player's clock is sent as the Foxglove time and the playback state. The player is the one
owner of the replay: a seek or a change of speed from Foxglove is a seek or a change of rate
of the player, which processes on `--clock log` follow as they follow the terminal's keys.
"""

from __future__ import annotations

import threading

import foxglove
from foxglove.websocket import (
    Capability,
    PlaybackCommand,
    PlaybackControlRequest,
    PlaybackState,
    PlaybackStatus,
    WebSocketServer,
)

from miro_gen.eventlog.fileset import Event, FileSet, TopicName
from miro_gen.eventlog.player import ClockState, Player
from miro_gen.eventlog.types import topic_name
from miro_gen.foxglove.bridge import Listen
from miro_gen.log import logger

_log = logger("MIRO")
MIN_RATE, MAX_RATE = 1 / 64, 64.0  # what a client's speed is kept within


class PlaybackDoor:
    """The Foxglove side of a `Player` of `files` (attach it with `attach` before playing)."""

    def __init__(self, files: FileSet, listen: Listen) -> None:
        listen.check()
        self.files = files
        self.context = foxglove.Context()
        self._channels: dict[TopicName, foxglove.Channel] = {}
        for f in files.files:
            for t in f.topics.values():
                name = (t.domain, t.type_name)
                if name in self._channels or name in files.excluded:
                    continue
                schema = None
                if t.schema_name:
                    schema = foxglove.Schema(
                        name=t.schema_name, encoding=t.schema_encoding, data=bytes(t.schema)
                    )
                self._channels[name] = foxglove.Channel(
                    topic_name(*name),
                    message_encoding=t.message_encoding,
                    schema=schema,
                    context=self.context,
                )
        self.player: Player | None = None
        self._lock = threading.Lock()
        self._epoch = -1
        start, end = files.cut
        # (the SDK's PlaybackControl needs the range: without one it fails)
        self.ws: WebSocketServer = listen.start(
            "miro-gen log player",
            context=self.context,
            capabilities=[Capability.PlaybackControl, Capability.Time],
            server_listener=self,
            playback_time_range=(start, max(start, end)),
        )

    @property
    def port(self) -> int:
        return int(self.ws.port)

    def attach(self, player: Player) -> None:
        self.player = player

    # ---- what the player does (its thread) -------------------------------------------------------

    def send(self, event: Event) -> None:
        channel = self._channels.get(event.name)
        if channel is not None:
            channel.log(bytes(event.message.data), log_time=event.log_time)

    def clock(self, state: ClockState) -> None:
        """The player's clock changed (or is due again): Foxglove's time and playback state."""
        with self._lock:
            did_seek = self._epoch not in (-1, state.epoch)
            self._epoch = state.epoch
        self.ws.broadcast_time(state.log_ns)
        self.ws.broadcast_playback_state(self._state(state, did_seek, None))

    def _state(self, state: ClockState, did_seek: bool, request_id: str | None) -> PlaybackState:
        player = self.player
        if player is not None and player.ended.is_set() and not player.loop:
            status = PlaybackStatus.Ended
        elif state.paused:
            status = PlaybackStatus.Paused
        else:
            status = PlaybackStatus.Playing
        return PlaybackState(status, state.log_ns, state.rate, did_seek, request_id)

    # ---- what clients ask (the SDK's threads) ---------------------------------------------------

    def on_playback_control_request(self, request: PlaybackControlRequest) -> PlaybackState | None:
        player = self.player
        if player is None:
            return None
        speed = request.playback_speed
        if speed > 0 and speed == speed:  # not NaN
            speed = min(max(speed, MIN_RATE), MAX_RATE)
            if speed != player.rate:
                player.set_rate(speed)
        if request.seek_time is not None:
            player.seek(int(request.seek_time))
        if request.playback_command == PlaybackCommand.Play:
            player.play()
        else:
            player.pause()
        state = player.clock()
        with self._lock:
            self._epoch = state.epoch
        return self._state(state, request.seek_time is not None, request.request_id)

    def close(self) -> None:
        self.ws.stop()
        for channel in self._channels.values():
            channel.close()
