"""Finding the naming service without its address: the manual's `Naming_Service -m 1`, with
multicast DNS service discovery (DNS-SD over mDNS, the `zeroconf` package).

`miro naming` announces itself as a `_miro-naming._tcp` service (the instance named after its
host, its addresses and port, and its endpoint in the TXT record) unless told not to
(`--no-announce`, `-m 0`). `miro naming --zenoh` announces itself the same way, with one TXT
key more: `zenoh`, the Zenoh locator its router listens on (`tcp/HOST:PORT`, or `tls/...` with
mutual TLS), which tells the two backbones' naming services apart: one service type, one
record per naming service, whichever its backbone. A process whose naming service was not
given (no `--naming`, no `-ORBInitRef`, no $MIRO_NAMING) and finds none answering at the
default address looks for an announced one of its own backbone (`naming_for`): a ZeroMQ
process skips Zenoh routers, a Zenoh session ZeroMQ naming services. `diagnose()` says what
is visible on this network and, for each, whether it answers and why not (no route, nothing
listening, packets dropped, another network), for `miro doctor`.

`MIRO_DISCOVERY=0` turns multicast DNS off in a process: it neither looks for naming services
nor announces one (the tests run so: nothing leaves loopback but inside namespaces they make).
"""

from __future__ import annotations

import contextlib
import errno
import ipaddress
import os
import socket
import threading
import time
from dataclasses import dataclass, field
from typing import Any

from miro_gen import log

SERVICE_TYPE = "_miro-naming._tcp.local."
BROWSE_TIMEOUT = 3.0  # seconds `miro doctor` looks for announced naming services
FIND_TIMEOUT = 1.5  # seconds a process without a naming service looks for an announced one
ZENOH_KEY = "zenoh"  # the TXT key of a Zenoh router's locator (`miro naming --zenoh`)
SETTLE = 0.3  # seconds to wait for more answers after the first
PROBE_TIMEOUT = 0.5  # seconds a TCP connection to a naming service may take to open
_log = log.logger("MIRO")
OFF = "multicast DNS is off here (MIRO_DISCOVERY=0)"


def enabled() -> bool:
    """Whether this process may use multicast DNS (announce, browse): not with MIRO_DISCOVERY=0."""
    return os.environ.get("MIRO_DISCOVERY", "1") != "0"


class DiscoveryOff(RuntimeError):
    """Looking for naming services was asked for, with multicast DNS turned off."""

    def __init__(self) -> None:
        super().__init__(OFF)


@dataclass
class Announced:
    """A naming service seen on the network."""

    name: str  # the DNS-SD instance name
    host: str  # the host it says it runs on
    port: int
    addresses: list[str]
    endpoint: str  # the endpoint it says it serves on (may be 0.0.0.0: every interface)
    interfaces: list[str] = field(default_factory=list)  # local ones that share a network
    zenoh: str = ""  # the Zenoh router's locator ("": a ZeroMQ naming service)

    @property
    def backbone(self) -> str:
        """The backbone of the processes that use it: `zenoh` or `zmq`."""
        return "zenoh" if self.zenoh else "zmq"

    def url(self) -> str:
        """The endpoint to use from here: an address of it on a network of this machine's
        (else its first)."""
        chosen = next(
            (a for a in self.addresses if _local_network(a) is not None),
            self.addresses[0] if self.addresses else self.host,
        )
        return f"tcp://{chosen}:{self.port}"


def local_networks() -> list[tuple[str, ipaddress.IPv4Network]]:
    """(interface, network) of this machine's IPv4 addresses."""
    import ifaddr

    out = []
    for adapter in ifaddr.get_adapters():
        for ip in adapter.ips:
            if isinstance(ip.ip, str):
                net = ipaddress.IPv4Network(f"{ip.ip}/{ip.network_prefix}", strict=False)
                out.append((str(adapter.nice_name), net))
    return out


def _local_network(address: str) -> str | None:
    """The local interface whose network holds `address`, or None."""
    try:
        ip = ipaddress.IPv4Address(address)
    except ValueError:
        return None
    for name, net in local_networks():
        if ip in net and not net.is_loopback:
            return name
    return None


