"""End to end in real time: `gs fly`'s daemon against the virtual lab over a real pty and UDP.

Each flight serves every assertion it can. The X-3D flight (module-scoped ``x3d_flight``)
is also the exclusive port's flight (a second `gs fly` on the flying vehicle's port is
refused without a byte on the wire) and the flight `gs foxglove` shows a WebSocket
client (the bridge in its own process, as a user runs it). The AscTec LL dialect flies
twice: once to the end (take-off, hover, landing, handback) and once into a vehicle that
stops answering polls; a link loss is terminal, so those two cannot be one flight.

The virtual X-3D runs on a pseudo-terminal and the virtual Vicon sends real UDP
datagrams on loopback; the daemon opens the pty with pyserial, binds the UDP port,
records its flight log and publishes telemetry that a subscriber in the test reads.
Ground truth comes from the virtual lab's truth file.
"""

from __future__ import annotations

import base64
import contextlib
import json
import select
import signal
import struct
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from lab_helpers import realtime_sim_config
from scipy.spatial.transform import Rotation
from test_foxglove import _decode as decode
from test_foxglove import _descriptors as descriptors
from test_foxglove import _vec as vec

from groundstation.app.daemon import FlightDaemon, FlightSummary
from groundstation.app.fly import fly_command
from groundstation.app.recorder import read_flight
from groundstation.config import GroundStationConfig, apply_overrides, dump_config
from groundstation.endpoints import free_ports, free_udp_port
from groundstation.flight.assembly import assemble
from groundstation.flight.supervisor import State
from groundstation.telemetry import foxglove as fx
from groundstation.telemetry.requests import send_request
from groundstation.telemetry.subscriber import TelemetrySubscriber
from sim_device.realtime import SimDeviceProcess
from sim_device.wire import WireRecord

REPO = Path(__file__).resolve().parents[1]
GS_IN_PROCESS = [sys.executable, "-c", "import sys; from groundstation.cli import main; "
                 "sys.argv[0] = 'gs'; main()"]


def _free_tcp_port() -> int:
    return free_ports(1)[0]


def _read_line(stream: Any, timeout: float) -> str:
    """One line from a child's pipe within ``timeout`` seconds (AssertionError if not)."""
    if not select.select([stream], [], [], timeout)[0]:
        raise AssertionError(f"no line from the child within {timeout} s")
    return str(stream.readline().decode())


