"""``gs link-check`` against ``gs sim-device`` over a real pty, in both dialects.

Healthy and unhealthy links (a corrupting line, a stalled stream, the serial-enable
switch off), and the vehicle's own record (the ground truth's wire log and applied
ctrl mask) shows that nothing that moves it was written: the X-3D received CONFIG and
no COMMAND, the LL vehicle polls and no command. Real time: run under the shared lock
(``flock /tmp/realtime.lock``). The healthy X-3D check runs the ``gs`` executable as a
person would; the others run the same command in this process (no second interpreter's
imports on a loaded machine, and the stall's timing stays inside the window).
"""

from __future__ import annotations

import json
import subprocess
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import serial
from lab_helpers import sim_config
from typer.testing import CliRunner

from groundstation.cli import app
from groundstation.config import dump_config
from groundstation.endpoints import free_udp_port
from sim_device.realtime import SimDeviceProcess

GS = Path(sys.executable).parent / "gs"
runner = CliRunner()


@contextmanager
def virtual_vehicle(tmp_path: Path, protocol: str = "x3d",
                    **overrides: Any) -> Iterator[tuple[SimDeviceProcess, Path]]:
    """``gs sim-device`` in a child process with ``overrides`` (dotted keys); yields it and
    the configuration file a link check reads."""
    cfg = sim_config(**{"vicon.port": free_udp_port(), "serial.protocol": protocol,
                        "logging.flight_log_dir": str(tmp_path / "logs"), **overrides})
    cfg_file = tmp_path / "lab.yaml"
    cfg_file.write_text(dump_config(cfg), encoding="utf-8")
    with SimDeviceProcess(cfg_file, tmp_path / "truth.npz", duration=120.0,
                          stderr=tmp_path / "sim.err") as device:
        yield device, cfg_file


def check(cfg_file: Path, port: str, *args: str) -> tuple[int, dict[str, Any]]:
    """``gs link-check --json`` in this process: (exit code, the report)."""
    result = runner.invoke(app, ["link-check", "-c", str(cfg_file), "--serial-port", port,
                                 "--json", *args])
    assert result.output.strip(), result
    return result.exit_code, json.loads(result.output.strip().splitlines()[-1])


def assert_nothing_moved_it(truth_file: Path, *, configs: bool) -> None:
    """From the vehicle's side: no command arrived (X-3D: CONFIG did), it never applied a
    ground-station channel, and its applied sticks were the pilot's (all zero here)."""
    with np.load(truth_file) as truth:
        assert len(truth["wire_command_in"]) == 0
        assert (len(truth["wire_config_in"]) > 0) == configs
        assert int(np.max(truth["ctrl_mask"])) == 0
        assert not np.any(truth["serial_active"])
        assert not np.any(truth["sticks"])


@pytest.mark.virtual_vehicle
def test_healthy_x3d_link_as_a_user_runs_it(tmp_path: Path) -> None:
    with virtual_vehicle(tmp_path) as (device, cfg_file):
        done = subprocess.run([str(GS), "link-check", "-c", str(cfg_file), "--serial-port",
                               device.pty_path, "--seconds", "3"], capture_output=True,
                              text=True, timeout=60)
    assert done.returncode == 0, done.stdout + done.stderr
    lines = done.stdout.splitlines()
    assert lines[-1] == "verdict: healthy"
    text = done.stdout
    assert "(x3d)" in lines[0] and "never a command" in lines[0]
    assert "serial-enable ON" in text and "applies ctrl mask 0x0" in text
    assert "status" in text and "gyro" in text and "acc" in text and "rc" in text
    # the DATA rate: 100 Hz configured (10 ms); the virtual X-3D paces it on its clock
    rate = float(next(x for x in lines if x.strip().startswith("DATA")).split(",")[1]
                 .split()[0])
    assert 90.0 < rate < 110.0
    assert_nothing_moved_it(tmp_path / "truth.npz", configs=True)


