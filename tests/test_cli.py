"""The `gs` commands that wrap the evaluation, export, replay and the request socket, end to
end through typer."""

from __future__ import annotations

import json
import threading
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from groundstation.cli import app
from groundstation.flight.assembly import assemble
from groundstation.telemetry.requests import RequestServer

REPO = Path(__file__).resolve().parents[1]
runner = CliRunner()


@pytest.mark.slow
def test_eval_fast_one_scenario(tmp_path: Path) -> None:
    out = tmp_path / "eval"
    res = runner.invoke(app, ["eval", "--config", str(REPO / "config" / "sim.yaml"), "--fast",
                              "--scenario", "hover-100hz", "--out", str(out)])
    assert res.exit_code == 0, res.output
    metrics = json.loads((out / "metrics.json").read_text())["scenarios"]["hover-100hz"]
    assert metrics["metrics"]["final_state"] == "DONE"
    assert metrics["metrics"]["truth"] == "virtual-lab ground truth"
    assert 0.0 < metrics["metrics"]["rms_m"] < 0.01  # a hover at 100 Hz Vicon: millimetres
    assert "| `hover-100hz` |" in (out / "report.md").read_text()


def test_eval_rejects_an_unknown_scenario() -> None:
    res = runner.invoke(app, ["eval", "--config", str(REPO / "config" / "sim.yaml"), "--fast",
                              "--scenario", "loop-the-loop"])
    assert res.exit_code == 2
    assert "loop-the-loop" in res.output


@pytest.mark.slow
def test_report_and_export_of_a_recorded_flight(tmp_path: Path) -> None:
    from groundstation.app.inprocess import fly_in_process
    from groundstation.app.recorder import FlightRecorder
    from groundstation.config import apply_overrides, dump_config, load_config
    from groundstation.flight.supervisor import State

    cfg = apply_overrides(load_config(REPO / "config" / "sim.yaml"), {"trajectory.name": "hover"})
    with FlightRecorder.create(tmp_path, dump_config(cfg),
                               {"supervisor_states": [s.name for s in State]}) as rec:
        fly_in_process(assemble(cfg), duration_s=3.0, max_time_s=40.0, recorder=rec)
        log = rec.directory
    res = runner.invoke(app, ["report", str(log), "--out", str(tmp_path / "rep")])
    assert res.exit_code == 0, res.output
    assert (tmp_path / "rep" / "metrics.json").exists()
    csv = tmp_path / "flight.csv"
    res = runner.invoke(app, ["export", str(log), "--out", str(csv)])
    assert res.exit_code == 0, res.output
    import pandas as pd

    table = pd.read_csv(csv)  # `name [unit]` headers, as the README reads it
    assert len(table) > 500 and "est_position_x [m]" in table.columns
    assert table["state_name"].iloc[-1] == "DONE"
    np.testing.assert_allclose(table["battery_v [V]"], np.load(log / "flight.npy")["battery_v"],
                               rtol=0, atol=5e-4)  # to the mV STATUS reports


def test_channels_talks_to_the_control_socket() -> None:
    seen: list[dict[str, object]] = []

    def handler(request: dict[str, object]) -> dict[str, object]:
        seen.append(request)
        if request.get("auto") == ["yaw"]:  # the daemon's refusal (here: in a test's mood)
            return {"ok": False, "error": "yaw alone is not allowed now"}
        return {"ok": True, "auto": ["thrust"], "state": "TRACK"}

    with RequestServer("tcp://127.0.0.1:*") as server:
        assert server.endpoint is not None
        stop = threading.Event()

        def serve() -> None:
            while not stop.wait(0.001):
                server.poll(handler)

        thread = threading.Thread(target=serve, daemon=True)
        thread.start()
        try:
            ok = runner.invoke(app, ["channels", "thrust", "--endpoint", server.endpoint])
            refused = runner.invoke(app, ["channels", "yaw", "--control", server.endpoint])
            bad = runner.invoke(app, ["channels", "elevator", "--endpoint", server.endpoint])
        finally:
            stop.set()
            thread.join(5.0)
    assert ok.exit_code == 0 and "automatic: thrust  (state TRACK)" in ok.output
    assert refused.exit_code == 1 and "yaw alone is not allowed now" in refused.output
    # not a channel: a usage error, named, and nothing sent
    assert bad.exit_code == 2 and "unknown channel 'elevator'" in bad.output
    assert seen == [{"request": "channels", "auto": ["thrust"]},
                    {"request": "channels", "auto": ["yaw"]}]


