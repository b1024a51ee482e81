"""The safety chain judged by the truth: faults in the plant and the reference, not in the
estimate, and what the vehicle really did.

A thrust fault (the rotors give several times the lift commanded for a fraction of a
second: an ESC glitch) pushes the vehicle up faster than the accelerometer can measure
(it clips at 14 m/s^2, Ch. 6.2), so the dead-reckoned estimate lags the climb. Before,
every layer trusted the estimate: the true poses were refused, read as a lost Vicon,
the landing was flown on dead reckoning and the motors idled in the air. Now poses that
agree with each other overrule the estimate, the geofence acts on the truth, and the
motors are idled only on evidence of the floor.

In-process on the simulated clock, the Vicon stream tracked well beyond the flight volume
(as a lab's cameras see beyond the volume the ground station is allowed to fly in).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from lab_helpers import sim_config

from groundstation.app.inprocess import FlightResult, InProcessFlight, fly_in_process
from groundstation.config import GroundStationConfig
from groundstation.control.trajectory import FigureEight
from groundstation.flight.assembly import assemble
from groundstation.flight.supervisor import State
from groundstation.types import Reference

TRACKED_FAR = {"sim.vicon.volume_x": [-20.0, 20.0], "sim.vicon.volume_y": [-20.0, 20.0],
               "sim.vicon.volume_z": [-20.0, 0.05]}
"""The virtual Vicon tracks the vehicle 20 m around (the flight volume is +-1.5 m, 2 m up)."""

COMMANDED = 0xF


def excursion(cfg: GroundStationConfig, result: FlightResult) -> float:
    """How far the truth got outside the flight volume while the ground station still
    commanded the vehicle (ctrl mask 0xF) [m]; 0 if it never did."""
    s = cfg.safety
    lo = np.array([s.volume_x[0], s.volume_y[0], s.volume_z[0]])
    hi = np.array([s.volume_x[1], s.volume_y[1], s.volume_z[1]])
    pos = result.trace["true_pos"][result.trace["mask"] == COMMANDED]
    outside = np.maximum(lo - pos, 0.0) + np.maximum(pos - hi, 0.0)
    return float(np.linalg.norm(outside, axis=1).max(initial=0.0))


def disarmed_height(result: FlightResult) -> float:
    """The truth's greatest height while the motors were idled to disarm [m] (0 if never)."""
    return float((-result.trace["true_pos"][:, 2])[result.during(State.DISARM)].max(initial=0.0))


@pytest.mark.slow
def fly_fault(lift_scale: float, duration_s: float, vicon_hz: float,
              **overrides: object) -> tuple[GroundStationConfig, FlightResult]:
    """Hover at 1 m; at 12 s (4 s into tracking) the rotors give ``lift_scale`` times their
    lift for ``duration_s``."""
    cfg = sim_config(**{"trajectory.name": "hover", "sim.vicon.rate_hz": vicon_hz,
                        **TRACKED_FAR, **overrides})
    result = fly_in_process(assemble(cfg), duration_s=20.0, max_time_s=60.0, events=[
        (12.0, lambda f: f.lab.thrust_fault(lift_scale, duration_s))])
    return cfg, result


def assert_judged_by_the_truth(cfg: GroundStationConfig, result: FlightResult) -> None:
    """The truth never left the volume by the margin while the ground station flew it, and
    the motors were never idled in the air."""
    assert excursion(cfg, result) < cfg.vicon.plausibility_margin_m, excursion(cfg, result)
    assert disarmed_height(result) < 0.1
    if result.final_state is State.DONE:
        assert -result.trace["true_pos"][-1, 2] < 0.02


@pytest.mark.parametrize(("lift_scale", "duration_s", "vicon_hz"),
                         [(3.0, 0.3, 100.0), (3.0, 0.3, 10.0), (2.5, 0.5, 10.0)])
def test_a_thrust_fault_that_blinds_the_estimate_is_caught_by_the_truth(
        lift_scale: float, duration_s: float, vicon_hz: float) -> None:
    """Three times the lift is 29 m/s^2 of specific force, twice the accelerometer's range:
    the estimate misses the climb, the poses overrule it, and the pilot gets the vehicle."""
    cfg, result = fly_fault(lift_scale, duration_s, vicon_hz)
    failsafes = [tr for tr in result.transitions if tr.failsafe]
    assert failsafes and not result.success, result.transitions
    assert failsafes[0].reason.startswith("estimate was wrong"), failsafes[0].reason
    assert failsafes[0].new is State.HANDBACK and 12.3 <= failsafes[0].t < 12.6
    assert_judged_by_the_truth(cfg, result)


def test_a_thrust_fault_that_pushes_the_vehicle_out_meets_the_geofence() -> None:
    """Landing on the re-anchored estimate (safety.on_overruled: land) while four times the
    lift for a second climbs through the ceiling: the geofence, watching Vicon, hands back
    as the truth crosses it, long before it is the margin beyond."""
    cfg, result = fly_fault(4.0, 1.0, 100.0, **{"safety.on_overruled": "land"})
    reasons = [tr.reason for tr in result.transitions if tr.failsafe]
    assert any(r.startswith("left the volume") for r in reasons), reasons
    assert result.final_state is State.HANDBACK
    assert (-result.trace["true_pos"][:, 2]).max() > 2.0  # it did leave: through the ceiling
    assert_judged_by_the_truth(cfg, result)


