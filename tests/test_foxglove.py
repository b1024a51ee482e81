"""`gs foxglove`: telemetry -> the Foxglove WebSocket protocol.

The conversion is checked against independent answers (scipy's rotations, the
protobuf wire format decoded here from the schema the SDK advertises); the live test
runs `gs foxglove` as a user does, in its own process, against a real-time flight of
the virtual lab and reads it with a plain WebSocket client (the ``websockets``
library), as Foxglove Studio would: serverInfo, advertise, subscribe, binary messages
(opcode 0x01, uint32 subscription, uint64 log time [ns], payload; little-endian).
"""

from __future__ import annotations

import base64
import json
import math
import select
import signal
import socket
import struct
import subprocess
import sys
import threading
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from lab_helpers import free_udp_port, sim_config
from scipy.spatial.transform import Rotation

from groundstation.config import apply_overrides, dump_config
from groundstation.flight.assembly import assemble
from groundstation.model.quaternion import dcm_from_quat, quat_from_euler
from groundstation.telemetry import foxglove as fx
from groundstation.telemetry.schema import SCHEMA_VERSION, state_payload
from groundstation.types import Reference, StateEstimate, Sticks

REPO = Path(__file__).resolve().parents[1]
GS = [sys.executable, "-c", "import sys; from groundstation.cli import main; "
      "sys.argv[0] = 'gs'; main()"]


# --- a protobuf decoder driven by the schema (a FileDescriptorSet), for the test only ---

def _varint(data: bytes, i: int) -> tuple[int, int]:
    value, shift = 0, 0
    while True:
        byte = data[i]
        i += 1
        value |= (byte & 0x7F) << shift
        shift += 7
        if not byte & 0x80:
            return value, i


def _fields(data: bytes) -> list[tuple[int, int, Any]]:
    """(field number, wire type, raw value) of a protobuf message, in order."""
    out: list[tuple[int, int, Any]] = []
    i = 0
    while i < len(data):
        key, i = _varint(data, i)
        number, wire = key >> 3, key & 7
        value: Any
        if wire == 0:
            value, i = _varint(data, i)
        elif wire == 1:
            value, i = data[i:i + 8], i + 8
        elif wire == 2:
            n, i = _varint(data, i)
            value, i = data[i:i + n], i + n
        elif wire == 5:
            value, i = data[i:i + 4], i + 4
        else:
            raise ValueError(f"wire type {wire}")
        out.append((number, wire, value))
    return out


def _descriptors(file_descriptor_set: bytes) -> dict[str, dict[int, tuple[str, int, str, bool]]]:
    """Message full name -> {field number: (name, type, type name, repeated)}, read from a
    FileDescriptorSet with the field numbers of google/protobuf/descriptor.proto."""
    out: dict[str, dict[int, tuple[str, int, str, bool]]] = {}

    def message(prefix: str, data: bytes) -> None:
        fields = _fields(data)
        name = prefix + next(v.decode() for n, _, v in fields if n == 1)
        table = out.setdefault(name, {})
        for n, _, v in fields:
            if n == 2:  # FieldDescriptorProto
                f = {fn: fv for fn, _, fv in _fields(v)}
                table[f[3]] = (f[1].decode(), f[5], f.get(6, b"").decode().lstrip("."),
                               f.get(4) == 3)
            elif n == 3:  # nested DescriptorProto
                message(name + ".", v)

    for number, _, file in _fields(file_descriptor_set):
        assert number == 1
        parts = {n: v for n, _, v in _fields(file) if n == 2}
        package = parts[2].decode() + "." if 2 in parts else ""
        for n, _, v in _fields(file):
            if n == 4:
                message(package, v)
    return out


_SCALARS = {1: ("<d", 8), 2: ("<f", 4), 6: ("<Q", 8), 7: ("<I", 4), 15: ("<i", 4),
            16: ("<q", 8)}