def _announce_addresses(host: str) -> list[str]:
    """What a naming service bound on `host` announces: that address, or for every interface
    (0.0.0.0) the non-loopback addresses of this machine."""
    if host not in ("0.0.0.0", "*", ""):
        return [host]
    return _own_ips()


def _own_ips() -> list[str]:
    import ifaddr

    return [
        str(ip.ip)
        for adapter in ifaddr.get_adapters()
        for ip in adapter.ips
        if isinstance(ip.ip, str) and not ip.ip.startswith("127.")
    ]


class Announcer:
    """Announces a naming service serving on `bound` (`tcp://HOST:PORT`) until `close()`;
    with `zenoh`, the locator of the Zenoh router that serves there (`miro naming --zenoh`).
    Registration takes a second or two of probing, done in a thread of its own."""

    def __init__(self, bound: str, zenoh: str = "") -> None:
        host, port = bound.removeprefix("tcp://").rsplit(":", 1)
        self.addresses = _announce_addresses(host)
        self.port = int(port)
        self.hostname = socket.gethostname().split(".")[0]
        self.name = f"{self.hostname} {self.port}.{SERVICE_TYPE}"
        self.endpoint = bound
        self.zenoh = zenoh
        self._zc: Any = None
        self._info: Any = None
        self._lock = threading.Lock()
        self._closed = False
        if not enabled():
            _log.notice("not announced on the network: %s", OFF)
        elif self.addresses:
            threading.Thread(target=self._register, name="miro-announce", daemon=True).start()

    def _register(self) -> None:
        try:
            from zeroconf import IPVersion, ServiceInfo, Zeroconf

            properties = {"endpoint": self.endpoint, "host": self.hostname, "version": "1"}
            if self.zenoh:
                properties[ZENOH_KEY] = self.zenoh
            info = ServiceInfo(
                SERVICE_TYPE,
                self.name,
                addresses=[socket.inet_aton(a) for a in self.addresses],
                port=self.port,
                properties=properties,
                server=f"{self.hostname}.local.",
            )
            zc = Zeroconf(ip_version=IPVersion.V4Only)
            with self._lock:
                if self._closed:
                    zc.close()
                    return
                self._zc, self._info = zc, info
            zc.register_service(info, allow_name_change=True)
            _log.notice("announced as %r on %s", info.name, ", ".join(self.addresses))
        except Exception as e:  # no multicast here: the service works, unannounced
            _log.warning("cannot announce the naming service (multicast DNS): %s", e)

    def close(self) -> None:
        with self._lock:
            self._closed = True
            zc, info = self._zc, self._info
        if zc is not None:
            with contextlib.suppress(Exception):
                zc.unregister_service(info)
            zc.close()


def browse(
    timeout: float = BROWSE_TIMEOUT, first: bool = False, backbone: str | None = None
) -> list[Announced]:
    """The naming services announced on this machine's networks, waiting up to `timeout`
    seconds (with `first`, only until one is seen, and a moment more for others); with
    `backbone` (`zmq`, `zenoh`), only those of that backbone. DiscoveryOff with
    MIRO_DISCOVERY=0."""
    if not enabled():
        raise DiscoveryOff
    from zeroconf import IPVersion, ServiceBrowser, ServiceStateChange, Zeroconf

    found: dict[str, Announced] = {}
    seen = threading.Event()
    zc = Zeroconf(ip_version=IPVersion.V4Only)

    def changed(zeroconf: Any, service_type: str, name: str, state_change: Any) -> None:
        if state_change is not ServiceStateChange.Added:
            return
        info = zeroconf.get_service_info(service_type, name, timeout=int(timeout * 1000))
        if info is None:
            return
        props = {
            k.decode(): (v or b"").decode("utf-8", "replace")
            for k, v in (info.properties or {}).items()
        }
        addresses = list(info.parsed_addresses(IPVersion.V4Only))
        announced = Announced(
            name=name.removesuffix("." + SERVICE_TYPE),
            host=props.get("host") or (info.server or "").removesuffix(".local."),
            port=int(info.port or 0),
            addresses=addresses,
            endpoint=props.get("endpoint", ""),
            interfaces=[i for i in (_local_network(a) for a in addresses) if i],
            zenoh=props.get(ZENOH_KEY, ""),
        )
        if backbone is not None and announced.backbone != backbone:
            return
        found[name] = announced
        seen.set()

    browser = ServiceBrowser(zc, SERVICE_TYPE, handlers=[changed])
    try:
        end = time.monotonic() + timeout
        if first:
            if seen.wait(timeout):
                time.sleep(SETTLE)
        else:
            time.sleep(max(end - time.monotonic(), 0))
    finally:
        browser.cancel()
        zc.close()
    return sorted(found.values(), key=lambda a: (not a.interfaces, a.name))


