"""Telemetry over real ZeroMQ sockets on tcp://127.0.0.1 (OS-chosen free ports): round trip,
schema, rate limiting on simulated times, never blocking, clean close. The monitor's
tests are in test_monitor.py."""

from __future__ import annotations

import json
import time
from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest
import zmq

from groundstation.config import TelemetryConfig
from groundstation.errors import GroundStationError
from groundstation.flight.assembly import publisher_params
from groundstation.telemetry import (
    SCHEMA_VERSION,
    TelemetryPublisher,
    TelemetrySubscriber,
    health_payload,
    state_payload,
)
from groundstation.telemetry.schema import REQUIRED_FIELDS, missing_fields
from groundstation.types import Reference, StateEstimate, Sticks

ANY_PORT = "tcp://127.0.0.1:*"
EST = StateEstimate(
    5.0, np.array([0.1, -0.2, -0.95]), np.array([1.0, 0.0, 0.0, 0.0]),
    np.array([0.3, 0.0, -0.1]), np.zeros(3), np.array([0.01, -0.02, 0.005]),
    np.array([0.05, -0.05, 0.1]), np.full(16, 1e-4),
)
REF = Reference(2.0, np.array([0.5, 0.0, -1.0]), np.array([0.2, 0.0, 0.0]), yaw=0.1)


VEHICLE = {"battery_v": 11.784, "serial_active": True, "motors_on": True, "rc_valid": True,
           "applied_mask": 0b1111, "pilot_enabled": True}
"""What the X-3D reports (STATUS, RC) as the daemon publishes it."""


def snapshot() -> dict[str, dict[str, Any]]:
    return {
        "state": state_payload(state=2, state_name="TRACK", estimate=EST, reference=REF,
                               sticks=Sticks(roll=-12, pitch=30, yaw=0, thrust=2010),
                               ctrl_mask=0b1111, sent=True, vehicle=VEHICLE),
        "health": health_payload(
            link={"rate_hz": 99.5, "rejected": {"crc": 2, "length": 1}, "time_since_data_s": 0.01},
            vicon={"rate_hz": 100.0, "rejected": {}, "time_since_pose_s": float("inf")},
            estimator={"rejected_updates": 4}, loop={"overruns": 1, "compute_time_s": 0.0011}),
    }


@pytest.fixture
def pub() -> Iterator[TelemetryPublisher]:
    with TelemetryPublisher(ANY_PORT, rate_hz=20.0) as publisher:
        yield publisher


def join(pub: TelemetryPublisher, client: TelemetrySubscriber) -> dict[str, dict[str, Any]]:
    """Slow-joiner handshake: publish until the client has one message of each topic
    (bounded: 300 rounds of 10 ms), return the last payload per topic."""
    got: dict[str, dict[str, Any]] = {}
    for k in range(300):
        for topic, body in snapshot().items():
            pub.publish(topic, body, t=float(k))
        while (message := client.receive(0.01)) is not None:
            got[message[0]] = message[1]
        if len(got) == 2:
            return got
    raise AssertionError("no telemetry arrived within 300 publish rounds")


def test_round_trip_and_schema(pub: TelemetryPublisher) -> None:
    assert pub.endpoint is not None and pub.endpoint.startswith("tcp://127.0.0.1:")
    with TelemetrySubscriber(pub.endpoint) as client:
        got = join(pub, client)
    state, health = got["state"], got["health"]
    for topic, payload in got.items():
        assert missing_fields(topic, payload) == []
        assert payload["schema"] == SCHEMA_VERSION and payload["topic"] == topic
    assert state["supervisor"] == {"state": 2, "name": "TRACK"}
    assert state["estimate"]["position"] == [0.1, -0.2, -0.95]
    assert state["reference"]["velocity"] == [0.2, 0.0, 0.0]
    # error = reference - estimate, computed here by hand: (0.4, 0.2, -0.05)
    np.testing.assert_allclose(state["error"]["position"], [0.4, 0.2, -0.05], atol=1e-12)
    assert state["error"]["distance"] == pytest.approx(np.sqrt(0.16 + 0.04 + 0.0025))
    assert state["command"] == {"pitch": 30, "roll": -12, "yaw": 0, "thrust": 2010,
                                "mask": 15, "sent": True}
    assert state["vehicle"] == VEHICLE  # the battery voltage among it [V]
    assert health["link"]["rejected"] == {"crc": 2, "length": 1}
    assert health["vicon"]["time_since_pose_s"] is None  # inf is not JSON: sent as null
    assert set(health["telemetry"]) == {"sent", "dropped", "errors"}
    assert health["seq"] == state["seq"] + 1  # state, then health, in one round


def test_messages_are_strict_json(pub: TelemetryPublisher) -> None:
    with zmq.Context() as ctx:  # read the raw frames, not through TelemetrySubscriber
        sub = ctx.socket(zmq.SUB)
        try:
            sub.setsockopt(zmq.LINGER, 0)
            sub.setsockopt(zmq.SUBSCRIBE, b"health")
            sub.connect(pub.endpoint or "")
            for k in range(300):
                pub.publish("health", snapshot()["health"], t=float(k))
                if sub.poll(10):
                    break
            topic, body = sub.recv_multipart()
        finally:
            sub.close(linger=0)

    def no_constants(name: str) -> None:
        raise AssertionError(f"non-standard JSON constant {name}")

    assert topic == b"health"
    payload = json.loads(body, parse_constant=no_constants)
    assert list(payload)[:5] == list(REQUIRED_FIELDS["health"][:5])  # envelope first


