"""Fly one scenario: in-process on the simulated clock, or in real time over pty and UDP.

Both runners build the same :class:`~groundstation.flight.core.FlightCore` from
:func:`~sim_device.evaluation.scenarios.scenario_config` (trajectory,
controller, duration) and return a :class:`FlightRecord`:

* :func:`run_in_process` flies :class:`~groundstation.app.inprocess.InProcessFlight`
  and times every ``FlightCore.tick`` with ``time.perf_counter`` (the code's
  back-to-back cost, not a real-time figure);
* :func:`run_real_time` starts the virtual lab (``gs sim-device``) in a child
  process, flies :class:`~groundstation.app.daemon.FlightDaemon` against it in
  real time, then reads the flight log and the lab's truth file, aligned on the
  monotonic clock. Timing comes from the log (compute, jitter, latency).

:func:`simulate_model` flies the same controller and trajectory on the
controller package's model-only simulator (true state fed back, no estimator):
the "simulation" curve of thesis Fig. 11.4.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from contextlib import ExitStack
from pathlib import Path

import numpy as np

from groundstation.app.daemon import FlightDaemon
from groundstation.app.inprocess import InProcessFlight
from groundstation.config import GroundStationConfig, apply_overrides, dump_config
from groundstation.control.factory import make_controller
from groundstation.control.simulate import SimPlant, SimResult, simulate
from groundstation.endpoints import free_udp_port
from groundstation.errors import GroundStationError
from groundstation.evaluation.record import FlightRecord, record_from_log, record_from_trace
from groundstation.flight.assembly import assemble
from groundstation.flight.core import FlightCore, TickResult
from groundstation.flight.inputs import InputHealth, VehicleStatus
from groundstation.types import ImuSample, Pose
from sim_device.config import sim_section
from sim_device.evaluation.scenarios import (
    Scenario,
    scenario_config,
    scenario_trajectory,
)
from sim_device.realtime import SimDeviceProcess

MARGIN_S = 60.0
"""Simulated time allowed beyond the trajectory for preflight, take-off and landing [s]."""

SIM_START_TIMEOUT_S = 20.0
"""How long the virtual lab's child process may take to announce itself, or to stop [s]."""


class _TickProbe:
    """Stands in for ``FlightCore.tick``: times each call and keeps the Vicon poses and the
    reference heading (the in-process trace has no column for it)."""

    def __init__(self, core: FlightCore) -> None:
        self._tick = core.tick
        self.compute: list[float] = []
        self.vicon: list[tuple[float, float, float, float]] = []
        self.ref_yaw: list[float] = []

    def __call__(self, t: float, imu: ImuSample | None, poses: Sequence[Pose],
                 vehicle: VehicleStatus, health: InputHealth,
                 stop_requests: int = 0) -> TickResult:
        start = time.perf_counter()
        result = self._tick(t, imu, poses, vehicle, health, stop_requests)
        self.compute.append(time.perf_counter() - start)
        self.ref_yaw.append(result.reference.yaw)
        for pose in poses:
            p = pose.position
            self.vicon.append((pose.t, float(p[0]), float(p[1]), float(p[2])))
        return result


def run_in_process(scenario: Scenario, base: GroundStationConfig) -> FlightRecord:
    """Fly ``scenario`` in-process against the virtual lab (deterministic for a seed)."""
    cfg = scenario_config(scenario, base)
    flight = InProcessFlight(assemble(cfg),
                             trajectory=scenario_trajectory(scenario, cfg),
                             duration_s=scenario.duration_s)
    probe = _TickProbe(flight.core)
    flight.core.tick = probe  # type: ignore[method-assign]  # timing wrapper, same signature
    result = flight.run(max_time_s=scenario.duration_s + MARGIN_S)
    return record_from_trace(result, np.array(probe.compute), np.array(probe.vicon),
                             np.array(probe.ref_yaw))


def build_daemon(scenario: Scenario, cfg: GroundStationConfig) -> FlightDaemon:
    """A daemon flying the scenario's controller (from ``cfg``) and trajectory."""
    return FlightDaemon(assemble(cfg), trajectory=scenario_trajectory(scenario, cfg),
                        duration_s=scenario.duration_s)


def run_real_time(scenario: Scenario, base: GroundStationConfig, workdir: Path) -> FlightRecord:
    """Fly ``scenario`` in real time: the virtual lab in a child process on a pty and UDP,
    the flight daemon in this process. The flight log, the truth file, the lab's log and
    the configuration flown are left in ``workdir/<scenario>/``."""
    d = workdir / scenario.name
    d.mkdir(parents=True, exist_ok=True)
    truth = d / "truth.npz"
    cfg = apply_overrides(scenario_config(scenario, base), {
        "vicon.port": free_udp_port(), "telemetry.enabled": False,
        "telemetry.control_endpoint": None,
        "logging.flight_log_dir": str(d), "sim.truth_file": str(truth)})
    config_file = d / "config.yaml"
    config_file.write_text(dump_config(cfg), encoding="utf-8")
    limit = scenario.duration_s + 3 * MARGIN_S
    with ExitStack() as stack:
        try:
            lab = stack.enter_context(SimDeviceProcess(
                config_file, truth, duration=limit, stderr=d / "sim-device.log",
                timeout=SIM_START_TIMEOUT_S))
        except RuntimeError as exc:
            raise GroundStationError(f"the virtual lab did not start: {exc}") from exc
        cfg = apply_overrides(cfg, {"serial.port": lab.pty_path})
        summary = build_daemon(scenario, cfg).run()
        time.sleep(0.2)  # the lab records the final COMMAND (mask 0) before it stops
    return record_from_log(summary.log_dir, truth)


def simulate_model(scenario: Scenario, base: GroundStationConfig) -> SimResult:
    """The scenario's controller and trajectory on the model-only simulator
    (:func:`groundstation.control.simulate.simulate`) with the lab's rate-loop lag,
    command delay and thrust error; starts on the trajectory, lasts ``duration_s``."""
    cfg = scenario_config(scenario, base)
    params = assemble(cfg)
    controller = make_controller(params.controller, params.vehicle, params.command_period_s)
    sim, vehicle = sim_section(cfg), cfg.vehicle
    plant = SimPlant(
        rate_tau=vehicle.rate_loop_tau_s if sim.rate_loop_tau_s is None else sim.rate_loop_tau_s,
        delay_s=vehicle.command_delay_s if sim.command_delay_s is None else sim.command_delay_s,
        thrust_scale=sim.thrust_scale)
    return simulate(controller, scenario_trajectory(scenario, cfg), scenario.duration_s,
                    params=params.vehicle, plant=plant,
                    rate_hz=cfg.serial.command_rate_hz)
