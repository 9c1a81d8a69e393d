"""A server's names over Zenoh: the leases of the ZeroMQ backbone (transport.naming.leases,
renewed by calls to the registry), and beside each bound name a liveliness token
(`keys.name_token`) held by the server's session.

The token is what makes a dead server's names go at once: when its process dies or its link
is cut, the router drops its tokens (at once for a killed process, within the link lease for
a cut link), and the registry in `miro naming --zenoh` ends the names' leases then
(transport.zenoh.registry), instead of after the lease. Leases still bound what a registry
that missed a token's end keeps.
"""

from __future__ import annotations

import contextlib
import threading
from typing import Any

import MiroNaming
import zenoh

from miro_gen.transport.naming.leases import Leases
from miro_gen.transport.zenoh import keys
from miro_gen.transport.zenoh.session import identity


class TokenedNames:
    """`leases` with a liveliness token per name held, declared on `session` (a `NameKeeper`,
    service.backbone)."""

    leased = True

    def __init__(self, leases: Leases, session: Any) -> None:
        self.leases = leases
        self.session = session
        self.zid = identity(session)
        self._tokens: dict[str, Any] = {}
        self._lock = threading.Lock()
        self._stopped = False
        # Names the leases' own thread binds (one another server held, bound once it let it
        # go) or gives up (taken by a newer run) get or lose their tokens then, too.
        leases.on_held_changed = self._sync

    def _sync(self) -> None:
        """A token for every name held, none for the others (from the server's thread or the
        leases' renewing thread)."""
        with self._lock:
            if self._stopped:
                return
            held = {e.name for e in self.leases.held()}
            for name in [n for n in self._tokens if n not in held]:
                _undeclare(self._tokens.pop(name))
            for name in held - self._tokens.keys():
                self._tokens[name] = self.session.liveliness().declare_token(
                    keys.name_token(self.zid, name)
                )

    def bind(self, entry: MiroNaming.Entry) -> bool:
        bound = self.leases.bind(entry)
        self._sync()
        return bound

    def claim(self, entry: MiroNaming.Entry, *, take_over: bool, timeout: float) -> bool:
        claimed = self.leases.claim(entry, take_over=take_over, timeout=timeout)
        self._sync()
        return claimed

    def want(self, entry: MiroNaming.Entry, holder: str) -> None:
        self.leases.want(entry, holder)

    def remove(self, name: str) -> None:
        self.leases.remove(name)
        self._sync()

    def held(self) -> list[MiroNaming.Entry]:
        return self.leases.held()

    def stop(self) -> None:
        self.leases.stop()
        with self._lock:
            self._stopped = True
            tokens, self._tokens = list(self._tokens.values()), {}
        for token in tokens:
            _undeclare(token)


def _undeclare(entity: Any) -> None:
    with contextlib.suppress(zenoh.ZError):  # the session is closed already
        entity.undeclare()
