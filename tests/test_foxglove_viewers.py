"""`gs foxglove` for the viewers labs run: the JSON channels' schemas parse in Lichtblick
(a port of its parser, `lichtblick_schema`), the `/state` and `/health` schemas name what
the daemon publishes, and a client that speaks only the protocol's former name,
`foxglove.websocket.v1` (Lichtblick's releases), is let in and gets the flight: checked
with a plain WebSocket client (the `websockets` library) against the server running on a
real telemetry publisher (pyzmq), as a viewer on another machine would connect."""

from __future__ import annotations

import json
import struct
import threading
import time
from collections.abc import Iterator, Mapping
from typing import Any

import numpy as np
import pytest
from lichtblick_schema import parse_json_schema

from groundstation.estimation.ekf import Ekf
from groundstation.telemetry import foxglove as fx
from groundstation.telemetry.publisher import TelemetryPublisher
from groundstation.telemetry.requests import RequestStats
from groundstation.telemetry.schema import (
    TOPIC_HEALTH,
    TOPIC_STATE,
    health_payload,
    state_payload,
)
from groundstation.types import Reference, StateEstimate, Sticks
from groundstation.vicon.posefilter import PoseFilter

pytest.importorskip("foxglove")
websockets = pytest.importorskip("websockets.sync.client")


def _state_body(t: float = 10.0, flight_time: float = 3.5) -> dict[str, Any]:
    estimate = StateEstimate(
        t=t, position=np.array([0.5, -0.2, -1.0]), quaternion=np.array([1.0, 0.0, 0.0, 0.0]),
        velocity_body=np.zeros(3), omega=np.zeros(3), gyro_bias=np.zeros(3),
        acc_bias=np.zeros(3), covariance_diag=np.zeros(16))
    reference = Reference(t=t, position=np.array([0.5, -0.2, -1.0]), velocity=np.zeros(3),
                          yaw=0.3)
    return state_payload(state=2, state_name="TRACK", estimate=estimate, reference=reference,
                         sticks=Sticks(thrust=2000), ctrl_mask=0xF, sent=True,
                         vehicle={"battery_v": 11.1, "serial_active": True,
                                  "motors_on": True, "rc_valid": True, "applied_mask": 15,
                                  "pilot_enabled": True},
                         flight_time_s=flight_time, final=True, outcome="COMPLETED",
                         reason="landed")


def _health_body() -> dict[str, Any]:
    """A health body as the daemon builds it, from the real parts' own health records."""
    return health_payload(link={"rate_hz": 100.0, "rejected": {"crc": 2}},
                          vicon=PoseFilter("X3D").health(0.0), estimator=Ekf().health(),
                          loop={"ticks": 10, "commands": 5}, control=RequestStats())


def _leaves(payload: Mapping[str, Any], prefix: str = "") -> Iterator[str]:
    for key, value in payload.items():
        if isinstance(value, Mapping):
            yield from _leaves(value, f"{prefix}{key}.")
        else:
            yield f"{prefix}{key}"


def _schema_paths(datatypes: dict[str, list[tuple[str, str]]], root: str) -> set[str]:
    out: set[str] = set()

    def walk(name: str, prefix: str) -> None:
        for field, kind in datatypes[name]:
            if kind in datatypes:
                walk(kind, f"{prefix}{field}.")
            else:
                out.add(f"{prefix}{field}")
    walk(root, "")
    return out


def test_every_json_schema_parses_in_lichtblick() -> None:
    for topic, schema in fx.JSON_SCHEMAS.items():
        datatypes = parse_json_schema(schema, topic)
        assert datatypes[topic], topic  # real properties, not an empty object


@pytest.mark.parametrize(("topic", "body"), [(TOPIC_STATE, _state_body()),
                                             (TOPIC_HEALTH, _health_body())])
def test_the_schemas_name_what_the_daemon_publishes(topic: str, body: dict[str, Any]) -> None:
    """Every value a published message carries has its field in the schema (free-form
    maps, the rejection counts by reason, are the one exception: no fixed names)."""
    with TelemetryPublisher(None) as publisher:
        publisher.publish(topic, body, 1.0)  # disabled: nothing sent, the envelope shape
    channel = fx.STATE if topic == TOPIC_STATE else fx.HEALTH
    payload = {"schema": 1, "topic": topic, "seq": 1, "t": 1.0, "time_unix": 1.7e9, **body}
    if topic == TOPIC_HEALTH:
        payload["telemetry"] = {"sent": 0, "dropped": 0, "errors": 0}
    known = _schema_paths(parse_json_schema(fx.JSON_SCHEMAS[channel], channel), channel)
    missing = {leaf for leaf in _leaves(payload) if leaf not in known
               and ".rejected." not in f".{leaf}"}
    assert not missing, missing