def test_a_thrust_fault_the_accelerometer_feels_is_flown_through() -> None:
    """Twice the lift for 0.3 s, 20 m/s^2 (the accelerometer clips at 14): the estimate keeps
    up well enough, the controller takes the vehicle back, nothing fails safe."""
    cfg, result = fly_fault(2.0, 0.3, 100.0)
    assert result.final_state is State.DONE and result.success, result.transitions
    assert (-result.trace["true_pos"][:, 2]).max() < 1.5
    assert_judged_by_the_truth(cfg, result)


class ArmedGlitch:
    """The figure-eight that flies, until :attr:`armed`: from then on every reference asks
    the acceleration and jerk min-jerk shaping of dense samples asked between its knots
    (69 m/s^2, 84,500 m/s^3). The feasibility check before flight sees the good one."""

    def __init__(self) -> None:
        self._base = FigureEight([0.0, 0.0, -1.0], width_m=1.0, period_s=20.0)
        self.name, self.duration, self.periodic = "glitch", 20.0, True
        self.free_heading = True
        self.armed = False

    def sample(self, t: float) -> Reference:
        ref = self._base.sample(t)
        if not self.armed:
            return ref
        wild = np.array([0.0, 69.0, 0.0]) * math.copysign(1.0, math.sin(300.0 * t))
        return Reference(t=ref.t, position=ref.position, velocity=ref.velocity,
                         acceleration=wild, jerk=np.array([0.0, 84_500.0, 0.0]), yaw=ref.yaw)


@pytest.mark.slow
def test_a_reference_beyond_what_the_check_allowed_is_a_fault_not_an_input() -> None:
    cfg = sim_config(**{"trajectory.name": "figure-eight"})
    glitch = ArmedGlitch()
    flight = InProcessFlight(assemble(cfg), trajectory=glitch, duration_s=20.0)

    def arm(_: InProcessFlight) -> None:
        glitch.armed = True

    result = flight.run(max_time_s=60.0, events=[(12.0, arm)])
    land = next(tr for tr in result.transitions if tr.new is State.LAND)
    assert land.failsafe and land.reason.startswith("reference fault"), land.reason
    assert "m/s^2" in land.reason or "m/s^3" in land.reason
    assert land.t - 12.0 < 0.05  # the next tick or two
    assert result.final_state is State.DONE and not result.success
    # the wild feed-forward never reached the vehicle: it stayed level and near its path
    tilt = [2.0 * math.degrees(math.asin(min(1.0, float(np.linalg.norm(q[1:3])))))
            for q in result.trace["true_q"]]
    assert max(tilt) < 15.0
    assert disarmed_height(result) < 0.1


def helix_csv(path: Path, *, hz: float = 100.0, noise_m: float = 5e-4, seed: int = 21) -> Path:
    """The file that flew away: a helix of radius 0.5 m at 0.7 m/s rising 0.3 m, heading
    along the motion (yaw in degrees, wrapped to +-180 as a tool writes angles), sampled
    at ``hz`` with ``noise_m`` of Gaussian noise on every coordinate, as numpy writes it."""
    rng = np.random.default_rng(seed)
    r, speed, rise = 0.5, 0.7, 0.3
    w = speed / r
    period = 2.0 * math.pi / w
    t = np.arange(0.0, period + 0.5 / hz, 1.0 / hz)
    x = r * np.cos(w * t) - r
    y = r * np.sin(w * t)
    z = -1.0 - rise * t / period
    yaw = np.degrees(np.arctan2(np.cos(w * t), -np.sin(w * t)))  # along the velocity
    noisy = np.column_stack([x, y, z]) + rng.normal(0.0, noise_m, (t.size, 3))
    rows = np.column_stack([t, noisy, (yaw + 180.0) % 360.0 - 180.0])
    np.savetxt(path, rows, delimiter=",", header="t,x,y,z,yaw_deg", comments="", fmt="%.6f")
    return path


@pytest.mark.slow
def test_the_noisy_dense_helix_that_flew_away_is_flown_on_its_curve(tmp_path: Path) -> None:
    """The whole chain on the file of the fly-away: it is read as samples of a curve (not
    corners passed at rest), its feed-forward stays within the envelope, nothing fails
    safe, and the truth follows the helix within centimetres, inside the volume."""
    cfg = sim_config(**{"trajectory.name": "waypoints",
                        "trajectory.file": str(helix_csv(tmp_path / "helix.csv")),
                        **TRACKED_FAR})
    result = fly_in_process(assemble(cfg), max_time_s=60.0)
    assert result.final_state is State.DONE and result.success, result.transitions
    track = result.during(State.TRACK)
    error = np.linalg.norm(result.trace["true_pos"][track] - result.trace["ref_pos"][track],
                           axis=1)
    assert np.sqrt(np.mean(error**2)) < 0.03 and error.max() < 0.08
    assert excursion(cfg, result) == 0.0
    assert (-result.trace["true_pos"][:, 2]).max() < 1.45  # 1.3 m at the top of the helix
    assert disarmed_height(result) < 0.1