@dataclass
class Foxglove:
    """`gs foxglove` in its own process and a plain WebSocket client of it (the
    ``websockets`` library), as Foxglove Studio would connect: serverInfo, advertise,
    subscribe, then binary messages (opcode 0x01, uint32 subscription, uint64 log time
    [ns], payload; little-endian) read in a thread of their own while the flight runs."""

    endpoint: str
    err_file: Path
    bridge: subprocess.Popen[bytes] | None = None
    ws: Any = None
    subprotocol: str | None = None
    server_name: str | None = None
    channels: dict[int, dict[str, Any]] = field(default_factory=dict)
    topic_of: dict[int, str] = field(default_factory=dict)
    frames: list[tuple[int, int, bytes]] = field(default_factory=list)
    """(subscription, log time [ns], payload) of every binary message."""
    error: BaseException | None = None
    """What stopped the reader before the flight's last messages, if anything."""
    exit_code: int | None = None
    flight_over: threading.Event = field(default_factory=threading.Event)
    reader: threading.Thread | None = None
    connection: contextlib.ExitStack = field(default_factory=contextlib.ExitStack)

    def start(self) -> None:
        """The bridge first (its SUB socket connects before the daemon binds: zmq
        retries), so the client sees the flight from its start."""
        with self.err_file.open("wb") as err:  # a file, not a pipe nobody reads while flying
            self.bridge = subprocess.Popen(
                [*GS_IN_PROCESS, "foxglove", "--endpoint", self.endpoint, "--port", "0",
                 "--duration", "120"], stdout=subprocess.PIPE, stderr=err, cwd=REPO)

    def connect(self) -> None:
        """Connect, read the advertised channels, subscribe to every one (the virtual
        vehicle starts meanwhile)."""
        websockets = pytest.importorskip("websockets.sync.client")
        from websockets.typing import Subprotocol

        assert self.bridge is not None and self.bridge.stdout is not None
        line = _read_line(self.bridge.stdout, 30.0)
        assert line.startswith("foxglove: serving ws://127.0.0.1:"), (
            line, self.err_file.read_text())
        # What the Foxglove app offers: the protocol's current name and its former one
        # (the same messages); foxglove-sdk 0.30 accepts the current one only.
        offered = [Subprotocol("foxglove.sdk.v1"), Subprotocol("foxglove.websocket.v1")]
        self.ws = self.connection.enter_context(websockets.connect(
            line.split()[2], subprotocols=offered, open_timeout=20, max_size=None))
        self.subprotocol = self.ws.subprotocol
        deadline = time.monotonic() + 20.0
        while set(fx.CHANNELS) - {c["topic"] for c in self.channels.values()}:
            assert time.monotonic() < deadline, self.channels
            message = json.loads(self.ws.recv(timeout=20.0))
            if message["op"] == "serverInfo":
                self.server_name = message["name"]
            elif message["op"] == "advertise":
                self.channels.update({c["id"]: c for c in message["channels"]})
        subscriptions = []
        for k, (cid, channel) in enumerate(sorted(self.channels.items()), start=1):
            self.topic_of[k] = channel["topic"]
            subscriptions.append({"id": k, "channelId": cid})
        self.ws.send(json.dumps({"op": "subscribe", "subscriptions": subscriptions}))
        self.reader = threading.Thread(target=self._read, name="foxglove-client")
        self.reader.start()

    def _read(self) -> None:
        """Every message until the flight is over and its last messages are through."""
        started = time.monotonic()
        last_state_at = started
        try:
            while not self.flight_over.is_set() or time.monotonic() - last_state_at < 1.0:
                try:
                    data = self.ws.recv(timeout=0.5)
                except TimeoutError:
                    if time.monotonic() - last_state_at > 30.0:
                        return
                    continue
                if isinstance(data, bytes):
                    assert data[0] == 0x01, data[:16]  # message data
                    sub, log_time = struct.unpack_from("<IQ", data, 1)
                    self.frames.append((sub, log_time, data[13:]))
                    if self.topic_of[sub] == fx.STATE:
                        last_state_at = time.monotonic()
                if time.monotonic() - started > 120.0:
                    return
        except BaseException as exc:  # judged by the test
            self.error = exc

    def stop(self) -> None:
        """The reader ends; Ctrl-C to the bridge (it stops cleanly: exit 0)."""
        self.flight_over.set()
        if self.reader is not None:
            self.reader.join(60.0)
        self.connection.close()
        if self.bridge is None:
            return
        if self.bridge.poll() is None:
            self.bridge.send_signal(signal.SIGINT)
        try:
            self.exit_code = self.bridge.wait(timeout=20.0)
        except subprocess.TimeoutExpired:
            self.bridge.kill()
            self.bridge.wait(timeout=10.0)
        assert self.bridge.stdout is not None
        self.bridge.stdout.close()


@dataclass
class X3dFlight:
    """What the X-3D flight showed: the daemon's summary and telemetry, the second
    `gs fly`, the pilot handover, the vehicle's wire record and truth, and what a
    Foxglove client saw (None without the foxglove extra)."""

    cfg: GroundStationConfig
    truth_file: Path
    summary: FlightSummary | None = None
    topics: dict[str, dict[str, Any]] = field(default_factory=dict)
    second: int | None = None
    echoed: list[str] = field(default_factory=list)
    t_second: float = 0.0
    t_second_end: float = 0.0
    handed: dict[str, Any] = field(default_factory=dict)
    back: dict[str, Any] = field(default_factory=dict)
    final: dict[str, Any] = field(default_factory=dict)
    wire: WireRecord | None = None
    foxglove: Foxglove | None = None


