"""``gs motors start|stop`` against the virtual AscTec LL vehicle over a real pty.

The gesture is sent only on this explicit request; it is refused while a flight holds the
port, in the X-3D dialect, and while the vehicle reports it is flying. The virtual vehicle
models the gesture (thrust 0, yaw full one way for 0.4 s starts the motors, the opposite
stops them) and reports the motors in LL_STATUS.
"""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from groundstation.asctec.ll_link import LlLink
from groundstation.config import apply_overrides, dump_config, load_config
from groundstation.endpoints import free_udp_port
from groundstation.flight.assembly import link_params
from sim_device.realtime import SimDeviceProcess

ROOT = Path(__file__).resolve().parents[1]


def gs(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "groundstation", *args], capture_output=True,
                          text=True, timeout=60, cwd=ROOT)


@pytest.fixture
def ll_lab(tmp_path: Path) -> Iterator[tuple[Path, str]]:
    cfg = apply_overrides(load_config(ROOT / "config" / "sim.yaml"),
                          {"serial.protocol": "asctec-ll", "vicon.port": free_udp_port()})
    config_file = tmp_path / "ll.yaml"
    config_file.write_text(dump_config(cfg), encoding="utf-8")
    with SimDeviceProcess(config_file, tmp_path / "truth.npz") as device:
        yield config_file, device.pty_path


@pytest.mark.virtual_vehicle
def test_start_then_stop_on_request(ll_lab: tuple[Path, str]) -> None:
    config_file, pty = ll_lab
    started = gs("motors", "start", "--config", str(config_file), "--serial-port", pty)
    assert started.returncode == 0, started.stdout + started.stderr
    assert "motors on" in started.stdout
    stopped = gs("motors", "stop", "--config", str(config_file), "--serial-port", pty)
    assert stopped.returncode == 0, stopped.stdout + stopped.stderr
    assert "motors off" in stopped.stdout


@pytest.mark.virtual_vehicle
def test_refused_while_another_process_holds_the_port(ll_lab: tuple[Path, str]) -> None:
    config_file, pty = ll_lab
    cfg = apply_overrides(load_config(config_file), {"serial.port": pty})
    with LlLink.from_params(link_params(cfg.serial)):  # a flight's link holds the port
        refused = gs("motors", "start", "--config", str(config_file), "--serial-port", pty)
    assert refused.returncode == 1
    assert "refused" in refused.stdout and "in use" in refused.stdout


@pytest.mark.virtual_vehicle
def test_the_x3d_dialect_has_no_gesture(ll_lab: tuple[Path, str]) -> None:
    config_file, pty = ll_lab
    out = gs("motors", "start", "--config", str(config_file), "--serial-port", pty,
             "--protocol", "x3d")
    assert out.returncode == 2
    assert "no motor gesture" in out.stdout


@pytest.mark.slow
def test_bad_action_is_a_usage_error(tmp_path: Path) -> None:
    out = gs("motors", "spin", "--config", str(ROOT / "config" / "sim.yaml"))
    assert out.returncode == 2 and "start or stop" in out.stderr


@pytest.mark.virtual_vehicle
def test_refused_while_the_vehicle_reports_flying(tmp_path: Path) -> None:
    cfg = apply_overrides(load_config(ROOT / "config" / "sim.yaml"),
                          {"serial.protocol": "asctec-ll", "vicon.port": free_udp_port(),
                           # in the air at 40 m on the pilot's stick, a little above hover
                           # (it drifts by centimetres a second): still flying however late
                           # the command starts (a 40 m fall was over before a slow start)
                           "sim.initial_position": [0.0, 0.0, -40.0], "sim.pilot_thrust": 1996})
    config_file = tmp_path / "ll.yaml"
    config_file.write_text(dump_config(cfg), encoding="utf-8")
    with SimDeviceProcess(config_file, tmp_path / "truth.npz") as device:
        out = gs("motors", "stop", "--config", str(config_file), "--serial-port",
                 device.pty_path)
    assert out.returncode == 1
    assert "flying" in out.stdout and "nothing sent" in out.stdout
