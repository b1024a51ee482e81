"""The first day of docs/lab-setup.md, rehearsed on the virtual lab, command by command.

``gs sim-device`` plays the vehicle in a process of its own (a pty and Vicon on UDP), a
vehicle that is not the model: its rate gains 30 % off the configured ones (1.3, 0.7,
1.3) and its rotors 10 % weaker than eq. 3.7. Every command of the guide's section 7
then runs as the ``gs`` executable, in order, with a copy of ``config/lab.yaml`` that
differs only in where the virtual lab is (its pty, a free Vicon port on loopback, free
telemetry ports) and in a flight-log directory that nobody can write, as
``/var/lib/groundstation/flightlogs`` is for a user: the logs fall back to
``$XDG_STATE_HOME``. What each step prints to paste is pasted (its ``--json`` form) into
that copy, as a person would, and each command must succeed. What the identification
finds is compared with the virtual vehicle's own parameters.

Real time, about four minutes: run under the shared lock (``flock /tmp/realtime.lock``).
"""

from __future__ import annotations

import json
import os
import re
import socket
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from lab_helpers import free_udp_port, sim_config
from scipy.optimize import brentq

from groundstation.config import GroundStationConfig, apply_overrides, dump_config, load_config
from sim_device.realtime import SimDeviceProcess

REPO = Path(__file__).resolve().parents[1]
GS = Path(sys.executable).parent / "gs"
TRUE_OVER_MODEL = [1.3, 0.7, 1.3]  # the virtual vehicle's rate gains / the configured ones
TRUE_LIFT = 0.9  # its rotors' lift / eq. 3.7
UNWRITABLE = "/sys/groundstation-rehearsal/flightlogs"  # sysfs: nobody, root neither


def free_tcp_ports(count: int) -> list[int]:
    """``count`` different TCP ports nothing on loopback listens on now."""
    sockets = [socket.socket(socket.AF_INET, socket.SOCK_STREAM) for _ in range(count)]
    try:
        for s in sockets:
            s.bind(("127.0.0.1", 0))
        return [int(s.getsockname()[1]) for s in sockets]
    finally:
        for s in sockets:
            s.close()


class Day:
    """The user's side: a configuration file they edit and the ``gs`` they run."""

    def __init__(self, tmp: Path, pty: str, vicon_port: int) -> None:
        self.tmp = tmp
        self.pty = pty
        self.env = {k: v for k, v in os.environ.items() if k != "NOTIFY_SOCKET"}
        self.env["XDG_STATE_HOME"] = str(tmp / "state")
        telemetry, control = free_tcp_ports(2)
        # the guide: "copy config/lab.yaml"; here the virtual lab is where the lab is
        self.config = apply_overrides(load_config(REPO / "config" / "lab.yaml"), {
            "vicon.port": vicon_port, "vicon.bind_address": "127.0.0.1",
            "telemetry.endpoint": f"tcp://127.0.0.1:{telemetry}",
            "telemetry.control_endpoint": f"tcp://127.0.0.1:{control}",
            "logging.flight_log_dir": UNWRITABLE,
            "realtime.cpu_dma_latency_us": None,  # the PC's PM QoS is not the rehearsal's
        })
        self.lab = tmp / "lab.yaml"
        self.save()

    def save(self, path: Path | None = None, config: GroundStationConfig | None = None
             ) -> Path:
        path = path or self.lab
        path.write_text(dump_config(config or self.config), encoding="utf-8")
        return path

    def paste(self, fields: dict[str, Any]) -> None:
        """Take the configuration fields of a ``--json`` report into the file."""
        self.config = apply_overrides(self.config, {k: v for k, v in fields.items()
                                                    if k.startswith("vehicle.")})
        self.save()

    def gs(self, *args: str, timeout: float = 120.0) -> str:
        """Run ``gs ARGS`` in the working directory; it must exit 0. Its stdout."""
        return self.run(*args, timeout=timeout).stdout

    def run(self, *args: str, timeout: float = 120.0) -> subprocess.CompletedProcess[str]:
        """Run ``gs ARGS`` in the working directory; it must exit 0."""
        done = subprocess.run([str(GS), *args], cwd=self.tmp, env=self.env, timeout=timeout,
                              capture_output=True, text=True)
        assert done.returncode == 0, (args, done.returncode, done.stdout[-3000:],
                                      done.stderr[-3000:])
        return done

    def json(self, *args: str) -> dict[str, Any]:
        out = self.gs(*args, "--json").strip().splitlines()
        report: dict[str, Any] = json.loads(out[-1])
        return report

    def fly(self, config: Path, *args: str) -> tuple[str, Path]:
        """``gs fly``; its output (stdout, then the log lines of stderr) and the flight log
        its summary's last line names."""
        done = self.run("fly", "-c", str(config), "--serial-port", self.pty, *args,
                        timeout=240.0)
        log = re.search(r"^  flight log: (.+)$", done.stdout, re.MULTILINE)
        assert log is not None, done.stdout[-2000:]
        return done.stdout + done.stderr, Path(log.group(1))