def _fly_x3d(tmp_path: Path) -> Iterator[X3dFlight]:
    endpoint = f"tcp://127.0.0.1:{_free_tcp_port()}"  # known before the daemon binds it
    cfg = apply_overrides(realtime_sim_config(), {
        "trajectory.name": "hover", "vicon.port": free_udp_port(),
        "telemetry.endpoint": endpoint, "logging.flight_log_dir": str(tmp_path),
        "telemetry.control_endpoint": "tcp://127.0.0.1:*",
        "sim.truth_file": str(tmp_path / "truth.npz"), "logging.mcap": True,
    })
    flight = X3dFlight(cfg, tmp_path / "truth.npz")
    # The virtual vehicle in its own process: a stall of this one (a loaded machine)
    # cannot stop the vehicle's clock and fake a watchdog expiry, which would make the
    # flight end as a failsafe.
    cfg_file = tmp_path / "lab.yaml"
    cfg_file.write_text(dump_config(cfg), encoding="utf-8")
    with contextlib.ExitStack() as stack:
        if _has_foxglove():
            flight.foxglove = Foxglove(endpoint, tmp_path / "bridge.err")
            stack.callback(flight.foxglove.stop)
            flight.foxglove.start()
        device = stack.enter_context(SimDeviceProcess(cfg_file, tmp_path / "truth.npz"))
        if flight.foxglove is not None:
            flight.foxglove.connect()
        _fly_over_pty(flight, apply_overrides(cfg, {"serial.port": device.pty_path}))
        if flight.foxglove is not None:
            flight.foxglove.flight_over.set()
        # Keep the lab running past the command link's delay and the 100 ms watchdog so
        # the truth log shows the final COMMAND (ctrl mask 0) applied.
        time.sleep(0.3)
        stack.pop_all().close()  # the lab, then the bridge, stop
        flight.wire = device.wire
        yield flight


def _has_foxglove() -> bool:
    try:
        import foxglove  # noqa: F401
        import websockets.sync.client  # noqa: F401
    except ImportError:
        return False
    return True


def _fly_over_pty(flight: X3dFlight, cfg: GroundStationConfig) -> None:
    """Fly the 3 s hover with the daemon in this process; on the way a second `gs fly` and
    the pilot's handover of yaw."""
    daemon = FlightDaemon(assemble(cfg), duration_s=3.0)
    out: dict[str, FlightSummary] = {}
    runner = threading.Thread(target=lambda: out.setdefault("s", daemon.run()))
    runner.start()
    try:
        assert daemon.ready.wait(10.0)
        assert daemon.telemetry_endpoint is not None
        client = TelemetrySubscriber(daemon.telemetry_endpoint)
        try:
            topics = flight.topics
            for _ in range(400):  # bounded: telemetry arrives at 20 Hz
                msg = client.receive(timeout=0.1)
                if msg is not None:
                    topics[msg[0]] = msg[1]
                if {"state", "health"} <= topics.keys() and \
                        topics["state"]["supervisor"]["name"] == "TRACK":
                    break
            # While tracking, a second `gs fly` on this vehicle's port, as a mistaken
            # operator starts it (the same configuration): refused before it sends a
            # byte (it used to fail on the Vicon bind and send ctrl mask 0 on its way out:
            # 6 ms with the pilot). The vehicle stamps every frame that reaches it.
            flight.t_second = time.monotonic()
            flight.second = fly_command(assemble(cfg), echo=flight.echoed.append)
            flight.t_second_end = time.monotonic()
            time.sleep(0.2)  # the wire window below ends before the handover
            # Then hand yaw to the pilot and back over the control socket (what
            # `gs channels` does).
            assert daemon.control_endpoint is not None
            flight.handed = send_request(
                daemon.control_endpoint, {"request": "channels",
                                          "auto": ["pitch", "roll", "thrust"]})
            time.sleep(0.5)
            flight.back = send_request(
                daemon.control_endpoint, {"request": "channels",
                                          "auto": ["pitch", "roll", "yaw", "thrust"]})
            runner.join(60.0)
            assert not runner.is_alive()
            # The flight's last message says how it ended (what `gs monitor` shows last).
            while (msg := client.receive(timeout=0.5)) is not None:
                if msg[0] == "state" and msg[1].get("final"):
                    flight.final = msg[1]
        finally:
            client.close()
    finally:
        runner.join(60.0)
    flight.summary = out["s"]