def answers(url: str, timeout: float = PROBE_TIMEOUT) -> str:
    """'' when something accepts TCP connections at `url` (`tcp://HOST:PORT`), else why not."""
    host, port = url.removeprefix("tcp://").rsplit(":", 1)
    try:
        with socket.create_connection((host.strip("[]"), int(port)), timeout):
            return ""
    except TimeoutError:
        return "no answer in time: a firewall drops the packets, or the host is down"
    except OSError as e:
        if e.errno == errno.ECONNREFUSED:
            return (
                "nothing listens there (the naming service is not running, or a firewall refuses)"
            )
        if e.errno in (errno.ENETUNREACH, errno.EHOSTUNREACH):
            return "no route to it from this machine (another network, or the wrong interface)"
        return e.strerror or str(e)


def naming_for(default: str, backbone: str = "zmq") -> str:
    """The naming service a process of `backbone` (`zmq`, or `zenoh`: the naming service is
    where the router is) should use when none was given: `default` when something answers
    there, else an announced one of that backbone (with a notice saying which), else
    `default`."""
    if not enabled() or not answers(default, timeout=0.2):
        return default
    try:
        found = browse(FIND_TIMEOUT, first=True, backbone=backbone)
    except Exception as e:  # no multicast at all: the default it is, and its error later
        _log.debug("cannot look for announced naming services: %s", e)
        return default
    if not found:
        return default
    chosen = found[0]
    url = chosen.url()
    others = ", ".join(a.name for a in found[1:])
    also = f" (others: {others}; give --naming to choose)" if others else ""
    router = f" (Zenoh router {chosen.zenoh})" if chosen.zenoh else ""
    _log.notice(
        "no naming service at %s; using %s%s, announced by %s%s",
        default,
        url,
        router,
        chosen.host,
        also,
    )
    return url


def diagnose(default: str, timeout: float = BROWSE_TIMEOUT) -> list[str]:
    """What is visible, and why a connection would fail, as lines for `miro doctor`."""
    lines = []
    why = answers(default)
    lines.append(f"{default}: " + (why or "a naming service answers"))
    nets = [f"{name} {net}" for name, net in local_networks() if not net.is_loopback]
    lines.append("this machine's networks: " + (", ".join(nets) or "none but loopback"))
    try:
        found = browse(timeout)
    except Exception as e:
        return [*lines, f"cannot look for announced naming services (multicast DNS): {e}"]
    if not found:
        lines.append(
            "no naming service announces itself on these networks: none runs with announcing "
            "on (miro naming on an address other hosts reach, without --no-announce), or "
            "multicast DNS (UDP port 5353) is blocked between the hosts"
        )
    for a in found:
        url = a.url()
        state = answers(url)
        where = ", ".join(a.addresses) or "no address"
        head = f"announced: {a.name} on {a.host} ({where}), port {a.port}"
        if a.zenoh:
            head += f" (Zenoh router {a.zenoh}, for --transport zenoh)"
        if not state:
            lines.append(f"{head}: answers at {url}")
        elif not a.interfaces:
            lines.append(
                f"{head}: {url}: {state}; it is on none of this machine's networks (announced "
                "through a multicast route or on the wrong interface?)"
            )
        else:
            lines.append(f"{head}: {url}: {state}")
    return lines