@pytest.mark.realtime
@pytest.mark.slow
@pytest.mark.timeout(900)  # about 4 min on an idle 2-core machine, three flights in real time
def test_the_first_day_of_the_guide_on_the_virtual_lab(tmp_path: Path) -> None:
    vicon_port = free_udp_port()
    vehicle = sim_config(**{"vicon.port": vicon_port, "sim.k_rate_scale": TRUE_OVER_MODEL,
                            "sim.thrust_scale": TRUE_LIFT,
                            "logging.flight_log_dir": str(tmp_path / "sim")})
    device_file = tmp_path / "virtual-vehicle.yaml"
    device_file.write_text(dump_config(vehicle), encoding="utf-8")
    with SimDeviceProcess(device_file, tmp_path / "truth.npz", duration=850.0,
                          stderr=tmp_path / "sim.err") as device:
        day = Day(tmp_path, device.pty_path, vicon_port)
        lab = str(day.lab)
        configured_k = np.array(day.config.vehicle.k_rate)

        # 1. link check: healthy, nothing that moves the vehicle sent
        out = day.gs("link-check", "-c", lab, "--serial-port", day.pty, "--seconds", "3")
        assert out.splitlines()[-1] == "verdict: healthy"

        # 2. Vicon check: frames right, the noise pasted
        vicon = day.json("calibrate", "vicon", "-c", lab, "--seconds", "3")
        assert vicon["frames_ok"] is True
        day.paste(vicon)

        # 3. IMU calibration
        day.paste(day.json("calibrate", "imu", "-c", lab, "--serial-port", day.pty,
                           "--seconds", "3"))

        # 4. a first thrust map from the stick the virtual vehicle hovers at (the pilot
        # would read it with gs link-check --expect-switch off while hovering by hand)
        v = vehicle.vehicle
        weight = v.mass_kg * v.gravity
        stick = brentq(lambda u: -TRUE_LIFT * np.polyval(v.thrust_poly, u) - weight, 1, 4095)
        first = day.json("identify", "hover-stick", f"{stick:.0f}", "-c", lab)
        scale = first["vehicle.thrust_poly"][3] / v.thrust_poly[3]
        assert scale == pytest.approx(TRUE_LIFT, rel=0.01)
        day.paste(first)

        # 6. thrust-only flight (the pilot's neutral sticks hold the attitude), its log
        # in the user's state directory, said in one line
        thrust_only = day.save(tmp_path / "lab-thrust.yaml",
                               apply_overrides(day.config, {"channels.auto": ["thrust"]}))
        out, log = day.fly(thrust_only, "--trajectory", "hover", "--duration", "10")
        assert out.count("cannot be written") == 1 and UNWRITABLE in out
        assert log.parent == tmp_path / "state" / "groundstation" / "flightlogs"
        thrust = day.json("identify", "thrust", str(log))
        assert thrust["vehicle.thrust_poly"][3] / v.thrust_poly[3] == pytest.approx(
            TRUE_LIFT, rel=0.03)
        day.paste(thrust)

        # 7. the identification flight and what it feeds
        out, log = day.fly(day.lab, "--trajectory", "sysid")
        rates = day.json("identify", "rates", str(log))
        found = np.array(rates["vehicle.k_rate"])
        truth = configured_k * np.array(TRUE_OVER_MODEL)
        assert np.all(np.abs(found / truth - 1.0) < 0.05), (found, truth)
        day.paste(rates)
        day.paste(day.json("identify", "scales", str(log)))
        day.paste(day.json("identify", "thrust", str(log)))
        day.paste(day.json("identify", "inflow", str(log)))
        day.gs("verify-model", str(log), "--json")

        # 8. full automatic, with what the day found
        day.gs("check-config", lab)
        out, log = day.fly(day.lab)
        tracking = re.search(r"tracking error \(estimate vs reference\): RMS ([0-9.]+) cm", out)
        assert tracking is not None and float(tracking.group(1)) < 2.0, out[-2000:]
        summary = next(x for x in out.splitlines() if x.startswith("flight ended in"))
        assert "mission completed" in summary and "exit code 0" in summary
    with np.load(tmp_path / "truth.npz") as truth_log:  # the vehicle flew: the truth says so
        assert float(-np.min(truth_log["position"][:, 2])) > 0.9