@pytest.fixture(scope="module")
def x3d_flight(tmp_path_factory: pytest.TempPathFactory) -> Iterator[X3dFlight]:
    yield from _fly_x3d(tmp_path_factory.mktemp("x3d"))


@pytest.mark.realtime
@pytest.mark.slow
def test_real_time_flight_over_pty_and_udp(x3d_flight: X3dFlight) -> None:
    flight = x3d_flight
    summary, topics, final, echoed = flight.summary, flight.topics, flight.final, flight.echoed
    assert summary is not None
    assert flight.second == 3, echoed  # could not start
    assert any("in use" in line for line in echoed), echoed
    wire = flight.wire
    assert wire is not None
    during = (wire.command_in >= flight.t_second) & (
        wire.command_in <= flight.t_second_end + 0.05)
    assert during.any() and np.all(wire.command_mask[during] == 0xF)  # only the first's
    # the first's, at its start
    assert len(wire.config_in) == 1 and wire.config_in[0] < flight.t_second
    assert {"state", "health"} <= topics.keys()
    assert flight.handed == {"ok": True, "auto": ["pitch", "roll", "thrust"], "state": "TRACK"}
    assert flight.back == {"ok": True, "auto": ["pitch", "roll", "yaw", "thrust"],
                           "state": "TRACK"}
    assert topics["state"]["supervisor"]["name"] in {s.name for s in State}
    assert final["supervisor"] == {"state": int(State.DONE), "name": "DONE"}
    assert final["outcome"] == "COMPLETED" and final["reason"] == summary.reason
    assert isinstance(final["flight_time_s"], float)
    assert abs(final["flight_time_s"] - summary.duration_s) < 0.5
    # The vehicle's own report is published: its battery (11.8 V, drooping slowly) and
    # that it applies all four channels while tracking.
    vehicle = topics["state"]["vehicle"]
    assert isinstance(vehicle, dict)
    assert 11.7 < vehicle["battery_v"] <= 11.8 and vehicle["serial_active"]
    assert vehicle["applied_mask"] == 0xF and vehicle["pilot_enabled"]

    # Took off, hovered, landed and handed back; exit code 0 for `gs fly`.
    assert summary.final_state is State.DONE and summary.success, summary.transitions
    assert [tr.new for tr in summary.transitions] == [
        State.TAKEOFF, State.TRACK, State.LAND, State.DISARM, State.DONE]

    # Ground truth: the vehicle flew at 1 m and is back on the floor with the pilot.
    truth = np.load(flight.truth_file)
    hovering = truth["ctrl_mask"] == 0xF
    assert -truth["position"][hovering, 2].min() > 0.9
    assert truth["on_ground"][-1] and truth["ctrl_mask"][-1] == 0
    assert np.abs(truth["position"][-1, :2]).max() < 0.1

    # The flight log is complete: every tick recorded, readable in one line, states named.
    rows, meta, config_text = read_flight(summary.log_dir)
    assert meta["supervisor_states"][rows["state"][-1]] in ("DISARM", "DONE")
    assert len(rows) >= 0.9 * summary.ticks
    assert "sim:" in config_text and meta["version"]
    assert np.all(np.diff(rows["t"]) > 0)
    assert np.all((rows["battery_v"] > 11.7) & (rows["battery_v"] <= 11.8))
    tracking = rows["state"] == int(State.TRACK)
    assert np.all(rows["vehicle_flags"][tracking] & 0x01)  # the X-3D applied our commands
    # logging.mcap: the step gs fly runs after the flight writes it as MCAP beside its log,
    # every JSON channel decoding as JSON (the poses and transforms are Foxglove's
    # protobuf schemas)
    from mcap.reader import make_reader

    from groundstation.export import mcap_after_flight

    mcap = Path(summary.log_dir) / "flight.mcap"
    assert mcap_after_flight(Path(summary.log_dir)) == [f"  MCAP (logging.mcap): {mcap}"]
    with open(mcap, "rb") as fh:
        reader = make_reader(fh)
        per_topic: dict[str, int] = {}
        for _schema, channel, message in reader.iter_messages():
            if channel.message_encoding == "json":
                assert isinstance(json.loads(message.data), dict)
            per_topic[channel.topic] = per_topic.get(channel.topic, 0) + 1
    assert per_topic["/imu"] == len(rows) and per_topic["/supervisor"] == len(rows)
    assert {"/estimate", "/vicon", "/command", "/vehicle", "/pose/estimate"} <= set(per_topic)
    link = meta["outcome"].pop("link")
    assert meta["outcome"] == {"outcome": "COMPLETED", "exit_code": 0, "final_state": "DONE",
                               "reason": summary.reason, "failsafe_transitions": [],
                               "events": [], "log": {"complete": True, "rows": len(rows),
                                                     "rows_lost": 0, "reasons": {}}}
    # DATA of status, gyro, acc, rc (41 B) at 100 Hz: 4100 B/s, 71 % of the 5760 B/s line
    assert link["protocol"] == "x3d" and 0.6 < link["in_line_share"] < 0.75
    assert link["rejected"] == 0 and link["unexpected_data"] == 0
    assert summary.commands_sent > 0.4 * summary.ticks  # 50 Hz commands on 100 Hz ticks
    # The handover reached the wire: about 0.5 s of COMMANDs without the yaw bit (25 at
    # 50 Hz; the bound leaves room for a loaded machine), then all four channels again.
    yaw_manual = (rows["cmd_mask"] == 0b1011) & rows["cmd_sent"]
    assert 10 <= yaw_manual.sum() <= 100, yaw_manual.sum()
    assert np.all(rows["state"][yaw_manual] == int(State.TRACK))
    sent_after = np.flatnonzero(rows["cmd_sent"][np.flatnonzero(yaw_manual)[-1] + 1:])
    assert rows["cmd_mask"][np.flatnonzero(yaw_manual)[-1] + 1 + sent_after[0]] == 0xF