def _decode(descriptors: Mapping[str, Mapping[int, tuple[str, int, str, bool]]],
            name: str, data: bytes) -> dict[str, Any]:
    """A protobuf message as a dict (absent fields absent: proto3 leaves out zeros)."""
    out: dict[str, Any] = {}
    for number, wire, raw in _fields(data):
        if number not in descriptors[name]:
            continue
        field, kind, type_name, repeated = descriptors[name][number]
        values: list[Any]
        if kind == 11:
            values = [_decode(descriptors, type_name, raw)]
        elif kind == 9:
            values = [raw.decode()]
        elif kind == 12:
            values = [raw]
        elif kind in _SCALARS:
            fmt, size = _SCALARS[kind]
            values = [struct.unpack_from(fmt, raw, k)[0] for k in range(0, len(raw), size)]
        elif wire == 2:  # packed varints
            values, i = [], 0
            while i < len(raw):
                v, i = _varint(raw, i)
                values.append(v)
        else:
            values = [raw]
        if kind == 8:
            values = [bool(v) for v in values]
        if repeated:
            out.setdefault(field, []).extend(values)
        else:
            out[field] = values[0]
    return out


def _vec(d: Mapping[str, Any], keys: str = "xyz") -> np.ndarray:
    return np.array([d.get(k, 0.0) for k in keys])


# --- pure conversion ---

def _state(*, position: Any = (0.5, -0.2, -1.0), quaternion: Any = (1.0, 0.0, 0.0, 0.0),
           ref_position: Any = (0.5, -0.2, -1.0), yaw: float = 0.3, t: float = 100.0,
           seq: int = 1, time_unix: float = 1.7e9 + 0.25, name: str = "TRACK",
           **extra: Any) -> dict[str, Any]:
    """A state payload as the publisher sends it (envelope included)."""
    estimate = None if position is None else StateEstimate(
        t=t, position=np.array(position, float), quaternion=np.array(quaternion, float),
        velocity_body=np.zeros(3), omega=np.zeros(3), gyro_bias=np.zeros(3),
        acc_bias=np.zeros(3), covariance_diag=np.zeros(16))
    reference = None if ref_position is None else Reference(
        t=t, position=np.array(ref_position, float), velocity=np.zeros(3), yaw=yaw)
    body = state_payload(state=2, state_name=name, estimate=estimate, reference=reference,
                         sticks=Sticks(thrust=2000), ctrl_mask=0xF, sent=True)
    return {"schema": SCHEMA_VERSION, "topic": "state", "seq": seq, "t": t,
            "time_unix": time_unix, **body, **extra}


def _by_channel(messages: list[tuple[str, dict[str, Any]]]) -> dict[str, dict[str, Any]]:
    out = dict(messages)
    assert len(out) == len(messages), "one message per channel and telemetry message"
    assert set(out) <= set(fx.CHANNELS)
    return out


def test_the_attitude_quaternion_is_reordered_not_changed() -> None:
    rng = np.random.default_rng(7)
    view = fx.LiveView()
    for _ in range(20):
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)  # scalar-first [w, x, y, z], R(q) = eCb
        out = _by_channel(view.messages_for("state", _state(quaternion=q)))
        o = out[fx.POSE_ESTIMATE]["pose"]["orientation"]
        xyzw = _vec(o, "xyzw")
        # scipy's default order is Foxglove's (scalar last); it must be the same rotation
        np.testing.assert_allclose(Rotation.from_quat(xyzw).as_matrix(), dcm_from_quat(q),
                                   atol=1e-12)
        np.testing.assert_allclose(Rotation.from_quat(q, scalar_first=True).as_quat(), xyzw,
                                   atol=1e-12)
        body = next(tr for tr in out[fx.TF]["transforms"] if tr["child_frame_id"] == "base_link")
        assert body["parent_frame_id"] == "ned" and body["rotation"] == o
        assert _vec(body["translation"]).tolist() == [0.5, -0.2, -1.0]


def test_the_reference_yaw_is_a_rotation_about_ned_down() -> None:
    for yaw in (0.0, 0.3, -1.2, math.pi / 2, 3.0):
        out = _by_channel(fx.LiveView().messages_for("state", _state(yaw=yaw)))
        pose = out[fx.POSE_REFERENCE]
        assert pose["frame_id"] == "ned"
        assert _vec(pose["pose"]["position"]).tolist() == [0.5, -0.2, -1.0]
        xyzw = _vec(pose["pose"]["orientation"], "xyzw")
        np.testing.assert_allclose(Rotation.from_quat(xyzw).as_matrix(),
                                   Rotation.from_euler("z", yaw).as_matrix(), atol=1e-12)
        np.testing.assert_allclose(Rotation.from_quat(xyzw).as_matrix(),
                                   dcm_from_quat(quat_from_euler(0.0, 0.0, yaw)), atol=1e-12)
    # a quarter turn points the nose (body x) east (NED y)
    east = Rotation.from_quat(_vec(fx.yaw_quaternion(math.pi / 2), "xyzw")).apply([1, 0, 0])
    np.testing.assert_allclose(east, [0, 1, 0], atol=1e-12)