@pytest.mark.slow
def test_channels_with_curve_keys(tmp_path: Path) -> None:
    import zmq.auth

    from groundstation.telemetry.curve import load_server_keys

    (tmp_path / "clients").mkdir()
    server, _ = zmq.auth.create_certificates(tmp_path, "server")
    zmq.auth.create_certificates(tmp_path / "clients", "alice")
    alice = str(tmp_path / "clients" / "alice.key_secret")
    curve = load_server_keys(tmp_path / "server.key_secret", tmp_path / "clients")
    reply = {"ok": True, "auto": ["thrust"], "state": "TRACK"}
    with RequestServer("tcp://127.0.0.1:*", curve=curve) as control:
        assert control.endpoint is not None
        stop = threading.Event()

        def serve() -> None:
            while not stop.wait(0.001):
                control.poll(lambda request: reply)

        thread = threading.Thread(target=serve, daemon=True)
        thread.start()
        try:
            ok = runner.invoke(app, ["channels", "thrust", "--endpoint", control.endpoint,
                                     "--server-key", server, "--client-key", alice])
            keyless = runner.invoke(app, ["channels", "--endpoint", control.endpoint,
                                          "--timeout", "0.3"])
            half = runner.invoke(app, ["channels", "--endpoint", control.endpoint,
                                       "--server-key", server])
            public_only = runner.invoke(app, ["channels", "--endpoint", control.endpoint,
                                              "--server-key", server, "--client-key", server])
        finally:
            stop.set()
            thread.join(5.0)
    assert ok.exit_code == 0 and "automatic: thrust  (state TRACK)" in ok.output, ok.output
    assert keyless.exit_code == 1 and "--server-key" in keyless.output
    assert half.exit_code == 2 and "go together" in half.output
    assert public_only.exit_code == 2 and "no secret key" in public_only.output


def test_channels_without_a_daemon_fails_clearly() -> None:
    res = runner.invoke(app, ["channels", "--endpoint", "tcp://127.0.0.1:9", "--timeout", "0.2"])
    assert res.exit_code == 1 and "no reply from tcp://127.0.0.1:9 within 0.2 s" in res.output


def _config_file(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "gs.yaml"
    path.write_text(text)
    return path


@pytest.mark.slow
def test_check_config_refuses_a_trajectory_outside_the_volume(tmp_path: Path) -> None:
    good = runner.invoke(app, ["check-config", "--show", str(_config_file(
        tmp_path, "trajectory:\n  name: square\n"))])
    assert good.exit_code == 0, good.output
    assert "shaping: min-jerk" in good.output
    bad = _config_file(tmp_path, "trajectory:\n  name: square\n  center: [0.0, 1.2, -1.0]\n")
    res = runner.invoke(app, ["check-config", str(bad)])
    assert res.exit_code == 2
    assert ("y = 1.57 m is outside safety.volume_y [-1.50, 1.50] less the 0.10 m margin"
            in res.output)
    # gs fly refuses the same file before connecting to anything (a software port, in case)
    fly = runner.invoke(app, ["fly", "--config", str(bad), "--serial-port", "loop://"])
    assert fly.exit_code == 2 and "outside safety.volume_y" in fly.output


def test_check_config_refuses_a_missing_waypoint_file(tmp_path: Path) -> None:
    missing = tmp_path / "absent.csv"
    res = runner.invoke(app, ["check-config", str(_config_file(
        tmp_path, f"trajectory:\n  name: waypoints\n  file: {missing}\n"))])
    assert res.exit_code == 2 and f"trajectory.file: '{missing}': no such file" in res.output


def test_fly_help_documents_every_exit_code() -> None:
    """`gs fly --help` names each exit code `gs fly` can return."""
    from groundstation.app.fly import EXIT_CODES

    result = runner.invoke(app, ["fly", "--help"], terminal_width=100)
    assert result.exit_code == 0
    text = " ".join(result.output.split())
    for code, meaning in EXIT_CODES.items():
        first_words = " ".join(meaning.split()[:2]).rstrip(":,")
        assert f"{code} {first_words}" in text, (code, first_words)


def test_fly_on_a_port_that_is_not_there_exits_3(tmp_path: Path) -> None:
    """Could not start: nothing was connected, nothing sent."""
    cfg = tmp_path / "fly.yaml"
    cfg.write_text(f"serial:\n  port: {tmp_path / 'no-such-tty'}\nlogging:\n"
                   f"  flight_log_dir: {tmp_path / 'logs'}\n", encoding="utf-8")
    result = runner.invoke(app, ["fly", "--config", str(cfg), "--trajectory", "hover"])
    assert result.exit_code == 3, result.output
    assert "cannot open serial port" in result.output