def test_a_supervisor_message_without_a_flight_time_leaves_it_out() -> None:
    state = {"schema": 1, "topic": "state", "seq": 1, "t": 1.0, "time_unix": 1.7e9,
             **_state_body(flight_time=float("nan"))}  # a NaN travels as null
    state = json.loads(json.dumps(state, allow_nan=False))
    out = dict(fx.LiveView().messages_for("state", state))
    assert "flight_time_s" not in out[fx.SUPERVISOR]
    assert out[fx.SUPERVISOR]["name"] == "TRACK" and out[fx.SUPERVISOR]["final"] is True


@pytest.fixture(scope="module", autouse=True)
def _sdk_runtime() -> None:
    """Start foxglove-sdk's runtime once for the module: its first server opens sockets the
    runtime keeps for the process (not a leak of a test's)."""
    import foxglove

    foxglove.start_server(host="127.0.0.1", port=0, context=foxglove.Context()).stop()


@pytest.fixture
def served() -> Iterator[tuple[str, TelemetryPublisher]]:
    """(the WebSocket URL, the telemetry publisher feeding it): `run_foxglove` in a thread,
    stopped at teardown."""
    with TelemetryPublisher("tcp://127.0.0.1:*", rate_hz=50.0) as publisher:
        assert publisher.endpoint is not None
        lines: list[str] = []
        stop = threading.Event()
        thread = threading.Thread(target=lambda: fx.run_foxglove(
            publisher.endpoint or "", port=0, duration=60.0, echo=lines.append, stop=stop),
            daemon=True)
        thread.start()
        deadline = time.monotonic() + 30.0
        while not lines and thread.is_alive() and time.monotonic() < deadline:
            time.sleep(0.05)
        assert lines and lines[0].startswith("foxglove: serving ws://127.0.0.1:"), lines
        try:
            yield lines[0].split()[2], publisher
        finally:
            stop.set()
            thread.join(30.0)
            assert not thread.is_alive()


def _advertised(ws: Any, topics: set[str]) -> dict[str, dict[str, Any]]:
    channels: dict[str, dict[str, Any]] = {}
    deadline = time.monotonic() + 20.0
    while topics - set(channels):
        assert time.monotonic() < deadline, channels
        message = json.loads(ws.recv(timeout=20.0))
        if message["op"] == "advertise":
            channels.update({c["topic"]: c for c in message["channels"]})
    return channels


@pytest.mark.parametrize("offered", [["foxglove.websocket.v1"], ["foxglove.sdk.v1"]])
def test_a_viewer_speaking_either_protocol_name_gets_the_flight(
        served: tuple[str, TelemetryPublisher], offered: list[str]) -> None:
    from websockets.typing import Subprotocol

    url, publisher = served
    with websockets.connect(url, subprotocols=[Subprotocol(s) for s in offered],
                            open_timeout=20, max_size=None) as ws:
        assert ws.subprotocol == offered[0]
        first = json.loads(ws.recv(timeout=20.0))
        assert first["op"] == "serverInfo" and first["name"] == "groundstation"
        channels = _advertised(ws, set(fx.CHANNELS))
        for topic in fx.JSON_SCHEMAS:  # the schemas as the viewer receives them
            channel = channels[topic]
            assert channel["encoding"] == "json" and channel["schemaEncoding"] == "jsonschema"
            parse_json_schema(json.loads(channel["schema"]), topic)
        subscribe = {1: fx.SUPERVISOR, 2: fx.STATE}
        ws.send(json.dumps({"op": "subscribe", "subscriptions": [
            {"id": k, "channelId": channels[topic]["id"]} for k, topic in subscribe.items()]}))
        received: dict[str, dict[str, Any]] = {}
        deadline = time.monotonic() + 20.0
        while set(subscribe.values()) - set(received):
            assert time.monotonic() < deadline, received
            publisher.publish(TOPIC_STATE, _state_body(), time.monotonic())
            try:
                data = ws.recv(timeout=0.2)
            except TimeoutError:
                continue
            if isinstance(data, bytes):
                assert data[0] == 0x01  # message data: opcode, subscription, log time
                subscription, _log_time = struct.unpack_from("<IQ", data, 1)
                received[subscribe[subscription]] = json.loads(data[13:])
    assert received[fx.SUPERVISOR] == {"state": 2, "name": "TRACK", "final": True,
                                       "flight_time_s": 3.5}
    assert received[fx.STATE]["estimate"]["position"] == [0.5, -0.2, -1.0]


def test_a_client_speaking_neither_name_is_refused(served: tuple[str, TelemetryPublisher]
                                                   ) -> None:
    from websockets.exceptions import InvalidStatus
    from websockets.typing import Subprotocol

    with pytest.raises(InvalidStatus, match="400"), websockets.connect(
            served[0], subprotocols=[Subprotocol("ros1")], open_timeout=20):
        pass
