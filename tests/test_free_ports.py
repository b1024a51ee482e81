"""The loopback ports a virtual lab is given stay free until its daemon binds them.

A port from ``bind(("127.0.0.1", 0))`` lies in the kernel's ephemeral range, and the next
sender that never bound (a virtual Vicon's first datagram) or connecting client may be
handed the same port: a real-time flight failed once with "cannot bind UDP
127.0.0.1:45435: Address already in use". :func:`free_ports` draws below that range.
"""

from __future__ import annotations

import socket
from pathlib import Path

import pytest

from groundstation import endpoints
from groundstation.endpoints import FREE_PORT_SPAN, free_ports


def ephemeral_range() -> tuple[int, int]:
    low, high = Path("/proc/sys/net/ipv4/ip_local_port_range").read_text().split()
    return int(low), int(high)


@pytest.mark.parametrize("kind", [socket.SOCK_DGRAM, socket.SOCK_STREAM])
def test_the_ports_are_free_distinct_and_outside_the_ephemeral_range(kind: int) -> None:
    low, _ = ephemeral_range()
    ports = free_ports(50, kind) + free_ports(50, kind)
    assert len(set(ports)) == 100  # never the same port twice, within a call or across
    assert all(1024 <= p < low for p in ports), (low, sorted(ports)[-5:])
    for port in ports[:10]:  # and each one binds
        with socket.socket(socket.AF_INET, kind) as s:
            s.bind(("127.0.0.1", port))


def test_what_the_kernel_hands_a_sender_is_never_one_of_them() -> None:
    """Unbound UDP senders take ephemeral ports; the ports given out are never among them."""
    low, high = ephemeral_range()
    given = set(free_ports(20, socket.SOCK_DGRAM))
    senders = [socket.socket(socket.AF_INET, socket.SOCK_DGRAM) for _ in range(200)]
    try:
        for s in senders:
            s.sendto(b"x", ("127.0.0.1", 9))  # discard port: the send binds the sender
        taken = {s.getsockname()[1] for s in senders}
    finally:
        for s in senders:
            s.close()
    assert all(low <= p <= high for p in taken)
    assert not taken & given


def test_a_port_that_is_taken_is_not_given(monkeypatch: pytest.MonkeyPatch) -> None:
    """The draw lands on a port another socket holds: that one is skipped."""
    low, _ = ephemeral_range()
    first = low - FREE_PORT_SPAN
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as holder:
        for port in range(first + 7, low):  # a port below the range that this test holds
            try:
                holder.bind(("127.0.0.1", port))
                break
            except OSError:
                continue
        held = holder.getsockname()[1]
        draws = iter([held - first, held - first + 1, held - first + 2, held - first + 3])
        monkeypatch.setattr(endpoints.secrets, "randbelow", lambda _n: next(draws))
        given = free_ports(1, socket.SOCK_DGRAM)[0]
    assert given != held and held < given <= held + 3
