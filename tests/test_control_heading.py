"""Every controller flies the same at any heading and while the heading turns.

The quadrotor's dynamics do not depend on its heading: a flight turned about the
vertical by psi (vehicle, trajectory and its heading) must produce the same
tracking errors, turned by psi, as the flight at heading 0. These closed loops
run on the nonlinear model with the rate-loop lag, the command delay and stick
quantisation (:func:`groundstation.control.simulate.simulate`, simulated clock);
the errors may differ by the stick quantisation only (1 RC unit = 1.1e-3 rad/s),
which the issue's 1 mm RMS bound covers. Before the heading frame the thesis's
LQR tilted the vehicle 68 degrees at heading ~115 degrees.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import pytest

from groundstation.control import Controller, LqrController, PidController, make_trajectory
from groundstation.control.hinf import HinfController, default_gain_path, load_hinf_gain
from groundstation.control.lqr_ff import FeedforwardLqr
from groundstation.control.shaping import min_jerk_path
from groundstation.control.simulate import SimPlant, SimResult, simulate
from groundstation.control.trajectory import PiecewiseLinear, Trajectory, YawTurn
from groundstation.model.quaternion import quat_from_euler
from groundstation.types import FloatArray, Reference

FACTORIES: dict[str, Callable[[], Controller]] = {
    "lqr-ff": FeedforwardLqr,
    "lqr-cv": lambda: LqrController(reference_model="velocity"),
    "lqr-cp": lambda: LqrController(reference_model="position"),
    "pid": PidController,
    "hinf": lambda: HinfController(load_hinf_gain(default_gain_path(True))),
}
PIVOT = np.array([0.0, 0.0, -1.0])
OFFSET = np.array([0.06, -0.04, 0.03])  # initial position error [m], NED
PLANT = SimPlant(rate_tau=0.064, delay_s=0.02)


def _rz(psi: float) -> FloatArray:
    c, s = math.cos(psi), math.sin(psi)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


class Turned:
    """``base`` turned by ``psi`` about the vertical through :data:`PIVOT`, heading + psi."""

    def __init__(self, base: Trajectory, psi: float) -> None:
        self.base, self.psi, self._R = base, psi, _rz(psi)
        self.name, self.duration, self.periodic = base.name, base.duration, base.periodic
        self.free_heading = False

    def sample(self, t: float) -> Reference:
        r = self.base.sample(t)
        R = self._R
        return Reference(t, PIVOT + R @ (r.position - PIVOT), R @ r.velocity,
                         acceleration=R @ r.acceleration, yaw=r.yaw + self.psi,
                         jerk=R @ r.jerk, yaw_rate=r.yaw_rate)


def _fly(name: str, traj: Trajectory, duration: float, psi: float) -> tuple[SimResult, FloatArray]:
    """Fly ``traj`` turned by ``psi`` from the turned initial offset; returns the result
    and the position errors turned back to heading 0 (N, 3)."""
    turned = Turned(traj, psi)
    x0 = np.zeros(10)
    x0[0:3] = turned.sample(0.0).position + _rz(psi) @ OFFSET
    x0[3:7] = quat_from_euler(0.0, 0.0, psi + traj.sample(0.0).yaw)
    r = simulate(FACTORIES[name](), turned, duration, plant=PLANT, x0=x0)
    return r, (r.position - r.reference) @ _rz(psi)  # rows: R^T e


def _rms(e: FloatArray) -> float:
    return float(np.sqrt(np.mean(np.sum(e * e, axis=1))))


SHAPES: dict[str, tuple[Callable[[], Trajectory], float]] = {
    "hover": (lambda: make_trajectory("hover"), 6.0),
    "step": (lambda: make_trajectory("step-x", step_m=0.3, step_time_s=1.0), 6.0),
    "square": (lambda: min_jerk_path(_square()), 20.0),
}


def _square() -> PiecewiseLinear:
    sq = make_trajectory("square")
    assert isinstance(sq, PiecewiseLinear)
    return sq


@pytest.mark.slow
@pytest.mark.parametrize("shape", list(SHAPES))
@pytest.mark.parametrize("name", list(FACTORIES))
def test_the_same_errors_at_every_heading(name: str, shape: str) -> None:
    make, duration = SHAPES[shape]
    _, e0 = _fly(name, make(), duration, 0.0)
    assert _rms(e0) > 0.003  # the flight has errors worth comparing
    for deg in (90.0, 180.0, 270.0):
        _, e = _fly(name, make(), duration, math.radians(deg))
        assert _rms(e - e0) < 0.001, (deg, _rms(e - e0), _rms(e0))


HEADING_LIMITS = {  # (largest heading error, error 2 s after the turn) [deg]; reached
    "lqr-ff": (0.5, 0.5),  # 0.03, 0.02: the yaw rate is fed forward, ahead of the lag
    "lqr-cv": (2.0, 1.0),  # 1.07, 0.4: the reference model carries the yaw rate
    "lqr-cp": (100.0, 20.0),  # 94, 13.9: no feed-forward, the thesis's slow q3 weight
    "pid": (20.0, 1.0),  # 16.9, 0.01: a proportional heading loop, no feed-forward
    "hinf": (6.0, 3.0),  # 4.6, 2.4: a slow robust design
}


@pytest.mark.slow
@pytest.mark.parametrize("name", list(FACTORIES))
def test_a_full_turn_while_holding_position_changes_nothing(name: str) -> None:
    """A 360-degree turn in 20 s (min-jerk, peak 0.59 rad/s) while recovering from the
    same offset as a hover at a fixed heading: the same position errors (reached
    0.05-0.5 mm), and the heading follows its reference across +-180 degrees."""
    hover = make_trajectory("hover")
    turn = YawTurn(PIVOT, turn=2.0 * math.pi, period_s=20.0)
    _, e0 = _fly(name, hover, 22.0, 0.0)
    r, e = _fly(name, turn, 22.0, 0.0)
    assert _rms(e - e0) < 0.001, _rms(e - e0)
    q = r.quaternion
    yaw = np.arctan2(2 * (q[:, 0] * q[:, 3] + q[:, 1] * q[:, 2]),
                     1 - 2 * (q[:, 2] ** 2 + q[:, 3] ** 2))
    ref_yaw = np.array([turn.sample(float(t)).yaw for t in r.t])
    err = np.degrees(np.abs(np.angle(np.exp(1j * (yaw - ref_yaw)))))
    largest, after = HEADING_LIMITS[name]
    assert err.max() < largest and err[-1] < after, (err.max(), err[-1])


@pytest.mark.parametrize("roll_deg, pitch_deg", [(0.0, 0.0), (20.0, 0.0), (10.0, -25.0),
                                                 (40.0, 30.0)])
def test_tilt_compensation_keeps_the_vertical_lift_of_the_linear_model(
        roll_deg: float, pitch_deg: float) -> None:
    """f_z = F_lift + m g along body z (NED: lift < 0). The linear models ask for a net
    vertical force f_lin = F_lift,vertical + m g; tilted by theta only cos(theta) of the
    lift is vertical, so (f_z - m g) cos(theta) must equal f_lin - m g, and linear()
    inverts command(). Independent cosine: cos(roll) cos(pitch) (ZYX Euler angles)."""
    from groundstation.control.base import TiltCompensation

    weight = 0.6 * 9.81
    phi, theta = math.radians(roll_deg), math.radians(pitch_deg)
    q = quat_from_euler(phi, theta, math.radians(75.0))
    cos_tilt = math.cos(phi) * math.cos(theta)
    tilt = TiltCompensation(weight, enabled=True)
    for f_lin in (-1.5, 0.0, 2.0):
        f_z = tilt.command(f_lin, q)
        assert (f_z - weight) * cos_tilt == pytest.approx(f_lin - weight, abs=1e-12)
        assert tilt.linear(f_z) == pytest.approx(f_lin, abs=1e-12)
    off = TiltCompensation(weight, enabled=False)
    assert off.command(1.25, q) == 1.25 and off.linear(1.25) == 1.25