def test_world_is_ned_with_z_up() -> None:
    out = _by_channel(fx.LiveView().messages_for("state", _state()))
    world = next(tr for tr in out[fx.TF]["transforms"] if tr["child_frame_id"] == "ned")
    assert world["parent_frame_id"] == "world"
    r = Rotation.from_quat(_vec(world["rotation"], "xyzw"))
    np.testing.assert_allclose(r.apply([0, 0, -1]), [0, 0, 1], atol=1e-12)  # 1 m up is up
    np.testing.assert_allclose(r.apply([1, 0, 0]), [1, 0, 0], atol=1e-12)  # north stays x


def test_times_are_the_telemetrys_wall_clock() -> None:
    assert fx.log_time_ns(1.7e9 + 0.25) == 1_700_000_000_250_000_000
    assert fx.timestamp(1.7e9 + 0.25) == {"sec": 1_700_000_000, "nsec": 250_000_000}
    out = _by_channel(fx.LiveView().messages_for("state", _state()))
    assert out[fx.POSE_ESTIMATE]["timestamp"] == {"sec": 1_700_000_000, "nsec": 250_000_000}


def test_the_json_channels_carry_the_payloads() -> None:
    payload = _state()
    out = _by_channel(fx.LiveView().messages_for("state", payload))
    assert out[fx.STATE] == payload
    # no flight time published: the field is absent (its schema has one type: number)
    assert out[fx.SUPERVISOR] == {"state": 2, "name": "TRACK", "final": False}
    final = _by_channel(fx.LiveView().messages_for("state", _state(final=True,
                                                                   flight_time_s=7.5)))
    assert final[fx.SUPERVISOR] == {"state": 2, "name": "TRACK", "final": True,
                                    "flight_time_s": 7.5}
    health = {"schema": SCHEMA_VERSION, "topic": "health", "seq": 3, "t": 1.0,
              "time_unix": 1.7e9, "link": {"rate_hz": 100.0}, "vicon": None,
              "estimator": None, "loop": None, "telemetry": {"sent": 3}}
    assert fx.LiveView().messages_for("health", health) == [(fx.HEALTH, health)]
    assert fx.LiveView().messages_for("health", {**health, "schema": 99}) == []
    assert fx.LiveView().messages_for("other", {**health, "topic": "other"}) == []
    for name, schema in fx.JSON_SCHEMAS.items():
        assert schema["title"] == fx.CHANNELS[name] and schema["type"] == "object"


def test_no_pose_without_an_estimate_or_reference() -> None:
    out = _by_channel(fx.LiveView().messages_for(
        "state", _state(position=None, ref_position=None)))
    assert set(out) == {fx.SUPERVISOR, fx.STATE, fx.TF}
    assert [tr["child_frame_id"] for tr in out[fx.TF]["transforms"]] == ["ned"]
    # a non-finite value arrives as null: that pose is left out, the rest goes on
    bad = _state()
    bad["estimate"]["position"][2] = None
    assert fx.POSE_ESTIMATE not in _by_channel(fx.LiveView().messages_for("state", bad))


def test_the_path_keeps_the_last_window() -> None:
    path = fx.PathBuffer(window_s=2.0)
    for k in range(20):  # 4 Hz (exact in binary) for 5 s
        path.append(k * 0.25, {"x": float(k), "y": 0.0, "z": -1.0})
    # the newest at 4.75 s; 2.75 s is the oldest within 2 s of it
    assert [p["x"] for p in path.points()] == [float(k) for k in range(11, 20)]
    path.append(0.0, {"x": -1.0, "y": 0.0, "z": 0.0})  # time went back: a new path
    assert path.points() == [{"x": -1.0, "y": 0.0, "z": 0.0}]
    with pytest.raises(ValueError, match="positive"):
        fx.PathBuffer(0.0)


