"""ViconReceiver over a real UDP socket on 127.0.0.1 (no mocks).

The client binds port 0 and the test reads the port back; a plain UDP socket
in the test is the sender. Waits are on data with timeouts, never sleeps.
"""

from __future__ import annotations

import os
import socket
import struct
import threading
from collections.abc import Iterator

import numpy as np
import pytest

from groundstation.errors import ViconError
from groundstation.vicon.receiver import ViconReceiver

TIMEOUT = 5.0  # generous upper bound; the tests return as soon as data arrives


def datagram(frame: int, x_mm: float, name: bytes = b"quad") -> bytes:
    """Spec layout, built by hand: header, one object item, padded to 1024 bytes."""
    item = struct.pack("<BH24s6d", 0, 72, name, x_mm, 200.0, 1000.0, 0.05, -0.03, 0.4)
    return (struct.pack("<IB", frame, 1) + item).ljust(1024, b"\0")


@pytest.fixture(autouse=True)
def no_leaked_threads() -> Iterator[None]:
    before = set(threading.enumerate())
    yield
    leaked = [t for t in threading.enumerate() if t not in before and t.is_alive()]
    assert not leaked, f"threads left running: {leaked}"


@pytest.fixture
def sender() -> Iterator[socket.socket]:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        yield s


def test_round_trip_over_loopback(sender: socket.socket) -> None:
    clock_value = 123.0  # injected clock: the stamp is exactly clock() - latency
    with ViconReceiver("127.0.0.1", 0, "quad", latency_s=0.004,
                       clock=lambda: clock_value) as client:
        host, port = client.address
        assert host == "127.0.0.1"
        assert port > 0
        assert client.latest() is None
        sender.sendto(datagram(1, 100.0, b"wand"), (host, port))  # other object: no pose
        for frame in (2, 3, 4, 5, 6):  # the first two confirm the stream (reanchor_poses 3)
            sender.sendto(datagram(frame, 100.0 + frame), (host, port))
        poses = [client.get(timeout=TIMEOUT) for _ in range(3)]
        assert all(p is not None for p in poses)
        assert [p.frame for p in poses if p is not None] == [4, 5, 6]
        first = poses[0]
        assert first is not None
        assert first.t == pytest.approx(123.0 - 0.004)
        # Vicon (104, 200, 1000) mm -> NED (0.104, -0.2, -1.0) m with the default C_wn.
        np.testing.assert_allclose(first.position, [0.104, -0.2, -1.0])
        latest = client.latest()
        assert latest is not None
        assert latest.frame == 6
        h = client.health()
        assert (h.datagrams, h.poses, h.lost_missing, h.unconfirmed) == (6, 3, 1, 2)
        assert client.get(timeout=0.01) is None  # queue drained


def test_monotonic_stamp_brackets_the_receive(sender: socket.socket) -> None:
    import time

    with ViconReceiver("127.0.0.1", 0, "quad", latency_s=0.0) as client:
        before = time.monotonic()
        for frame in (1, 2, 3):
            sender.sendto(datagram(frame, 0.0), client.address)
        pose = client.get(timeout=TIMEOUT)
        after = time.monotonic()
    assert pose is not None
    assert before <= pose.t <= after


def test_bad_datagrams_do_not_stop_the_reader(sender: socket.socket) -> None:
    with ViconReceiver("127.0.0.1", 0, "quad") as client:
        sender.sendto(b"", client.address)
        sender.sendto(b"\x01\x00\x00\x00\x05garbage", client.address)
        for frame in (5, 6, 7):
            sender.sendto(datagram(frame, 1.0), client.address)
        pose = client.get(timeout=TIMEOUT)
        assert pose is not None
        assert pose.frame == 7
        h = client.health()
    assert h.rejected_datagrams == 2
    assert h.rejected["short_header"] == 1


def test_bind_failure_is_a_vicon_error() -> None:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as taken:
        taken.bind(("127.0.0.1", 0))
        client = ViconReceiver("127.0.0.1", taken.getsockname()[1], "quad")
        with pytest.raises(ViconError, match="cannot bind") as info:
            client.start()
        assert isinstance(info.value, OSError)
        assert isinstance(info.value.__cause__, OSError)
        client.close()


def test_reader_failure_is_raised_on_the_next_call() -> None:
    # Replace the socket's descriptor by a pipe: the reader's next recv fails with
    # ENOTSOCK, a real OS error, which must surface in the user's thread.
    read_fd, write_fd = os.pipe()
    try:
        client = ViconReceiver("127.0.0.1", 0, "quad", poll_interval_s=0.02).start()
        os.dup2(read_fd, client.fileno())
        os.write(write_fd, b"x")
        with pytest.raises(ViconError, match="reader failed") as info:
            client.get(timeout=TIMEOUT)
        assert isinstance(info.value.__cause__, OSError)
        with pytest.raises(ViconError):
            client.latest()  # and every call after that
        with pytest.raises(ViconError):
            client.health()
        client.close()
    finally:
        os.close(read_fd)
        os.close(write_fd)


