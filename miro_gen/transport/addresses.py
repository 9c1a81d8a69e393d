"""Which address a server's sockets bind on, and which one its naming entries advertise.

Other processes connect to the endpoint a server writes into the naming service, so that
address must be reachable from wherever they run (PITFALLS: "advertise an address clients can
reach, not the bind address"). The rules, in order:

* `--host HOST` / `MIRO_HOST`: advertise HOST as given. It must be (or resolve to) an IPv4
  address of this machine; otherwise a `UsageError` says so before anything is bound. A
  loopback address binds only that address; any other address, or a host name, binds every
  interface.
* otherwise, a naming service on loopback (`127.x`, `localhost`, also `0.0.0.0`): advertise
  `127.0.0.1`, as before. Nothing leaves the machine.
* otherwise, the naming service is on another host: advertise this machine's address on the
  interface that routes to it. The kernel picks it when a UDP socket is `connect()`ed to the
  naming host (no packet is sent); whoever can reach the naming service can usually reach that
  address too. No route, or a host name that does not resolve, is a `UsageError`.

Without `--host`, sockets bind on `127.0.0.1` when the advertised address is a loopback one and
on `0.0.0.0` (every interface) otherwise. `--bind ADDR|IFACE` listens on one interface instead
(given by an address of this machine or an interface name such as `eth0`); without `--host`,
that interface's address is the one advertised. The transport speaks IPv4 only (its ZeroMQ
sockets are not IPv6-enabled).
"""

from __future__ import annotations

import contextlib
import errno
import ipaddress
import socket
from dataclasses import dataclass

from miro_gen.transport.usage import UsageError

LOOPBACK = "127.0.0.1"
EVERY_INTERFACE = "0.0.0.0"


@dataclass(frozen=True)
class Addresses:
    """Where a server binds (`bind`) and what it tells others to connect to (`advertise`)."""

    bind: str
    advertise: str


def server_addresses(naming: str, host: str | None, bind: str | None = None) -> Addresses:
    """The addresses of a server whose naming service is at `naming` (`tcp://HOST:PORT`), with
    `host` the `--host` / `MIRO_HOST` value and `bind` the `--bind` one, if given."""
    chosen = _addresses(naming, host)
    if not bind:
        return chosen
    if bind in ("*", EVERY_INTERFACE):
        return Addresses(EVERY_INTERFACE, chosen.advertise)
    ip = _interface_address(bind)
    if ip is None:
        ip = _resolve(bind, f"--bind {bind!r}")
        _check_mine(ip, f"--bind {bind!r}")
    if host:
        if _is_local_only(ip) and not _is_local_only(_resolve(host, "--host")):
            raise UsageError(f"--bind {bind} is loopback: others cannot reach it at {host}")
        return Addresses(ip, chosen.advertise)
    return Addresses(ip, ip)


def _addresses(naming: str, host: str | None) -> Addresses:
    if host:
        return _given(host)
    naming_host, _, port = naming.partition("://")[2].rpartition(":")
    naming_host = naming_host.strip("[]")
    ip = _resolve(naming_host, f"the naming service host in {naming}")
    if _is_local_only(ip):
        return Addresses(LOOPBACK, LOOPBACK)
    try:
        mine = route_source(ip, int(port))
    except OSError as e:
        raise UsageError(
            f"this machine has no route to the naming service at {naming} "
            f"({e.strerror or e}); connect to its network or give --host ADDRESS"
        ) from None
    return Addresses(EVERY_INTERFACE, mine)


def route_source(ip: str, port: int) -> str:
    """This machine's address on the interface that routes to `ip` (no packet is sent: a UDP
    connect() only asks the kernel for a route and a source address)."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.connect((ip, port))
        return str(s.getsockname()[0])


def _given(host: str) -> Addresses:
    """The addresses for a `--host` value, after checking that it names this machine."""
    what = f"--host / MIRO_HOST {host!r}"
    if _is_ipv6(host):
        raise UsageError(f"{what}: the transport speaks IPv4 only; give an IPv4 address")
    ip = _resolve(host, what)
    if ipaddress.ip_address(ip).is_unspecified:
        raise UsageError(f"{what}: others cannot connect to {ip}; give this machine's address")
    _check_mine(ip, what)
    if ip == host and _is_local_only(ip):  # a loopback address: nobody else could use it
        return Addresses(ip, host)
    # Other machines may resolve a host name to another address than this one does (Debian maps
    # its own name to 127.0.1.1), so a name binds every interface.
    return Addresses(EVERY_INTERFACE, host)


def _check_mine(ip: str, what: str) -> None:
    """UsageError unless `ip` is an address of this machine."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        try:
            s.bind((ip, 0))
        except OSError as e:
            if e.errno == errno.EADDRNOTAVAIL:
                raise UsageError(
                    f"{what}: {ip} is not an address of this machine; give one of its own "
                    "addresses, or leave --host out to use the one that routes to the naming "
                    "service"
                ) from None
            raise UsageError(f"{what}: cannot use {ip}: {e.strerror or e}") from None


def _interface_address(name: str) -> str | None:
    """The IPv4 address of the network interface `name` (`eth0`), None if there is no such
    interface; UsageError if it has no IPv4 address."""
    if name not in {n for _, n in socket.if_nameindex()}:
        return None
    import fcntl
    import struct

    siocgifaddr = 0x8915
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        try:
            raw = fcntl.ioctl(s.fileno(), siocgifaddr, struct.pack("256s", name.encode()[:15]))
        except OSError:
            raise UsageError(f"--bind {name}: the interface has no IPv4 address") from None
    return socket.inet_ntoa(raw[20:24])


def _resolve(name: str, what: str) -> str:
    """The IPv4 address of `name` (an address or a host name)."""
    if _is_ipv6(name):
        raise UsageError(f"{what}: the transport speaks IPv4 only, not {name}")
    with contextlib.suppress(ValueError):
        # An address already: nothing to look up. (getaddrinfo on a str host encodes it
        # with the IDNA codec, which loads three modules and 0.4 MB into every service.)
        return str(ipaddress.IPv4Address(name))
    try:
        infos = socket.getaddrinfo(name, None, socket.AF_INET, socket.SOCK_STREAM)
    except (socket.gaierror, UnicodeError) as e:
        reason = e.strerror if isinstance(e, socket.gaierror) else str(e)
        raise UsageError(f"{what}: cannot resolve {name!r} ({reason})") from None
    return str(infos[0][4][0])


def _is_local_only(ip: str) -> bool:
    address = ipaddress.ip_address(ip)
    return address.is_loopback or address.is_unspecified


def _is_ipv6(text: str) -> bool:
    try:
        return ipaddress.ip_address(text.strip("[]")).version == 6
    except ValueError:
        return False
