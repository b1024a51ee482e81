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

One virtual lab serves the whole day; each step is a test of its own that takes the
configuration the steps before it left (module-scoped fixtures, in the guide's order), so a
failure names its step. The flights are as short as what they feed allows: a 4 s
thrust-only hover (the thrust map needs the hover) and 6 s of the configured square fully
automatic, both ``gs fly`` over the pty in real time. The identification flight (36.5 s of
air) is flown on the simulated clock against the same virtual vehicle (its own
configuration, in-process) with the configuration the day has reached, its log written
where ``gs fly`` writes one; every ``gs identify`` and ``gs verify-model`` of the step then
runs on it as the user runs them. The wire and the daemon are the day's two real-time
flights' to prove; what this leaves unproven is the rate identification on a log whose
times carry a real link's jitter.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from lab_helpers import fly_logged, sim_config
from scipy.optimize import brentq

from groundstation.config import GroundStationConfig, apply_overrides, dump_config, load_config
from groundstation.endpoints import free_ports, free_udp_port
from sim_device.lab import VirtualLab
from sim_device.realtime import SimDeviceProcess

REPO = Path(__file__).resolve().parents[1]
GS = Path(sys.executable).parent / "gs"
TRUE_OVER_MODEL = [1.3, 0.7, 1.3]  # the virtual vehicle's rate gains / the configured ones
TRUE_LIFT = 0.9  # its rotors' lift / eq. 3.7
UNWRITABLE = "/sys/groundstation-rehearsal/flightlogs"  # sysfs: nobody, root neither


class Day:
    """The user's side: a configuration file they edit and the ``gs`` they run."""

    def __init__(self, tmp: Path, pty: str, vicon_port: int) -> None:
        self.tmp = tmp
        self.pty = pty
        self.env = {k: v for k, v in os.environ.items() if k != "NOTIFY_SOCKET"}
        self.env["XDG_STATE_HOME"] = str(tmp / "state")
        telemetry, control = free_ports(2)
        # the guide: "copy config/lab.yaml"; here the virtual lab is where the lab is
        self.config = apply_overrides(load_config(REPO / "config" / "lab.yaml"), {
            "vicon.port": vicon_port, "vicon.bind_address": "127.0.0.1",
            "telemetry.endpoint": f"tcp://127.0.0.1:{telemetry}",
            "telemetry.control_endpoint": f"tcp://127.0.0.1:{control}",
            "logging.flight_log_dir": UNWRITABLE,
            "realtime.cpu_dma_latency_us": None,  # the PC's PM QoS is not the rehearsal's
        })
        self.lab = tmp / "lab.yaml"
        self.vehicle: GroundStationConfig = self.config  # the virtual vehicle's own file
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

    def json_together(self, *commands: tuple[str, ...]) -> list[dict[str, Any]]:
        """Several ``gs ... --json`` that only read (a flight log) run at once, as a
        person with several terminals might; their reports in the order given."""
        children = [subprocess.Popen([str(GS), *args, "--json"], cwd=self.tmp, env=self.env,
                                     stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                     text=True) for args in commands]
        reports = []
        for args, child in zip(commands, children, strict=True):
            out, err = child.communicate(timeout=120.0)
            assert child.returncode == 0, (args, child.returncode, out[-3000:], err[-3000:])
            reports.append(json.loads(out.strip().splitlines()[-1]))
        return reports

    def fly_simulated(self, config: GroundStationConfig) -> Path:
        """Fly ``config`` in-process on the simulated clock against this day's virtual
        vehicle (its own configuration, not the user's), for one period of its trajectory;
        the flight log goes where ``gs fly`` would put it. Its directory."""
        log_dir = self.tmp / "state" / "groundstation" / "flightlogs"
        return fly_logged(config, log_dir, None, lab=VirtualLab(self.vehicle))[0]

    def fly(self, config: Path, *args: str) -> tuple[str, Path]:
        """``gs fly``; its output (stdout, then the log lines of stderr) and the flight log
        its summary's last line names."""
        done = self.run("fly", "-c", str(config), "--serial-port", self.pty, *args,
                        timeout=240.0)
        log = re.search(r"^  flight log: (.+)$", done.stdout, re.MULTILINE)
        assert log is not None, done.stdout[-2000:]
        return done.stdout + done.stderr, Path(log.group(1))


@pytest.fixture(scope="module")
def day(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Day]:
    """The virtual vehicle (30 % off in its rate gains, 10 % weak rotors) in its own
    process, and the user's copy of config/lab.yaml pointing at it."""
    tmp = tmp_path_factory.mktemp("rehearsal")
    vicon_port = free_udp_port()
    vehicle = sim_config(**{"vicon.port": vicon_port, "sim.k_rate_scale": TRUE_OVER_MODEL,
                            "sim.thrust_scale": TRUE_LIFT,
                            "logging.flight_log_dir": str(tmp / "sim")})
    device_file = tmp / "virtual-vehicle.yaml"
    device_file.write_text(dump_config(vehicle), encoding="utf-8")
    with SimDeviceProcess(device_file, tmp / "truth.npz", duration=600.0,
                          stderr=tmp / "sim.err") as device:
        day = Day(tmp, device.pty_path, vicon_port)
        day.vehicle = vehicle
        yield day
    with np.load(tmp / "truth.npz") as truth_log:  # the vehicle flew: the truth says so
        assert float(-np.min(truth_log["position"][:, 2])) > 0.9


@pytest.fixture(scope="module")
def grounded(day: Day) -> dict[str, Any]:
    """Steps 1-4, the vehicle on the ground: link check, Vicon and IMU calibration, a
    first thrust map from the hover stick; each report pasted."""
    lab = str(day.lab)
    found: dict[str, Any] = {}
    # 1. link check: healthy, nothing that moves the vehicle sent
    found["link"] = day.gs("link-check", "-c", lab, "--serial-port", day.pty, "--seconds", "2")
    # 2. Vicon check: frames right, the noise pasted
    found["vicon"] = day.json("calibrate", "vicon", "-c", lab, "--seconds", "2")
    day.paste(found["vicon"])
    # 3. IMU calibration
    day.paste(day.json("calibrate", "imu", "-c", lab, "--serial-port", day.pty,
                       "--seconds", "2"))
    # 4. a first thrust map from the stick the virtual vehicle hovers at (the pilot would
    # read it with gs link-check --expect-switch off while hovering by hand)
    v = day.vehicle.vehicle
    weight = v.mass_kg * v.gravity
    stick = brentq(lambda u: -TRUE_LIFT * np.polyval(v.thrust_poly, u) - weight, 1, 4095)
    found["first"] = day.json("identify", "hover-stick", f"{stick:.0f}", "-c", lab)
    day.paste(found["first"])
    return found


@pytest.fixture(scope="module")
def thrust_only(day: Day, grounded: dict[str, Any]) -> dict[str, Any]:
    """Step 6: the thrust-only flight (the pilot's neutral sticks hold the attitude) and
    the thrust map its log gives."""
    config = day.save(day.tmp / "lab-thrust.yaml",
                      apply_overrides(day.config, {"channels.auto": ["thrust"]}))
    out, log = day.fly(config, "--trajectory", "hover", "--duration", "4")
    thrust = day.json("identify", "thrust", str(log))
    day.paste(thrust)
    return {"out": out, "log": log, "thrust": thrust}


@pytest.fixture(scope="module")
def identified(day: Day, thrust_only: dict[str, Any]) -> dict[str, Any]:
    """Step 7: the identification flight and what it feeds."""
    configured_k = np.array(day.config.vehicle.k_rate)
    log = day.fly_simulated(apply_overrides(day.config, {"trajectory.name": "sysid"}))
    rates, *others = day.json_together(
        *[("identify", what, str(log)) for what in ("rates", "scales", "thrust", "inflow")],
        ("verify-model", str(log)))
    for report in (rates, *others[:-1]):  # verify-model's report is to read, not to paste
        day.paste(report)
    return {"rates": rates, "configured_k": configured_k}


@pytest.mark.realtime
@pytest.mark.slow
def test_on_the_ground_the_link_vicon_imu_and_a_first_thrust_map(
        day: Day, grounded: dict[str, Any]) -> None:
    assert grounded["link"].splitlines()[-1] == "verdict: healthy"
    assert grounded["vicon"]["frames_ok"] is True
    v = day.vehicle.vehicle
    scale = grounded["first"]["vehicle.thrust_poly"][3] / v.thrust_poly[3]
    assert scale == pytest.approx(TRUE_LIFT, rel=0.01)


@pytest.mark.realtime
@pytest.mark.slow
def test_the_thrust_only_flight_logs_where_the_user_can_and_maps_the_thrust(
        day: Day, thrust_only: dict[str, Any]) -> None:
    # its log in the user's state directory, said in one line
    out = thrust_only["out"]
    assert out.count("cannot be written") == 1 and UNWRITABLE in out
    assert thrust_only["log"].parent == day.tmp / "state" / "groundstation" / "flightlogs"
    v = day.vehicle.vehicle
    assert thrust_only["thrust"]["vehicle.thrust_poly"][3] / v.thrust_poly[3] == \
        pytest.approx(TRUE_LIFT, rel=0.03)


@pytest.mark.realtime
@pytest.mark.slow
def test_the_identification_flight_finds_the_rate_gains(identified: dict[str, Any]) -> None:
    found = np.array(identified["rates"]["vehicle.k_rate"])
    truth = identified["configured_k"] * np.array(TRUE_OVER_MODEL)
    assert np.all(np.abs(found / truth - 1.0) < 0.05), (found, truth)


@pytest.mark.realtime
@pytest.mark.slow
def test_fully_automatic_with_what_the_day_found(day: Day,
                                                  identified: dict[str, Any]) -> None:
    """Step 8: the configured square, fully automatic, on the parameters the day found."""
    day.gs("check-config", str(day.lab))
    out, _ = day.fly(day.lab, "--duration", "6")
    tracking = re.search(r"tracking error \(estimate vs reference\): RMS ([0-9.]+) cm", out)
    assert tracking is not None and float(tracking.group(1)) < 2.0, out[-2000:]
    summary = next(x for x in out.splitlines() if x.startswith("flight ended in"))
    assert "mission completed" in summary and "exit code 0" in summary