def test_topic_filter(pub: TelemetryPublisher) -> None:
    with TelemetrySubscriber(pub.endpoint or "", topics=["health"]) as client:
        for k in range(300):
            pub.publish("state", snapshot()["state"], t=float(k))
            pub.publish("health", snapshot()["health"], t=float(k))
            if (message := client.receive(0.01)) is not None:
                break
        assert message is not None and message[0] == "health"
        for k in range(20):
            pub.publish("state", snapshot()["state"], t=float(k))
        assert client.receive(0.05) is None


def test_rate_limiting_on_simulated_time() -> None:
    calls = []

    def snap() -> dict[str, dict[str, Any]]:
        calls.append(1)
        return {}

    with TelemetryPublisher(ANY_PORT, rate_hz=20.0) as pub:
        published = [t for t in np.arange(1000) / 1000.0 if pub.maybe_publish(t, snap)]
        # 1 s of 1 kHz ticks at 20 Hz: 20 snapshots, 50 ms apart (grid 0.00, 0.05, ...)
        assert len(calls) == len(published) == 20
        np.testing.assert_allclose(np.diff(published), 0.05, atol=1.5e-3)
        # after a 10 s pause: one snapshot, then the 50 ms grid restarts (no catch-up burst)
        burst = [pub.maybe_publish(11.0 + k / 1000.0, snap) for k in range(100)]
        assert sum(burst) == 2 and burst[0] and burst[50]


def test_rate_holds_when_ticks_do_not_divide_the_period() -> None:
    # 30 Hz ticks for 3 s at 20 Hz: due times advance on their own 50 ms grid, so the
    # count is rate x duration = 60 (restarting the period at each publish would give 45)
    with TelemetryPublisher(ANY_PORT, rate_hz=20.0) as pub:
        count = sum(pub.maybe_publish(k / 30.0 + 5e-4, dict) for k in range(90))
    assert abs(count - 60) <= 1


@pytest.mark.slow
def test_publishing_without_subscriber_never_blocks(pub: TelemetryPublisher) -> None:
    body = snapshot()["state"]
    start = time.monotonic()
    for k in range(10_000):
        pub.publish("state", body, t=float(k))
    # bound far above the cost (~1 s on a loaded machine): catches a blocking send, not speed
    assert time.monotonic() - start < 30.0
    assert pub.sent == 10_000 and pub.dropped == 0 and pub.errors == 0


@pytest.mark.slow
def test_stuck_subscriber_drops_and_counts(pub: TelemetryPublisher) -> None:
    with TelemetrySubscriber(pub.endpoint or "", rcvhwm=10) as client:
        join(pub, client)  # connected and subscribed; from now on the client never reads
        sent_before = pub.sent
        big = {**snapshot()["state"], "pad": "x" * 4096}
        for k in range(10_000):
            pub.publish("state", big, t=float(k))
    assert pub.dropped > 0  # the queues filled: zmq.Again, counted instead of blocking
    assert pub.sent - sent_before + pub.dropped == 10_000


def test_snapshot_errors_are_counted_not_raised(pub: TelemetryPublisher) -> None:
    def broken() -> dict[str, dict[str, Any]]:
        raise KeyError("bug in the loop's snapshot")

    assert not pub.maybe_publish(0.0, broken)
    assert pub.errors == 1
    assert pub.maybe_publish(1.0, lambda: {"state": {}})  # still working


def test_close_releases_the_port_and_context() -> None:
    pub = TelemetryPublisher(ANY_PORT)
    endpoint = pub.endpoint
    assert endpoint is not None
    with pytest.raises(GroundStationError, match="cannot bind"):
        TelemetryPublisher(endpoint)  # address in use; the failed one closes its own context
    pub.close()
    pub.close()
    assert not pub.enabled and not pub.maybe_publish(0.0, snapshot)
    with TelemetryPublisher(endpoint) as again:  # the port is free again
        assert again.endpoint == endpoint


def test_disabled_publisher_and_config() -> None:
    with TelemetryPublisher.from_params(publisher_params(TelemetryConfig(enabled=False))) as pub:
        assert not pub.enabled and not pub.maybe_publish(0.0, snapshot)
    enabled = publisher_params(TelemetryConfig(endpoint=ANY_PORT, rate_hz=5.0))
    with TelemetryPublisher.from_params(enabled) as pub:
        assert pub.enabled
        assert [pub.maybe_publish(t, dict) for t in (0.0, 0.1, 0.19, 0.2)] == [
            True, False, False, True]  # 5 Hz: every 0.2 s


def test_client_skips_malformed_messages() -> None:
    with zmq.Context() as ctx:
        raw = ctx.socket(zmq.PUB)
        try:
            raw.setsockopt(zmq.LINGER, 0)
            port = raw.bind_to_random_port("tcp://127.0.0.1")
            with TelemetrySubscriber(f"tcp://127.0.0.1:{port}", context=ctx) as client:
                good = [b"state", json.dumps({"schema": 1, "seq": 1}).encode()]
                for _ in range(300):
                    raw.send_multipart(good)
                    if client.receive(0.01) is not None:
                        break
                raw.send_multipart([b"state", b"{not json"])
                raw.send_multipart([b"only-one-frame"])
                raw.send_multipart([b"state", b"[1, 2]"])
                raw.send_multipart([b"state", json.dumps({"schema": 1, "seq": 2}).encode()])
                # a loaded machine leaves warm-up messages queued before the malformed
                # ones: read up to the last message sent (one connection keeps the order)
                deadline = time.monotonic() + 10.0
                got = client.receive(1.0)
                while got is not None and got[1]["seq"] == 1 and time.monotonic() < deadline:
                    got = client.receive(1.0)
                assert got == ("state", {"schema": 1, "seq": 2})
                assert client.bad_messages == 3
        finally:
            raw.close(linger=0)