def test_path_scenes_are_throttled_and_carry_the_path() -> None:
    view = fx.LiveView(path_window_s=1.0, path_period_s=0.2)
    scenes = []
    for k in range(60):  # 20 Hz for 3 s, the reference climbing 1 cm per message
        t = 100.0 + 0.05 * k
        out = _by_channel(view.messages_for("state", _state(
            t=t, seq=k, ref_position=(0.0, 0.0, -0.01 * k), position=(0.0, 0.0, -0.01 * k))))
        if fx.PATH_REFERENCE in out:
            assert fx.PATH_ESTIMATE in out
            scenes.append((t, out[fx.PATH_REFERENCE]))
    assert 13 <= len(scenes) <= 16  # every 0.2 s of telemetry time, not every message
    t_last, scene = scenes[-1]
    (entity,) = scene["entities"]
    assert entity["frame_id"] == "ned" and entity["id"] == "reference"
    (line,) = entity["lines"]
    zs = [p["z"] for p in line["points"]]
    k_last = round((t_last - 100.0) / 0.05)
    assert k_last >= 56 and zs[-1] == pytest.approx(-0.01 * k_last)  # newest last
    assert 20 <= len(zs) <= 21  # the last 1 s at 20 Hz
    assert np.all(np.diff(zs) < 0)
    # a new publisher (seq restarts) starts new paths
    out = _by_channel(view.messages_for("state", _state(t=t_last + 1.0, seq=0)))
    assert fx.PATH_REFERENCE not in out  # one point is no line yet
    assert len(view.paths[fx.PATH_REFERENCE]) == 1


def test_sdk_messages_encode_what_the_view_says() -> None:
    """The SDK objects, encoded to protobuf and decoded with their own schema, give back
    the view's dicts (where proto3 leaves zeros out, zero)."""
    pytest.importorskip("foxglove")
    from foxglove import messages as fm

    view = fx.LiveView(path_period_s=0.0)
    view.messages_for("state", _state(t=99.9, seq=0))
    out = _by_channel(view.messages_for("state", _state(quaternion=(0.9, 0.1, -0.3, 0.2))))
    classes: dict[str, Any] = {"foxglove.PoseInFrame": fm.PoseInFrame,
               "foxglove.FrameTransforms": fm.FrameTransforms,
               "foxglove.SceneUpdate": fm.SceneUpdate}

    def zero(value: Any) -> bool:
        if isinstance(value, dict | list):
            return all(zero(v) for v in (value.values() if isinstance(value, dict) else value))
        return bool(value in (0, 0.0, False, ""))

    def close(decoded: Any, expected: Any) -> None:
        if isinstance(expected, dict):
            for key, value in expected.items():
                key = {"sec": "seconds", "nsec": "nanos"}.get(key, key)  # google.protobuf
                if key not in decoded:
                    assert zero(value), key  # proto3 leaves defaults out
                    continue
                close(decoded[key], value)
        elif isinstance(expected, list):
            assert len(decoded) == len(expected)
            for d, e in zip(decoded, expected, strict=True):
                close(d, e)
        elif isinstance(expected, float):
            assert decoded == pytest.approx(expected, abs=1e-6)  # Color is float32
        else:
            assert decoded == expected

    for channel, schema in fx.CHANNELS.items():
        if not schema.startswith("foxglove."):
            continue
        sdk_schema = classes[schema].get_schema()
        assert sdk_schema.name == schema and sdk_schema.encoding == "protobuf"
        data = fx.sdk_message(schema, out[channel]).encode()
        close(_decode(_descriptors(sdk_schema.data), schema, data), out[channel])


# --- the missing extra ---

