"""`miro naming --zenoh`: the Zenoh router and the name registry in one process.

The process's session is a Zenoh router listening where services look for their naming
service; every other process is its client (transport.zenoh.session). Beside the router it
serves the naming registry (transport.naming.service's `Registry` over the table of
transport.naming.table: owners, leases, quotas, kept names) as an object on its own session's
call key, which clients reach at the endpoint `zenoh/naming` (the router they are connected
to: no other session can answer for it, transport.zenoh.invoker), and on the registry's keys
per owner (`miro/@registry/<owner>`, transport.zenoh.keys), where processes with a certificate
bind their names.

Who binds: with access control per robot (`robots`), the router lets only ROBOT's certificate
(and the fleet's) ask on `miro/@registry/ROBOT`, so the registry takes a binding operation that
came there as ROBOT's (`cert:ROBOT`: owners, quotas) and lets it bind only in ROBOT's context
(transport.zenoh.access.PerRobot); binding operations on the open key are refused. Without it
every caller is the principal `zenoh` (unverified), on either key.

Denials: what the router's access control drops, it logs only at Rust's trace level, and
zenoh-python cannot route Zenoh's log into Python's: `RUST_LOG` (e.g.
`zenoh::net::routing::interceptor::access_control=trace`) prints it on this process's
standard output (Zenoh writes it there). The registry's own refusals are warnings in the log.

Liveliness: each name a server keeps has a token (transport.zenoh.names). When a token goes
(its server's process died, or its link was cut and the router's lease ran out), the name's
lease ends at once, as if it had run out: the name is no longer resolved, and is kept for
its owner as any lapsed name is. The token's callback only hands the key to the reactor.
"""

from __future__ import annotations

import json
import time
from collections.abc import Sequence
from typing import Any

import MiroNaming
import zenoh

from miro_gen.log import logger
from miro_gen.transport.events.channels import CHANNEL_REPO_ID
from miro_gen.transport.naming.client import (
    DEFAULT_HOLD,
    DEFAULT_LEASE,
    DEFAULT_MAX_NAMES,
    DEFAULT_QUOTA,
    NAMING_KEY,
)
from miro_gen.transport.naming.owners_log import OwnersLog, Restored
from miro_gen.transport.naming.service import PURGE_INTERVAL, Registry
from miro_gen.transport.naming.table import Table
from miro_gen.transport.reactor import Reactor
from miro_gen.transport.tlsfiles import TlsFiles
from miro_gen.transport.zenoh import keys
from miro_gen.transport.zenoh.access import PerRobot, access_control
from miro_gen.transport.zenoh.adapter import ZenohAdapter
from miro_gen.transport.zenoh.invoker import ZenohInvoker
from miro_gen.transport.zenoh.session import (
    config,
    direct,
    identity,
    locator,
    shared_memory,
    track,
    untrack,
)

_log = logger("MIRO")


class ZenohNaming:
    """A Zenoh router listening at `naming` (tcp://HOST:PORT) with the naming registry, its
    sweeps run by `reactor`."""

    def __init__(
        self,
        reactor: Reactor,
        naming: str,
        quota: int = DEFAULT_QUOTA,
        max_names: int = DEFAULT_MAX_NAMES,
        *,
        hold: float = DEFAULT_HOLD,
        log_path: str | None = None,
        tls: TlsFiles | None = None,
        robots: Sequence[str] = (),
    ) -> None:
        self.reactor = reactor
        self.locator = locator(naming, tls)  # tls/...: only sessions with a key of its CA
        # RUST_LOG: Zenoh's own log, on stdout (its access control's denials: above)
        zenoh.try_init_log_from_env()  # type: ignore[no-untyped-call]
        conf = config("router", listen=self.locator, tls=tls)
        self.per_robot: PerRobot | None = None
        if robots:  # each robot's certificate only its own keys (transport.zenoh.access)
            if tls is None:
                raise ValueError("access control per robot needs TLS: no certificates without")
            conf.insert_json5("access_control", json.dumps(access_control(tls.name, robots)))
            self.per_robot = PerRobot(tls.name, robots)
        self.shared_memory = shared_memory(conf)
        self.table = Table(quota, max_names, hold)
        self.log: OwnersLog | None = None
        self.restored = Restored()
        if log_path is not None:  # (before the router listens: it serves the registry at once)
            self.log = OwnersLog(log_path, self.table)
            self.restored = self.log.restore(time.monotonic(), DEFAULT_LEASE)
        per_robot = self.per_robot
        self.registry = Registry(
            self.table, self.log, admit=None if per_robot is None else per_robot.refusal
        )
        self.session: Any = zenoh.open(conf)
        self.zid = identity(self.session)  # %/<zid>: the router has no owner
        self.endpoint = keys.endpoint(self.zid)
        self.invoker = ZenohInvoker(self.session)
        self.adapter = ZenohAdapter(
            self.session,
            self.invoker,
            identify_callers=True,
            caller_of=None if per_robot is None else per_robot.caller,
        )
        self.invoker.adapter = self.adapter
        self.adapter.activate(self.registry, NAMING_KEY)
        self.adapter.serve_also(keys.REGISTRY_KEYS)
        self.ended = 0  # names whose tokens went: their leases ended then
        self._tokens: Any = track(
            self.session.liveliness().declare_subscriber(
                keys.NAME_TOKENS, direct(self._on_token), history=True
            )
        )
        self._timer = reactor.schedule_timer(PURGE_INTERVAL, PURGE_INTERVAL, self._purge)

    def keep_channel(self, name: str) -> None:
        """Bind the event channel `name` as the naming service's own: over Zenoh a channel is
        its keys, hosted by no process."""
        self.registry.keep(MiroNaming.Entry(name, CHANNEL_REPO_ID, self.endpoint, b"", ""))

    def _on_token(self, sample: Any) -> None:  # Zenoh's thread: hand over, never block
        if sample.kind == zenoh.SampleKind.DELETE:
            self.reactor.call_soon(self._token_gone, str(sample.key_expr))

    def _token_gone(self, key: str) -> None:
        found = keys.name_of_token(key)
        if found is None:
            return
        zid, name = found
        if not self.registry.end_lease(name, keys.endpoint(zid)):
            return  # bound again since, by another process, or gone already
        self.ended += 1
        _log.info(
            "%s: its server's session %s is gone; its lease ends", name, keys.zid_part(zid)[:8]
        )
        self.registry.purge()

    def _purge(self, _: Any) -> None:
        self.registry.purge()

    def close(self) -> None:
        self.reactor.cancel_timer(self._timer)
        untrack(self._tokens)
        self.adapter.close()
        self.invoker.close()
        if self.log is not None:
            self.log.close()
        self.session.close()
