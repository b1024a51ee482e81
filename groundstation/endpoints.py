"""Network endpoints: what a UDP host address, a ZeroMQ endpoint and a Zenoh endpoint
are, and whether an endpoint reaches only this machine.

The configuration checks the addresses it is given with these (``vicon.bind_address``,
``telemetry.endpoint``, ``telemetry.control_endpoint``, ``fleet.zenoh.listen`` and
``connect``), and the request socket refuses, with the same rule, to serve beyond
loopback without authentication, as a fleet's Zenoh network does without TLS.
"""

from __future__ import annotations

import ipaddress
import re
import secrets
import socket
from pathlib import Path

_HOST_LABEL = re.compile(r"^(?!-)[A-Za-z0-9-]{1,63}(?<!-)$")


def host_address(value: str) -> str:
    """An IPv4 address or a host name (RFC 1123: dot-separated labels of letters, digits
    and hyphens, at most 253 characters); ValueError naming what is wrong otherwise."""
    try:
        address = ipaddress.ip_address(value)
    except ValueError:
        address = None
    if address is not None:
        if address.version != 4:
            raise ValueError("an IPv6 address: this socket is IPv4 (AF_INET); give an IPv4 "
                             "address or a host name")
        return value
    labels = value.removesuffix(".").split(".")
    if (not value or len(value) > 253 or not all(_HOST_LABEL.match(x) for x in labels)
            or labels[-1].isdigit()):
        raise ValueError("not an IPv4 address (0.0.0.0: every interface) or a host name "
                         "(letters, digits, hyphens and dots)")
    return value


IPC_PATH_MAX = 107
"""Longest ``ipc://`` path ZeroMQ accepts on Linux [bytes]: ``sockaddr_un.sun_path`` less
its terminating NUL."""


def zmq_endpoint(value: str) -> str:
    """A ZeroMQ endpoint a socket can bind: ``tcp://HOST:PORT`` (HOST ``*``, an IPv4
    address, ``[IPv6]``, a host or interface name; PORT 1-65535 or ``*`` for any free
    one), ``ipc://PATH`` or ``inproc://NAME``. ValueError naming what is wrong."""
    transport, sep, address = value.partition("://")
    if not sep or transport not in ("tcp", "ipc", "inproc"):
        raise ValueError("must be a ZeroMQ endpoint: tcp://HOST:PORT, ipc://PATH or "
                         "inproc://NAME")
    if transport == "ipc":
        if not address or "\0" in address or len(address.encode()) > IPC_PATH_MAX:
            raise ValueError(f"ipc:// needs a path of 1-{IPC_PATH_MAX} bytes (a Unix "
                             "socket's limit)")
        return value
    if transport == "inproc":
        if not address:
            raise ValueError("inproc:// needs a name")
        return value
    host, colon, port = address.rpartition(":")
    if not colon or not host:
        raise ValueError("tcp:// needs HOST:PORT, e.g. tcp://127.0.0.1:5556")
    if port != "*" and not (port.isdigit() and 1 <= int(port) <= 65535):
        raise ValueError(f"port {port!r}: a TCP port is 1-65535 (or * for any free one)")
    if host == "*":
        return value
    if host.startswith("[") and host.endswith("]"):
        try:
            ipaddress.IPv6Address(host[1:-1])
        except ValueError:
            raise ValueError(f"{host}: not an IPv6 address") from None
        return value
    try:
        host_address(host)
    except ValueError:
        raise ValueError(f"host {host!r}: not *, an IPv4 address, [an IPv6 address], a host "
                         "name or an interface name") from None
    return value