def test_without_the_extra_the_command_says_what_to_install(
        monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    from groundstation.cli import main

    monkeypatch.setitem(sys.modules, "foxglove", None)  # `import foxglove` fails
    with pytest.raises(SystemExit) as exited:
        main(["foxglove", "--endpoint", "tcp://127.0.0.1:1", "--duration", "0.1"])
    assert exited.value.code == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("error: ")
    assert "pip install 'groundstation[foxglove]'" in err


# --- live: `gs foxglove` during a real-time flight of the virtual lab ---

def _free_tcp_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _read_line(stream: Any, timeout: float) -> str:
    """One line from a child's pipe within ``timeout`` seconds (AssertionError if not)."""
    if not select.select([stream], [], [], timeout)[0]:
        raise AssertionError(f"no line from the child within {timeout} s")
    return str(stream.readline().decode())


@pytest.mark.realtime
@pytest.mark.slow
def test_foxglove_client_sees_the_flight(tmp_path: Path) -> None:
    pytest.importorskip("foxglove")
    websockets = pytest.importorskip("websockets.sync.client")
    from websockets.typing import Subprotocol

    from groundstation.app.daemon import FlightDaemon, FlightSummary
    from groundstation.flight.supervisor import State
    from sim_device.realtime import SimDeviceProcess

    started = time.monotonic()
    endpoint = f"tcp://127.0.0.1:{_free_tcp_port()}"
    cfg = sim_config(**{
        "trajectory.name": "hover", "vicon.port": free_udp_port(),
        "telemetry.endpoint": endpoint, "telemetry.control_endpoint": None,
        "logging.flight_log_dir": str(tmp_path), "sim.truth_file": str(tmp_path / "truth.npz"),
    })
    cfg_file = tmp_path / "lab.yaml"
    cfg_file.write_text(dump_config(cfg), encoding="utf-8")

    # The bridge first (its SUB socket connects before the daemon binds: zmq retries), so
    # the client sees the flight from its start; the virtual vehicle starts meanwhile.
    err_file = tmp_path / "bridge.err"  # a file, not a pipe nobody reads while flying
    with err_file.open("wb") as err:
        bridge = subprocess.Popen([*GS, "foxglove", "--endpoint", endpoint, "--port", "0",
                                   "--duration", "90"], stdout=subprocess.PIPE, stderr=err,
                                  cwd=REPO)
    assert bridge.stdout is not None
    frames: list[tuple[int, int, bytes]] = []  # (subscription, log time ns, payload)
    out: dict[str, FlightSummary] = {}
    runner: threading.Thread | None = None
    try:
        with SimDeviceProcess(cfg_file, tmp_path / "truth.npz") as device:
            line = _read_line(bridge.stdout, 30.0)
            assert line.startswith("foxglove: serving ws://127.0.0.1:"), (
                line, err_file.read_text())
            url = line.split()[2]
            # What the Foxglove app offers: the protocol's current name and its former one
            # (the same messages); foxglove-sdk 0.30 accepts the current one only.
            offered = [Subprotocol("foxglove.sdk.v1"), Subprotocol("foxglove.websocket.v1")]
            with websockets.connect(url, subprotocols=offered, open_timeout=20,
                                    max_size=None) as ws:
                assert ws.subprotocol == "foxglove.sdk.v1"
                channels: dict[int, dict[str, Any]] = {}
                deadline = time.monotonic() + 20.0
                while set(fx.CHANNELS) - {c["topic"] for c in channels.values()}:
                    assert time.monotonic() < deadline, channels
                    message = json.loads(ws.recv(timeout=20.0))
                    if message["op"] == "serverInfo":
                        assert message["name"] == "groundstation"
                    elif message["op"] == "advertise":
                        channels.update({c["id"]: c for c in message["channels"]})
                topic_of = {}
                subscriptions = []
                for k, (cid, channel) in enumerate(sorted(channels.items()), start=1):
                    topic_of[k] = channel["topic"]
                    subscriptions.append({"id": k, "channelId": cid})
                ws.send(json.dumps({"op": "subscribe", "subscriptions": subscriptions}))

                flying = apply_overrides(cfg, {"serial.port": device.pty_path})
                daemon = FlightDaemon(assemble(flying), duration_s=2.0)
                runner = threading.Thread(target=lambda: out.setdefault("s", daemon.run()))
                runner.start()
                try:
                    last_state_at = time.monotonic()
                    # until the flight is over and its last messages are through
                    while runner.is_alive() or time.monotonic() - last_state_at < 1.0:
                        try:
                            data = ws.recv(timeout=0.5)
                        except TimeoutError:
                            if time.monotonic() - last_state_at > 30.0:
                                break
                            continue
                        if isinstance(data, bytes):
                            assert data[0] == 0x01  # message data
                            sub, log_time = struct.unpack_from("<IQ", data, 1)
                            frames.append((sub, log_time, data[13:]))
                            if topic_of[sub] == fx.STATE:
                                last_state_at = time.monotonic()
                        if time.monotonic() - started > 35.0:
                            break
                finally:
                    runner.join(60.0)
        bridge.send_signal(signal.SIGINT)  # Ctrl-C: the bridge stops cleanly, exit 0
        assert bridge.wait(timeout=20.0) == 0, err_file.read_text()
    finally:
        if bridge.poll() is None:
            bridge.kill()
            bridge.wait(timeout=10.0)
        bridge.stdout.close()
    assert runner is not None and not runner.is_alive()
    assert out["s"].final_state is State.DONE, out["s"].transitions

    # advertised as the table says: typed channels in protobuf, the rest JSON
    by_topic = {c["topic"]: c for c in channels.values()}
    for topic, schema in fx.CHANNELS.items():
        advertised = by_topic[topic]
        assert advertised["schemaName"] == schema
        assert advertised["encoding"] == ("protobuf" if schema.startswith("foxglove.")
                                          else "json")
    descriptors = {topic: _descriptors(base64.b64decode(c["schema"]))
                   for topic, c in by_topic.items() if c["encoding"] == "protobuf"}

    def decoded(topic: str, last: int = 0) -> list[tuple[int, dict[str, Any]]]:
        """The messages of ``topic`` (the ``last`` ones only, if given), decoded."""
        rows = [(t, p) for sub, t, p in frames if topic_of[sub] == topic][-last:]
        if topic in descriptors:
            return [(t, _decode(descriptors[topic], fx.CHANNELS[topic], p)) for t, p in rows]
        return [(t, json.loads(p)) for t, p in rows]

    # the supervisor: the flight's states in order, from the first to the last
    names = [m["name"] for _, m in decoded(fx.SUPERVISOR)]
    seen = [n for k, n in enumerate(names) if k == 0 or n != names[k - 1]]
    assert "TRACK" in seen, seen
    order = ["PREFLIGHT", "TAKEOFF", "TRACK", "LAND", "DISARM", "DONE"]
    assert seen == [n for n in order if n in seen], seen
    assert {"TAKEOFF", "TRACK", "LAND"} <= set(seen), seen

    # log time is the telemetry's time_unix [ns]
    states = decoded(fx.STATE)
    assert len(states) > 50  # 20 Hz for several seconds
    for log_time, payload in states:
        assert log_time == fx.log_time_ns(payload["time_unix"])
    tracking = {t for t, p in states if p["supervisor"]["name"] == "TRACK"}
    assert len(tracking) > 20

    # the poses decode with their advertised schema; while tracking, estimate ~ reference
    estimates = dict(decoded(fx.POSE_ESTIMATE))
    references = dict(decoded(fx.POSE_REFERENCE))
    close = 0
    for t in tracking:
        est, ref = estimates[t], references[t]
        assert est["frame_id"] == ref["frame_id"] == "ned"
        assert est["timestamp"]["seconds"] * 10**9 + est["timestamp"].get("nanos", 0) == t
        p_est, p_ref = _vec(est["pose"]["position"]), _vec(ref["pose"]["position"])
        assert p_ref[2] == pytest.approx(-1.0, abs=0.05)  # hover at 1 m
        assert np.linalg.norm(p_est - p_ref) < 0.5
        close += int(np.linalg.norm(p_est - p_ref) < 0.15)
        q = _vec(est["pose"]["orientation"], "xyzw")
        assert np.linalg.norm(q) == pytest.approx(1.0, abs=1e-9)
        assert Rotation.from_quat(q).magnitude() < 0.3  # about level, nose north
    assert close > 0.8 * len(tracking)

    # /tf: ned -> base_link follows the estimate; world -> ned is there
    for t, msg in decoded(fx.TF):
        frames_of = {tr["child_frame_id"]: tr for tr in msg["transforms"]}
        assert frames_of["ned"]["parent_frame_id"] == "world"
        if t in tracking:
            body = frames_of["base_link"]
            assert body["parent_frame_id"] == "ned"
            np.testing.assert_allclose(_vec(body["translation"]),
                                       _vec(estimates[t]["pose"]["position"]))

    # the reference path: a line strip at 1 m while tracking
    assert len([sub for sub, _, _ in frames if topic_of[sub] == fx.PATH_REFERENCE]) >= 5
    (entity,) = decoded(fx.PATH_REFERENCE, last=1)[0][1]["entities"]
    assert entity["frame_id"] == "ned" and entity["id"] == "reference"
    points = entity["lines"][0]["points"]
    assert len(points) > 20 and min(p.get("z", 0.0) for p in points) < -0.9
    (entity,) = decoded(fx.PATH_ESTIMATE, last=1)[0][1]["entities"]
    assert entity["id"] == "estimate" and len(entity["lines"][0]["points"]) > 20
    assert decoded(fx.HEALTH, last=1)[0][1]["topic"] == "health"
