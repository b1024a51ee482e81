"""Controllers in the virtual lab: the whole chain, on the simulated clock.

``groundstation.app.inprocess.fly_in_process`` flies the flight core against
``sim_device.VirtualLab``: COMMAND bytes into the virtual X-3D (rate-loop lag
0.064 s, 20 ms command delay, motor lag, battery droop, IMU biases), DATA bytes
and Vicon datagrams back through the decoders and the EKF. The controller sees
the EKF's estimate; the figures are measured on the lab's ground truth.
Thresholds are the reached figures with the margin stated next to them.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from groundstation.app.inprocess import FlightResult, fly_in_process
from groundstation.config import GroundStationConfig, apply_overrides, load_config
from groundstation.control import (
    Controller,
    LqrController,
    PidController,
    make_trajectory,
)
from groundstation.control.hinf import HinfController, default_gain_path, load_hinf_gain
from groundstation.evaluation.metrics import error_norms, rms, time_lag
from groundstation.flight.assembly import assemble
from groundstation.flight.supervisor import State

REPO = Path(__file__).resolve().parents[1]


def lab_config(**overrides: object) -> GroundStationConfig:
    return apply_overrides(load_config(REPO / "config" / "sim.yaml"), dict(overrides))


def fly(cfg: GroundStationConfig, controller: Controller, trajectory: str,
        duration_s: float) -> FlightResult:
    return fly_in_process(assemble(cfg), controller=controller,
                          trajectory=make_trajectory(trajectory),
                          duration_s=duration_s, max_time_s=duration_s + 40.0)


@pytest.fixture(scope="module")
def square_10hz() -> dict[str, tuple[float, float]]:
    """Second-lap (RMS xy error [m], time lag [s]) of each controller, Vicon at 10 Hz."""
    cfg = lab_config(**{"trajectory.name": "square", "sim.vicon.rate_hz": 10.0,
                        "trajectory.shaping": "none"})  # the thesis's sharp square
    params = assemble(cfg).vehicle
    controllers: dict[str, Controller] = {
        "lqr-cv": LqrController(params=params, reference_model="velocity"),
        "lqr-cp": LqrController(params=params, reference_model="position"),
        "pid": PidController(params=params),
    }
    out = {}
    for name, ctrl in controllers.items():
        result = fly(cfg, ctrl, "square", 40.0)
        assert result.final_state is State.DONE, name
        track = result.during(State.TRACK)
        t = result.trace["t"][track]
        lap2 = t >= t[0] + 20.0
        pos = result.trace["true_pos"][track][lap2, :2]
        ref = result.trace["ref_pos"][track][lap2, :2]
        out[name] = (rms(error_norms(pos, ref)), time_lag(pos, ref, float(np.median(np.diff(t)))))
    return out


@pytest.mark.slow
def test_square_at_10hz_vicon_constant_velocity_lqr_wins(square_10hz) -> None:
    # The thesis's central result (Ch. 11.3) through the EKF at the Ch. 11 Vicon rate.
    # Reached (fixed-window cross-correlation, 50 Hz commands, rate-loop design model):
    # see the printed figures in the assertion messages; lag bound: reached + 0.05 s.
    (rms_cv, lag_cv), (rms_cp, lag_cp), (rms_pid, lag_pid) = (
        square_10hz["lqr-cv"], square_10hz["lqr-cp"], square_10hz["pid"])
    figures = square_10hz
    assert abs(lag_cv) < 0.1, figures
    assert 0.5 < lag_cp < 1.1 and 0.8 < lag_pid < 1.4, figures
    assert rms_cv < 0.045, figures
    assert rms_cv < 0.35 * rms_cp and rms_cv < 0.3 * rms_pid, figures


def _hover_z_offset(result: FlightResult, state: State) -> float:
    """Mean true z minus reference z over the last 5 s spent in ``state`` [m]."""
    mask = result.during(state)
    t = result.trace["t"][mask]
    last = t > t[-1] - 5.0
    z = result.trace["true_pos"][mask][last, 2]
    return float(np.mean(z - result.trace["ref_pos"][mask][last, 2]))


@pytest.mark.slow
def test_ten_percent_thrust_error_is_removed_by_the_observer() -> None:
    cfg = lab_config(**{"trajectory.name": "hover", "sim.thrust_scale": 0.9})
    params = assemble(cfg).vehicle
    with_observer = fly(cfg, LqrController(params=params), "hover", 20.0)
    assert with_observer.final_state is State.DONE
    assert abs(_hover_z_offset(with_observer, State.TRACK)) < 0.005  # reached 1.1 mm
    # The same LQR without it hangs below the take-off height by the closed-form offset
    # 0.1 m g (1 - sum K_j) / (0.9 |K_z|): true net force 0.9 u + 0.1 m g = 0 with, at rest,
    # u = K_z (z - r) + sum_j K_j u (K_j: the gains on the thrust sent during the delay).
    bare = LqrController(params=params, disturbance_tau=None)
    result = fly_in_process(assemble(cfg), controller=bare, trajectory=make_trajectory("hover"),
                            duration_s=20.0, max_time_s=25.0)
    assert State.TRACK not in [tr.new for tr in result.transitions]
    k_past = float(np.sum(bare.gains.K_s[3, 12 + 3::4]))
    expected = 0.1 * params.mass * params.g * (1.0 - k_past) / (0.9 * -bare.gains.K_s[3, 2])
    assert _hover_z_offset(result, State.TAKEOFF) == pytest.approx(expected, rel=0.15)


@pytest.mark.slow
def test_hinf_findings_in_the_virtual_lab() -> None:
    cfg = lab_config(**{"trajectory.name": "hover"})
    params = assemble(cfg).vehicle
    thesis = HinfController(load_hinf_gain(default_gain_path(False)), params=params)
    result = fly(cfg, thesis, "hover", 15.0)
    # as on the real X-3D (Ch. 10.3): it cannot hold the vehicle; the supervisor lands
    landing = next(tr for tr in result.transitions if tr.new is State.LAND)
    assert "tilt" in landing.reason and State.TRACK not in [tr.new for tr in result.transitions]
    lag = HinfController(load_hinf_gain(default_gain_path(True)), params=params)
    result = fly(cfg, lag, "hover", 15.0)
    assert result.final_state is State.DONE and result.success
    track = result.during(State.TRACK)
    err = rms(error_norms(result.trace["true_pos"][track], result.trace["ref_pos"][track]))
    assert err < 0.03  # reached 0.012 m


@pytest.mark.slow
@pytest.mark.parametrize("controller", ["lqr-ff", "lqr-cv"])
def test_a_waypoint_file_turning_the_heading_once_around_flies(tmp_path: Path,
                                                               controller: str) -> None:
    """A reported failure: hovering while a waypoint CSV's yaw column turns once around in
    20 s, the constant-velocity LQR tilted to 68 degrees near 115 degrees and the
    supervisor landed it. Here on a perturbed vehicle (rate gains 1.3/0.8/1.36, rate loop
    0.083 s, 8 % heavier, 5 % less lift, 30 ms delay), through the EKF at 10 Hz Vicon."""
    csv = tmp_path / "turn.csv"
    rows = [f"{t}, 0.0, 0.0, -1.0, {np.radians(18.0 * t):.6f}" for t in range(0, 21, 5)]
    csv.write_text("t, x, y, z, yaw\n" + "\n".join(rows) + "\n", encoding="utf-8")
    cfg = lab_config(**{"trajectory.name": "waypoints", "trajectory.file": str(csv),
                        "controller.type": controller, "sim.vicon.rate_hz": 10.0,
                        "sim.k_rate_scale": [1.3, 0.8, 1.36], "sim.rate_loop_tau_s": 0.083,
                        "sim.mass_scale": 1.08, "sim.thrust_scale": 0.95,
                        "sim.command_delay_s": 0.03})
    result = fly_in_process(assemble(cfg), duration_s=22.0, max_time_s=60.0)
    assert result.final_state is State.DONE and result.success
    track = result.during(State.TRACK)
    q = result.trace["true_q"][track]
    tilt = np.degrees(np.arccos(np.clip(q[:, 0] ** 2 - q[:, 1] ** 2 - q[:, 2] ** 2
                                        + q[:, 3] ** 2, -1.0, 1.0)))
    assert tilt.max() < 5.0  # reached 1.0 deg (lqr-ff), 0.3 deg (lqr-cv)
    err = rms(error_norms(result.trace["true_pos"][track], result.trace["ref_pos"][track]))
    assert err < 0.015, err  # the 1.5 cm; reached 0.38 cm (lqr-ff), 1.0 cm (lqr-cv)
    yaw = np.arctan2(2 * (q[:, 0] * q[:, 3] + q[:, 1] * q[:, 2]),
                     1 - 2 * (q[:, 2] ** 2 + q[:, 3] ** 2))
    # the whole turn was flown: the unwrapped heading advanced by a full turn
    turned = np.degrees(np.unwrap(yaw)[-1] - np.unwrap(yaw)[0])
    assert 355.0 < turned < 365.0, turned