def test_lifecycle() -> None:
    client = ViconReceiver("127.0.0.1", 0, "quad")
    with pytest.raises(ViconError, match="not started"):
        client.get(timeout=0.0)
    with pytest.raises(ViconError, match="not started"):
        _ = client.address
    assert client.start() is client.start()  # second start is a no-op
    client.close()
    client.close()  # idempotent
    assert client.get(timeout=TIMEOUT) is None  # returns at once once closed
    with pytest.raises(ViconError, match="closed"):
        client.start()


def test_close_wakes_a_blocked_get() -> None:
    client = ViconReceiver("127.0.0.1", 0, "quad").start()
    result: list[object] = []
    waiter = threading.Thread(target=lambda: result.append(client.get(timeout=TIMEOUT * 4)))
    waiter.start()
    client.close()
    waiter.join(TIMEOUT)
    assert not waiter.is_alive()
    assert result == [None]


def test_filter_options_are_passed_through(sender: socket.socket) -> None:
    with ViconReceiver(
        "127.0.0.1", 0, "quad", max_speed=0.1, position_slack=0.0, reanchor_after_s=60.0
    ) as client:
        assert client.filter.max_speed == 0.1
        for frame in (1, 2, 3):
            sender.sendto(datagram(frame, 0.0), client.address)
        sender.sendto(datagram(4, 900.0), client.address)  # 0.9 m jump: an outlier
        sender.sendto(datagram(5, 0.0), client.address)
        frames = [client.get(timeout=TIMEOUT), client.get(timeout=TIMEOUT)]
        assert [p.frame for p in frames if p is not None] == [3, 5]
        assert client.health().outliers == 1


def test_from_assembled_params(sender: socket.socket) -> None:
    from dataclasses import replace

    from groundstation.config import load_config
    from groundstation.flight.assembly import plausible_volume, vicon_params

    sim = load_config("config/sim.yaml")
    cfg = sim.vicon
    # Port 0 for the test: any free one
    params = replace(vicon_params(cfg, sim.safety), bind_address="127.0.0.1", port=0)
    with ViconReceiver.from_params(params, clock=lambda: 7.0) as client:
        assert client.filter.plausibility.volume == plausible_volume(cfg, sim.safety)
        for frame in (1, 2, 3):
            sender.sendto(datagram(frame, 0.0, cfg.object_name.encode()), client.address)
        pose = client.get(timeout=TIMEOUT)
    assert pose is not None
    assert pose.t == pytest.approx(7.0 - cfg.latency_s)
    np.testing.assert_allclose(pose.position, [0.0, -0.2, -1.0], atol=1e-15)


class Steps:
    """A clock that advances 5 ms per call (thread-safe): the reader's stamp per datagram
    and each evidence() call, whatever the machine's speed."""

    def __init__(self) -> None:
        self._t = 0.0
        self._lock = threading.Lock()

    def __call__(self) -> float:
        with self._lock:
            self._t += 0.005
            return self._t


def test_evidence_and_diagnosis_over_udp(sender: socket.socket) -> None:
    """Tracker's noise-free-angle stream (rotation exactly 0, position noisy) from one
    socket, a forger 0.5 m off from another, interleaved: the real stream is followed and
    passed, the forger is a rival (evidence, diagnosis), and the counters outlive close()."""
    rng = np.random.default_rng(9)
    zero = (0.0, 0.0, 0.0)

    def item(frame: int, x_mm: float) -> bytes:
        x, y, z = np.array([x_mm, 200.0, 1000.0]) + rng.normal(0.0, 0.65, 3)
        body = struct.pack("<IB", frame, 1) + struct.pack("<BH24s6d", 0, 72, b"quad",
                                                          x, y, z, *zero)
        return body.ljust(1024, b"\0")

    with (socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as forger,
          ViconReceiver("127.0.0.1", 0, "quad", latency_s=0.0, clock=Steps()) as client):
        last = b""
        for k in range(21):
            last = item(k + 1, 100.0)
            sender.sendto(last, client.address)
            if k < 20:
                forger.sendto(item(900 + k, 600.0), client.address)
        frames = []
        while not frames or frames[-1] != 21:
            pose = client.get(timeout=TIMEOUT)
            assert pose is not None, frames
            frames.append(pose.frame)
        assert frames == list(range(3, 22))
        evidence = client.evidence()
        x, y, z = struct.unpack_from("<3d", last, 5 + 27)
        assert evidence.last_position == pytest.approx((x / 1000, -y / 1000, -z / 1000),
                                                       abs=1e-12)
        assert (evidence.rivals, evidence.rival_events, evidence.outside) == (1, 1, None)
    # Both senders start together: the real one, first, is followed at its third pose;
    # alternations count from then on, so the forger's third and fourth are held back and
    # its fifth (after five alternations) is a rival's.
    assert client.diagnosis() == (
        "41 datagrams, 19 poses of 'quad' passed; refused: 1 inconsistent, 5 unconfirmed, "
        "16 from a rival stream")
