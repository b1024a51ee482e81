"""End to end in real time: `gs fly`'s daemon against the virtual lab over a real pty and UDP.

Each flight serves every assertion it can: the first is also the exclusive port's flight
(a second `gs fly` on the flying vehicle's port is refused without a byte on the wire).

The virtual X-3D runs on a pseudo-terminal and the virtual Vicon sends real UDP
datagrams on loopback; the daemon opens the pty with pyserial, binds the UDP port,
records its flight log and publishes telemetry that a subscriber in the test reads.
Ground truth comes from the virtual lab's truth file.
"""

from __future__ import annotations

import threading
import time
from pathlib import Path

import numpy as np
import pytest
from lab_helpers import free_udp_port

from groundstation.app.daemon import FlightDaemon, FlightSummary
from groundstation.app.fly import fly_command
from groundstation.app.recorder import read_flight
from groundstation.config import apply_overrides, dump_config, load_config
from groundstation.flight.assembly import assemble
from groundstation.flight.supervisor import State
from groundstation.telemetry.requests import send_request
from groundstation.telemetry.subscriber import TelemetrySubscriber
from sim_device.realtime import SimDeviceProcess

REPO = Path(__file__).resolve().parents[1]


@pytest.mark.realtime
@pytest.mark.slow
def test_real_time_flight_over_pty_and_udp(tmp_path: Path) -> None:
    cfg = apply_overrides(load_config(REPO / "config" / "sim.yaml"), {
        "trajectory.name": "hover", "vicon.port": free_udp_port(),
        "telemetry.endpoint": "tcp://127.0.0.1:*", "logging.flight_log_dir": str(tmp_path),
        "telemetry.control_endpoint": "tcp://127.0.0.1:*",
        "sim.truth_file": str(tmp_path / "truth.npz"), "logging.mcap": True,
    })
    # The virtual vehicle in its own process: a stall of this one (a loaded machine)
    # cannot stop the vehicle's clock and fake a watchdog expiry, which would make the
    # flight end as a failsafe.
    cfg_file = tmp_path / "lab.yaml"
    cfg_file.write_text(dump_config(cfg), encoding="utf-8")
    with SimDeviceProcess(cfg_file, tmp_path / "truth.npz") as device:
        cfg = apply_overrides(cfg, {"serial.port": device.pty_path})
        daemon = FlightDaemon(assemble(cfg), duration_s=3.0)
        out: dict[str, FlightSummary] = {}
        runner = threading.Thread(target=lambda: out.setdefault("s", daemon.run()))
        runner.start()
        assert daemon.ready.wait(10.0)
        assert daemon.telemetry_endpoint is not None
        client = TelemetrySubscriber(daemon.telemetry_endpoint)
        try:
            topics: dict[str, dict[str, object]] = {}
            for _ in range(400):  # bounded: telemetry arrives at 20 Hz
                msg = client.receive(timeout=0.1)
                if msg is not None:
                    topics[msg[0]] = msg[1]
                if {"state", "health"} <= topics.keys() and \
                        topics["state"]["supervisor"]["name"] == "TRACK":  # type: ignore[index]
                    break
            # While tracking, a second `gs fly` on this vehicle's port, as a mistaken
            # operator starts it (the same configuration): refused before it sends a
            # byte (it used to fail on the Vicon bind and send ctrl mask 0 on its way out:
            # 6 ms with the pilot). The vehicle stamps every frame that reaches it.
            echoed: list[str] = []
            t_second = time.monotonic()
            second = fly_command(assemble(cfg), echo=echoed.append)
            t_second_end = time.monotonic()
            time.sleep(0.2)  # the wire window below ends before the handover
            # Then hand yaw to the pilot and back over the request socket (what
            # `gs channels` does).
            assert daemon.control_endpoint is not None
            handed = send_request(daemon.control_endpoint,
                                  {"request": "channels", "auto": ["pitch", "roll", "thrust"]})
            time.sleep(0.5)
            back = send_request(daemon.control_endpoint,
                                {"request": "channels", "auto": ["pitch", "roll", "yaw", "thrust"]})
            runner.join(60.0)
            assert not runner.is_alive()
            # The flight's last message says how it ended (what `gs monitor` shows last).
            final: dict[str, object] = {}
            while (msg := client.receive(timeout=0.5)) is not None:
                if msg[0] == "state" and msg[1].get("final"):
                    final = msg[1]
        finally:
            client.close()
        # Keep the lab running past the command link's delay and the 100 ms watchdog so
        # the truth log shows the final COMMAND (ctrl mask 0) applied.
        time.sleep(0.3)
    summary = out["s"]
    assert second == 3, echoed  # could not start
    assert any("in use" in line for line in echoed), echoed
    wire = device.wire
    assert wire is not None
    during = (wire.command_in >= t_second) & (wire.command_in <= t_second_end + 0.05)
    assert during.any() and np.all(wire.command_mask[during] == 0xF)  # only the first's
    assert len(wire.config_in) == 1 and wire.config_in[0] < t_second  # the first's, at its start
    assert {"state", "health"} <= topics.keys()
    assert handed == {"ok": True, "auto": ["pitch", "roll", "thrust"], "state": "TRACK"}
    assert back == {"ok": True, "auto": ["pitch", "roll", "yaw", "thrust"], "state": "TRACK"}
    assert topics["state"]["supervisor"]["name"] in {s.name for s in State}  # type: ignore[index]
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
    truth = np.load(tmp_path / "truth.npz")
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
    import json

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
@pytest.mark.timeout(300)  # two processes of up to 110 s each on a loaded machine
def test_demo_keeps_the_truth_with_the_log_and_reports_against_it(tmp_path: Path) -> None:
    """`gs fly --demo` (what `make demo` runs): the lab's truth ends up inside the flight's
    directory, and the flight's report is judged against it, not against the estimate."""
    import json
    import subprocess
    import sys

    out = subprocess.run(
        [sys.executable, "-m", "groundstation", "fly", "--config",
         str(REPO / "config" / "sim.yaml"), "--demo", "--trajectory", "hover", "--duration", "2",
         "--log-dir", str(tmp_path)],
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
    # `gs report LOG` on the demo's log finds the truth kept in its directory
    again = subprocess.run([sys.executable, "-m", "groundstation", "report", str(log),
                            "--out", str(tmp_path / "again")], capture_output=True, text=True,
                           timeout=110, cwd=REPO)
    assert again.returncode == 0, again.stderr
    metrics = json.loads((tmp_path / "again" / "metrics.json").read_text())
    assert metrics["truth_file"] == str(log / "truth.npz")


@pytest.mark.realtime
@pytest.mark.slow
def test_real_time_flight_in_the_asctec_ll_dialect(tmp_path: Path) -> None:
    """`gs fly --protocol asctec-ll`'s daemon against the virtual LL vehicle over a pty:
    polled IMU at 100 Hz, acknowledged commands, take-off, hover, landing and handback,
    judged from the lab's truth."""
    cfg = apply_overrides(load_config(REPO / "config" / "sim.yaml"), {
        "serial.protocol": "asctec-ll", "trajectory.name": "hover",
        "vicon.port": free_udp_port(), "telemetry.endpoint": "tcp://127.0.0.1:*",
        "logging.flight_log_dir": str(tmp_path), "telemetry.control_endpoint": None,
        "sim.truth_file": str(tmp_path / "truth.npz"),
    })
    cfg_file = tmp_path / "lab.yaml"
    cfg_file.write_text(dump_config(cfg), encoding="utf-8")
    with SimDeviceProcess(cfg_file, tmp_path / "truth.npz") as device:
        summary = FlightDaemon(assemble(apply_overrides(cfg, {"serial.port": device.pty_path})),
                               duration_s=4.0).run()
        time.sleep(0.3)  # the final ctrl mask 0 reaches the vehicle
    assert summary.final_state is State.DONE and summary.success, summary.transitions
    rows, meta, _ = read_flight(summary.log_dir)
    link = meta["outcome"]["link"]
    assert link["protocol"] == "asctec-ll"
    assert link["polls_unanswered"] <= 0.01 * link["polls"]
    assert link["acks_missing"] <= 0.01 * link["acks"]
    assert 0.015 < link["ack_p50_ms"] / 1e3 < link["ack_p99_ms"] / 1e3 < 0.08
    assert link["in_line_share"] < 1.0 and link["out_line_share"] < 0.5
    # the IMU came at the polled 100 Hz, each sample once (no repeats without a counter)
    tracking = rows["state"] == int(State.TRACK)
    interval = np.diff(np.unique(rows["imu_t"][tracking]))
    assert 0.009 < float(np.median(interval)) < 0.011
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
    cfg = apply_overrides(load_config(REPO / "config" / "sim.yaml"), {
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
