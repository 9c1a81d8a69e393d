"""What `miro launch` watches in the naming service: whether it answers, and which names are
bound (for services that start after a name), on either backbone.

On ZeroMQ the registry is asked over a socket with the key and limits the services get from
the environment; on Zenoh (`transport = "zenoh"`, docs/FLEET.md) through a client session of
the router that `miro naming --zenoh` hosts, opened again and again until the router is up.
"""

from __future__ import annotations

import contextlib
import threading
from collections.abc import Callable
from typing import Any

NAMES_POLL = 0.25  # seconds between looks at the naming service's names
FIRST_POLL = 0.02  # seconds between looks while it does not answer yet


class NameWatcher:
    """Looks at the names of the naming service at `url` (of `transport`, zmq or zenoh) from a
    thread of its own: whether it answers, and which names are bound."""

    def __init__(
        self, url: str, changed: threading.Event | None = None, transport: str = "zmq"
    ) -> None:
        self.url = url
        self.transport = transport
        self.answering = False
        self.names: frozenset[str] = frozenset()
        self.changed = changed if changed is not None else threading.Event()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="launch-names", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        from miro_gen.exceptions import SystemException
        from miro_gen.transport.naming.client import list_entries

        opened = self._open_zenoh() if self.transport == "zenoh" else self._open_zmq()
        if opened is None:
            return  # stopped before the router was up
        registry, close = opened
        try:
            while not self._stop.is_set():
                try:
                    names = frozenset(e.name for e in list_entries(registry))
                    answering = True
                except SystemException:
                    names, answering = frozenset(), False
                if names != self.names or answering != self.answering:
                    self.names, self.answering = names, answering
                    self.changed.set()
                # quickly until it first answers: everything waits for that
                self._stop.wait(NAMES_POLL if answering else FIRST_POLL)
        finally:
            close()

    def _open_zmq(self) -> tuple[Any, Callable[[], None]]:
        import MiroNaming
        import zmq

        from miro_gen.runtime.cdr import ObjectRef
        from miro_gen.service.options import UsageError, parse_common_options
        from miro_gen.transport import sockets
        from miro_gen.transport.naming.client import NAMING_KEY
        from miro_gen.transport.rpc.invoker import ZmqInvoker

        context: zmq.Context[Any] = zmq.Context()
        try:  # the key and limits its services get from the environment (or the default key)
            env, _ = parse_common_options([])
            policy = sockets.policy_for(
                keys=env.keys,
                insecure=env.insecure,
                max_message_size=env.max_message_size,
                talks_to=sockets.endpoint_host(self.url),
            )
            sockets.configure(context, policy)
        except UsageError:
            pass  # no key where one is needed: the services say so, and fail
        invoker = ZmqInvoker(context)
        ref = ObjectRef(MiroNaming.Registry._repo_id, self.url, NAMING_KEY)

        def close() -> None:
            invoker.close()
            context.destroy(linger=0)

        return MiroNaming.Registry(ref, invoker, timeout=1.0), close

    def _open_zenoh(self) -> tuple[Any, Callable[[], None]] | None:
        """The registry beside the Zenoh router at `url`, once the router is up (None: the
        watcher was stopped first)."""
        import MiroNaming

        from miro_gen.exceptions import TRANSIENT
        from miro_gen.runtime.cdr import ObjectRef
        from miro_gen.service.options import UsageError, parse_common_options
        from miro_gen.transport import sockets
        from miro_gen.transport.naming.client import NAMING_KEY
        from miro_gen.transport.zenoh import keys
        from miro_gen.transport.zenoh.invoker import ZenohInvoker
        from miro_gen.transport.zenoh.security import tls_for
        from miro_gen.transport.zenoh.session import open_client

        try:  # the key its services get from the environment (or the default key)
            env, _ = parse_common_options([])
            tls = tls_for(
                keys=env.keys, insecure=env.insecure, talks_to=sockets.endpoint_host(self.url)
            )
        except UsageError:
            tls = None  # no key where one is needed: the services say so, and fail
        while True:
            try:
                session = open_client(self.url, 0.0, tls)
                break
            except TRANSIENT:
                if self._stop.wait(FIRST_POLL):
                    return None
        invoker = ZenohInvoker(session)
        ref = ObjectRef(MiroNaming.Registry._repo_id, keys.NAMING_ENDPOINT, NAMING_KEY)

        def close() -> None:
            invoker.close()
            with contextlib.suppress(Exception):  # (zenoh.ZError: closed already)
                session.close()

        return MiroNaming.Registry(ref, invoker, timeout=1.0), close

    def bound(self, name: str, context: str) -> bool:
        if "/" in name:
            return name in self.names
        return f"{context}/{name}" in self.names or name in self.names

    def close(self) -> None:
        self._stop.set()
        self._thread.join(3)