def local_endpoint(endpoint: str) -> bool:
    """Whether a ZeroMQ bind endpoint reaches only this machine: TCP on a loopback address
    (127.0.0.0/8, ``::1``, ``localhost``, the ``lo`` interface), IPC or in-process.
    ``tcp://*:5557``, ``tcp://0.0.0.0:5557``, another address or an interface name are not."""
    transport, sep, address = endpoint.partition("://")
    if not sep:
        return False
    if transport in ("ipc", "inproc"):
        return True
    if transport != "tcp":
        return False
    host = address.rpartition(":")[0].removeprefix("[").removesuffix("]")
    if host in ("localhost", "lo"):
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:  # "*", an interface or a host name
        return False


_ZENOH_ENDPOINT = re.compile(r"^(tcp|tls|udp|quic)/(\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9.-]+):"
                             r"([0-9]{1,5})$")


def zenoh_endpoint(value: str) -> str:
    """A Zenoh locator ``PROTOCOL/HOST:PORT`` (tcp, tls, udp or quic; HOST an address, a
    [IPv6] or a name; PORT 0-65535, 0 for any free one). ValueError naming what is
    wrong."""
    match = _ZENOH_ENDPOINT.match(value)
    if match is None:
        raise ValueError("must be a Zenoh endpoint PROTOCOL/HOST:PORT, e.g. "
                         "tcp/127.0.0.1:7447 (tcp, tls, udp or quic)")
    if int(match.group(3)) > 65535:
        raise ValueError(f"port {match.group(3)}: a port is 0-65535")
    return value


def zenoh_local(endpoint: str) -> bool:
    """Whether a Zenoh endpoint reaches only this machine: a loopback address (127.0.0.0/8,
    [::1]) or ``localhost``. ``tcp/0.0.0.0:7447``, another address or a name are not."""
    host = endpoint.partition("/")[2].rpartition(":")[0].removeprefix("[").removesuffix("]")
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:  # a host name: it may resolve anywhere
        return False


EPHEMERAL_LOW_DEFAULT = 32768
"""Linux's lowest ephemeral port when ``/proc/sys/net/ipv4/ip_local_port_range`` cannot be
read (its default, 32768-60999)."""

FREE_PORT_SPAN = 12000
"""How many ports below the ephemeral range :func:`free_ports` draws from."""

_issued: set[tuple[int, int]] = set()
"""(socket kind, port) this process has handed out."""


def _ephemeral_low() -> int:
    try:
        return int(Path("/proc/sys/net/ipv4/ip_local_port_range").read_text().split()[0])
    except (OSError, ValueError, IndexError):
        return EPHEMERAL_LOW_DEFAULT


def free_ports(count: int, kind: int = socket.SOCK_STREAM) -> list[int]:
    """``count`` different loopback ports of ``kind`` (``socket.SOCK_STREAM`` or
    ``SOCK_DGRAM``) that nothing is bound to now, for a virtual lab's Vicon stream and its
    endpoints.

    The ports are drawn at random from the :data:`FREE_PORT_SPAN` ports just below the
    kernel's ephemeral range, never from it: a port the kernel hands to ``bind(0)`` is
    free only until its next ephemeral allocation, and every connecting TCP client and
    every UDP sender that never bound (a virtual Vicon) takes one, so the port could be
    gone before the daemon binds it ("Address already in use"). Below the range only an
    explicit bind can take it, and this process never issues the same port twice.
    """
    high = _ephemeral_low()
    low = max(1024, high - FREE_PORT_SPAN)
    ports: list[int] = []
    for _ in range(100 * count):
        # not the random module: a test that seeds it would make every process draw alike
        port = secrets.randbelow(high - low) + low
        if (kind, port) in _issued or port in ports:
            continue
        with socket.socket(socket.AF_INET, kind) as s:
            try:
                s.bind(("127.0.0.1", port))
            except OSError:
                continue
        _issued.add((kind, port))
        ports.append(port)
        if len(ports) == count:
            return ports
    raise OSError(f"no {count} free loopback ports between {low} and {high - 1}")


def free_udp_port() -> int:
    """One loopback UDP port nothing is bound to now (:func:`free_ports`): a virtual lab's
    Vicon stream."""
    return free_ports(1, socket.SOCK_DGRAM)[0]