@pytest.mark.virtual_vehicle
def test_healthy_ll_link_polls_and_commands_nothing(tmp_path: Path) -> None:
    with virtual_vehicle(tmp_path, "asctec-ll") as (device, cfg_file):
        code, report = check(cfg_file, device.pty_path, "--seconds", "3")
    assert code == 0, report
    assert report["protocol"] == "asctec-ll" and report["healthy"]
    assert report["sent"]["poll"] > 200 and report["sent"]["command"] == 0
    assert report["serial_enable_switch"] is True and report["applied_ctrl_mask"] == 0
    assert 90.0 < report["data_rate_hz"] < 110.0
    # the virtual vehicle's battery (sim.battery_mv 11800 mV, drooping with the lift: none)
    assert report["battery_v"] == pytest.approx(11.8, abs=0.05)
    assert_nothing_moved_it(tmp_path / "truth.npz", configs=False)


@pytest.mark.virtual_vehicle
def test_a_corrupting_line_is_not_healthy(tmp_path: Path) -> None:
    """One bit flip per 500 bytes: about 8 % of the 41-byte DATA frames fail."""
    with virtual_vehicle(tmp_path, **{"sim.faults.corruption_rate": 2e-3}) as (device, cfg):
        code, report = check(cfg, device.pty_path, "--seconds", "3")
    assert code == 1
    rejected = sum(report["rejections"].values())
    accepted = sum(report["frames"].values())
    assert rejected > 0.01 * (accepted + rejected)
    assert any("rejected" in r for r in report["reasons"]), report["reasons"]
    assert_nothing_moved_it(tmp_path / "truth.npz", configs=True)


@pytest.mark.virtual_vehicle
def test_a_stalled_stream_is_not_healthy(tmp_path: Path) -> None:
    """The virtual X-3D sends nothing from 1.5 s to 2.5 s after it starts; the check
    listens from its start for 4 s."""
    faults = {"sim.faults.stall_at_s": 1.5, "sim.faults.stall_duration_s": 1.0}
    with virtual_vehicle(tmp_path, **faults) as (device, cfg_file):
        code, report = check(cfg_file, device.pty_path, "--seconds", "4")
    assert code == 1
    assert report["longest_gap_s"] > 0.8  # the stall, less what fell before the check began
    assert any("stalled" in r for r in report["reasons"]), report["reasons"]
    assert_nothing_moved_it(tmp_path / "truth.npz", configs=True)


@pytest.mark.virtual_vehicle
def test_the_switch_off_is_not_healthy_unless_expected(tmp_path: Path) -> None:
    with virtual_vehicle(tmp_path, "asctec-ll", **{"sim.serial_enable": False}) as (
            device, cfg_file):
        code, report = check(cfg_file, device.pty_path, "--seconds", "2")
        off_code, off_report = check(cfg_file, device.pty_path, "--seconds", "2",
                                     "--expect-switch", "off")
    assert code == 1 and report["serial_enable_switch"] is False
    assert any("switch is OFF" in r for r in report["reasons"]), report["reasons"]
    assert off_code == 0, off_report  # the hand-back test: off is what was expected
    assert_nothing_moved_it(tmp_path / "truth.npz", configs=False)


@pytest.mark.virtual_vehicle
def test_a_port_held_by_a_flight_exits_3_without_a_byte(tmp_path: Path) -> None:
    """The port is locked as gs fly locks it (pyserial exclusive: flock)."""
    with virtual_vehicle(tmp_path) as (device, cfg_file), \
            serial.Serial(device.pty_path, exclusive=True):
        result = runner.invoke(app, ["link-check", "-c", str(cfg_file), "--serial-port",
                                     device.pty_path, "--seconds", "1"])
    assert result.exit_code == 3
    assert "in use" in result.output
    with np.load(tmp_path / "truth.npz") as truth:
        assert len(truth["wire_config_in"]) == 0 and len(truth["wire_command_in"]) == 0


def test_usage_and_a_missing_port(tmp_path: Path) -> None:
    cfg = sim_config(**{"logging.flight_log_dir": str(tmp_path)})
    cfg_file = tmp_path / "lab.yaml"
    cfg_file.write_text(dump_config(cfg), encoding="utf-8")
    missing = runner.invoke(app, ["link-check", "-c", str(cfg_file), "--serial-port",
                                  str(tmp_path / "no-such-tty"), "--seconds", "1"])
    assert missing.exit_code == 3 and "cannot open serial port" in missing.output
    bad = runner.invoke(app, ["link-check", "-c", str(cfg_file), "--expect-switch", "maybe"])
    assert bad.exit_code == 2
    no_config = runner.invoke(app, ["link-check", "-c", str(tmp_path / "none.yaml")])
    assert no_config.exit_code == 2
