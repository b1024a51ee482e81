"""Shared by the tests that fly the virtual lab: a free UDP port for its Vicon stream, the
bundled sim configuration with overrides, a recorded in-process flight, and an empty log.
Test-only (not part of the package), imported like ``ekf_truth``."""

from __future__ import annotations

from pathlib import Path

from groundstation.app.inprocess import FlightResult, fly_in_process
from groundstation.app.recorder import FlightRecorder
from groundstation.config import GroundStationConfig, apply_overrides, dump_config, load_config
from groundstation.flight.assembly import assemble
from groundstation.flight.supervisor import State
from groundstation.lab import Lab

REPO = Path(__file__).resolve().parents[1]
LIVELY_WAYPOINTS = """t,x,y,z,yaw
0,0,0,-1,0
2,0.6,0,-1,0.6
4,0.6,0.6,-1.4,-0.3
6,-0.6,0.6,-0.9,0.5
8,-0.6,-0.6,-1.3,-0.6
10,0.6,-0.6,-0.8,0.4
12,0,0,-1.2,-0.4
14,0.6,0.6,-0.9,0.5
16,-0.6,0.6,-1.3,-0.5
18,0,-0.6,-0.9,0.3
20,0,0,-1,0
"""
"""A lively 20 s waypoint path (t [s], x, y, z NED [m], yaw [rad]): 1.2 m legs in 2 s,
height changes of 0.5 m (the accelerometer's z needs vertical accelerations) and heading
swings of about 1 rad, for identification; min-jerk shaping makes it flyable."""

META = {"supervisor_states": [s.name for s in State]}
"""What the daemon writes into every flight log's meta.json."""


def sim_config(**overrides: object) -> GroundStationConfig:
    """``config/sim.yaml`` with ``overrides`` (dotted keys)."""
    return apply_overrides(load_config(REPO / "config" / "sim.yaml"), dict(overrides))


REALTIME_SETTLE_S = 1.0
"""[s] on the ground before take-off in the real-time flights (``estimator.settle_time_s``;
Ch. 7.4's 3 s is the shipped value): they prove the wire, the signals, the exclusive port,
the API and the fleet, which the estimator's settling does not touch, and every second a
real-time flight spends waiting is a second of every ``make test``. The EKF's gyro bias
settles in about 1.2 s; the preflight's checks still decide when the vehicle may go."""


REALTIME_MOVES = {"safety.takeoff_speed_m_s": 1.0, "safety.land_speed_m_s": 1.0,
                  "safety.takeoff_land_accel_m_s2": 2.0, "serial.handover_blend_s": 0.5}
"""The take-off and landing of the real-time flights, brisker than the shipped ones: a 1 m
climb and the landing in 2.0 s each instead of 3.4 s and 3.7 s (peak 1 m/s, 0.4 m/s as
the vehicle meets the floor), and the pilot's sticks blended into the controller's in
0.5 s instead of 1 s, for the same reason as :data:`REALTIME_SETTLE_S` (the in-process
flights and the evaluation fly the shipped ones)."""


def realtime_sim_config(**overrides: object) -> GroundStationConfig:
    """``config/sim.yaml`` as the real-time flights fly it (:data:`REALTIME_SETTLE_S`,
    :data:`REALTIME_MOVES`), with ``overrides`` (dotted keys)."""
    return sim_config(**{"estimator.settle_time_s": REALTIME_SETTLE_S, **REALTIME_MOVES,
                         **overrides})


def fly_logged(cfg: GroundStationConfig, log_dir: Path, duration_s: float | None,
               lab: Lab | None = None) -> tuple[Path, FlightResult]:
    """Fly ``cfg`` in-process (simulated clock) for ``duration_s`` of trajectory (None: one
    period of it) against ``lab`` (None: the virtual lab of ``cfg``), recording the flight
    log under ``log_dir``; the flight must end DONE. (log directory, result)."""
    max_time_s = 300.0 if duration_s is None else duration_s + 40.0
    with FlightRecorder.create(log_dir, dump_config(cfg), META) as rec:
        result = fly_in_process(assemble(cfg), lab=lab, duration_s=duration_s,
                                max_time_s=max_time_s, recorder=rec)
        directory = rec.directory
    assert result.final_state is State.DONE, result.transitions
    return directory, result


def empty_log(log_dir: Path) -> Path:
    """A flight log that never took off: no rows."""
    with FlightRecorder.create(log_dir, dump_config(sim_config()), META) as rec:
        return rec.directory