@pytest.mark.realtime
@pytest.mark.slow
def test_foxglove_client_sees_the_flight(x3d_flight: X3dFlight) -> None:
    """`gs foxglove` -> the Foxglove WebSocket protocol, live: the X-3D flight as a
    WebSocket client sees it (the conversion itself is tested in test_foxglove.py)."""
    fox = x3d_flight.foxglove
    if fox is None:
        pytest.skip("needs the foxglove extra (foxglove-sdk, websockets)")
    assert fox.subprotocol == "foxglove.sdk.v1"
    assert fox.server_name == "groundstation"
    assert fox.error is None, repr(fox.error)
    assert fox.exit_code == 0, fox.err_file.read_text()  # Ctrl-C: a clean stop
    summary = x3d_flight.summary
    assert summary is not None and summary.final_state is State.DONE, summary
    frames, topic_of = fox.frames, fox.topic_of

    # advertised as the table says: typed channels in protobuf, the rest JSON
    by_topic = {c["topic"]: c for c in fox.channels.values()}
    for topic, schema in fx.CHANNELS.items():
        advertised = by_topic[topic]
        assert advertised["schemaName"] == schema
        assert advertised["encoding"] == ("protobuf" if schema.startswith("foxglove.")
                                          else "json")
    schemas = {topic: descriptors(base64.b64decode(c["schema"]))
               for topic, c in by_topic.items() if c["encoding"] == "protobuf"}

    def decoded(topic: str, last: int = 0) -> list[tuple[int, dict[str, Any]]]:
        """The messages of ``topic`` (the ``last`` ones only, if given), decoded."""
        rows = [(t, p) for sub, t, p in frames if topic_of[sub] == topic][-last:]
        if topic in schemas:
            return [(t, decode(schemas[topic], fx.CHANNELS[topic], p)) for t, p in rows]
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
        p_est, p_ref = vec(est["pose"]["position"]), vec(ref["pose"]["position"])
        assert p_ref[2] == pytest.approx(-1.0, abs=0.05)  # hover at 1 m
        assert np.linalg.norm(p_est - p_ref) < 0.5
        close += int(np.linalg.norm(p_est - p_ref) < 0.15)
        q = vec(est["pose"]["orientation"], "xyzw")
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
            np.testing.assert_allclose(vec(body["translation"]),
                                       vec(estimates[t]["pose"]["position"]))

    # the reference path: a line strip at 1 m while tracking
    assert len([sub for sub, _, _ in frames if topic_of[sub] == fx.PATH_REFERENCE]) >= 5
    (entity,) = decoded(fx.PATH_REFERENCE, last=1)[0][1]["entities"]
    assert entity["frame_id"] == "ned" and entity["id"] == "reference"
    points = entity["lines"][0]["points"]
    assert len(points) > 20 and min(p.get("z", 0.0) for p in points) < -0.9
    (entity,) = decoded(fx.PATH_ESTIMATE, last=1)[0][1]["entities"]
    assert entity["id"] == "estimate" and len(entity["lines"][0]["points"]) > 20
    assert decoded(fx.HEALTH, last=1)[0][1]["topic"] == "health"


@pytest.mark.realtime
@pytest.mark.slow
@pytest.mark.timeout(200)  # a process of up to 110 s on a loaded machine
def test_demo_keeps_the_truth_with_the_log_and_reports_against_it(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """`gs fly --demo` (what `make demo` runs, here with the real-time flights' brisker
    settling, take-off and landing): the lab's truth ends up inside the flight's
    directory, and the flight's report is judged against it, not against the estimate."""
    config = tmp_path / "sim.yaml"
    config.write_text(dump_config(realtime_sim_config()), encoding="utf-8")
    out = subprocess.run(
        [sys.executable, "-m", "groundstation", "fly", "--config", str(config), "--demo",
         "--trajectory", "hover", "--duration", "2", "--log-dir", str(tmp_path)],
        capture_output=True, text=True, timeout=110, cwd=REPO)
    assert out.returncode == 0, out.stdout + out.stderr
    (log,) = [p for p in tmp_path.iterdir() if (p / "meta.json").exists()]
    truth = np.load(log / "truth.npz")
    assert len(truth["t"]) > 100
    report = json.loads((log / "report" / "metrics.json").read_text())
    assert report["truth_file"] == str(log / "truth.npz")
    assert report["metrics"]["final_state"] == "DONE"
    assert (log / "report" / "flight.png").stat().st_size > 10_000
    assert "judged from virtual-lab ground truth" in out.stdout
    # `gs report LOG` on the demo's log finds the truth kept in its directory; the demo
    # drew the figures already (tests/test_report_figures.py tests them), so this one runs
    # in this process without matplotlib: the metrics are written all the same
    from typer.testing import CliRunner

    from groundstation.cli import app

    monkeypatch.setitem(sys.modules, "matplotlib", None)  # import matplotlib -> ImportError
    again = CliRunner().invoke(app, ["report", str(log), "--out", str(tmp_path / "again")])
    assert again.exit_code == 0, again.output
    assert "no figures" in again.output, again.output
    metrics = json.loads((tmp_path / "again" / "metrics.json").read_text())
    assert metrics["truth_file"] == str(log / "truth.npz")
    assert metrics["metrics"] == report["metrics"]


@pytest.mark.realtime
@pytest.mark.slow
def test_real_time_flight_in_the_asctec_ll_dialect(tmp_path: Path) -> None:
    """`gs fly --protocol asctec-ll`'s daemon against the virtual LL vehicle over a pty:
    polled IMU at 100 Hz, acknowledged commands, take-off, hover, landing and handback,
    judged from the lab's truth."""
    cfg = apply_overrides(realtime_sim_config(), {
        "serial.protocol": "asctec-ll", "trajectory.name": "hover",
        "vicon.port": free_udp_port(), "telemetry.endpoint": "tcp://127.0.0.1:*",
        "logging.flight_log_dir": str(tmp_path), "telemetry.control_endpoint": None,
        "sim.truth_file": str(tmp_path / "truth.npz"),
    })
    cfg_file = tmp_path / "lab.yaml"
    cfg_file.write_text(dump_config(cfg), encoding="utf-8")
    with SimDeviceProcess(cfg_file, tmp_path / "truth.npz") as device:
        summary = FlightDaemon(assemble(apply_overrides(cfg, {"serial.port": device.pty_path})),
                               duration_s=2.0).run()
        time.sleep(0.3)  # the final ctrl mask 0 reaches the vehicle
    assert summary.final_state is State.DONE and summary.success, summary.transitions
    rows, meta, _ = read_flight(summary.log_dir)
    link = meta["outcome"]["link"]
    assert link["protocol"] == "asctec-ll"
    assert link["polls_unanswered"] <= 0.01 * link["polls"]
    assert link["acks_missing"] <= 0.01 * link["acks"]
    assert 0.015 < link["ack_p50_ms"] / 1e3 < link["ack_p99_ms"] / 1e3 < 0.08
    assert link["in_line_share"] < 1.0 and link["out_line_share"] < 0.5
    # the IMU came at the polled 100 Hz, each sample once (no repeats without a counter):
    # the rate over the hover, not the median interval between receive times, which a
    # loaded machine bunches (8.9994 ms once beside a busy loop, the rate still 100 Hz)
    tracking = rows["state"] == int(State.TRACK)
    samples = np.unique(rows["imu_t"][tracking])
    rate_hz = (len(samples) - 1) / float(samples[-1] - samples[0])
    assert 90.0 < rate_hz < 110.0 and len(samples) > 150, (rate_hz, len(samples))
    assert np.all(rows["vehicle_flags"][tracking] & 0x01)  # applying our commands
    truth = np.load(tmp_path / "truth.npz")
    hovering = truth["ctrl_mask"] == 0xF
    assert -truth["position"][hovering, 2].min() > 0.9
    assert truth["on_ground"][-1] and truth["ctrl_mask"][-1] == 0


@pytest.mark.realtime
@pytest.mark.slow
def test_an_ll_vehicle_that_stops_answering_polls_is_link_loss(tmp_path: Path) -> None:
    """The virtual LL vehicle stops answering polls in the air (its commands still reach
    it): the daemon stops at link loss, never flies blind, and the vehicle's fallback
    hands every channel back to the pilot."""
    cfg = apply_overrides(realtime_sim_config(), {
        "serial.protocol": "asctec-ll", "trajectory.name": "hover",
        "vicon.port": free_udp_port(), "telemetry.endpoint": "tcp://127.0.0.1:*",
        "logging.flight_log_dir": str(tmp_path), "telemetry.control_endpoint": None,
        "sim.truth_file": str(tmp_path / "truth.npz"),
        "sim.faults.stall_at_s": 9.0, "sim.faults.stall_duration_s": 30.0,
    })
    cfg_file = tmp_path / "lab.yaml"
    cfg_file.write_text(dump_config(cfg), encoding="utf-8")
    with SimDeviceProcess(cfg_file, tmp_path / "truth.npz") as device:
        summary = FlightDaemon(assemble(apply_overrides(cfg, {"serial.port": device.pty_path})),
                               duration_s=30.0).run()
        time.sleep(0.3)
    assert summary.final_state is State.LINK_LOST and not summary.success
    assert summary.transitions[-1].failsafe
    truth = np.load(tmp_path / "truth.npz")
    assert truth["ctrl_mask"][-1] == 0  # the fallback gave the pilot the vehicle
    assert (truth["ctrl_mask"] == 0xF).any()  # it was flying on our commands before
