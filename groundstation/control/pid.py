"""Cascaded PID baseline (thesis Ch. 8): position -> velocity -> attitude -> body rates.

The thesis compares its LQR with "10 PID controllers connected for position,
orientation and velocity" without printing their structure; this is the
conventional cascade with that count (3 position P, 3 velocity PID, roll,
pitch and yaw attitude P, and the thrust path):

1. position P (earth axes): ``v_sp = Kp_p (r - P)``, clamped to ``max_speed``;
   optionally plus the reference velocity (off by default: the thesis's PID
   has no feed-forward, which is why it lags like the constant-position LQR);
2. velocity PID on ``e_v = v_sp - v`` (earth axes, ``v = eCb v_body``):
   north/east give the tilt set points in the heading frame (pitch nose down
   to go north: ``theta = -k e_north``, roll right to go east: ``phi = +k
   e_east``, eq. 4.22-4.23) clamped to ``max_tilt``; down gives ``F_z = k
   e_down`` [N] plus the extra lift a tilted vehicle needs, ``m g (1 - 1/cos)``;
3. attitude P on the error quaternion ``q_e = q* ⊗ q_sp`` (body axes):
   ``omega = 2 Kp_att sign(q_e0) [q_e1, q_e2, q_e3]``, clamped to the rate limits.

Integrators hold while their output saturates (conditional anti-windup).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from groundstation.control.sticks import CommandLimits, StickParams
from groundstation.errors import ControlError
from groundstation.model import QuadrotorParams
from groundstation.model.quaternion import dcm_from_quat
from groundstation.types import ControlOutput, Reference, StateEstimate


def _vec3(values: Sequence[float], name: str) -> np.ndarray:
    arr = np.asarray(values, dtype=float)
    if arr.shape != (3,) or not np.all(np.isfinite(arr)) or np.any(arr < 0.0):
        raise ControlError(f"{name} must be 3 finite non-negative gains, found {values!r}")
    return arr


class PidController:
    """The cascaded PID (see the module docstring). Gains per axis [x, y, z] / [roll, pitch, yaw].

    position_kp [1/s]; velocity_kp, velocity_ki, velocity_kd: x/y in rad of
    tilt per (m/s, m, m/s^2), z in N per (m/s, m, m/s^2); attitude_kp [1/s];
    max_tilt_deg; max_speed [m/s] on the velocity set point; velocity_feedforward
    adds the reference velocity to it; dt [s] the loop period; params: the
    vehicle; limits: rate and F_z saturation (default from ``params``).
    """

    def __init__(
        self,
        *,
        params: QuadrotorParams | None = None,
        dt: float = 0.02,
        position_kp: Sequence[float] = (0.8, 0.8, 1.2),
        velocity_kp: Sequence[float] = (0.25, 0.25, 4.0),
        velocity_ki: Sequence[float] = (0.05, 0.05, 1.5),
        velocity_kd: Sequence[float] = (0.0, 0.0, 0.0),
        attitude_kp: Sequence[float] = (4.0, 4.0, 2.0),
        max_tilt_deg: float = 20.0,
        max_speed: float = 1.0,
        velocity_feedforward: bool = False,
        integral_limit: float = 2.0,
        limits: CommandLimits | None = None,
    ) -> None:
        self.params = params if params is not None else QuadrotorParams()
        if not (dt > 0.0 and 0.0 < max_tilt_deg < 90.0 and max_speed > 0.0):
            raise ControlError("need dt > 0, 0 < max_tilt_deg < 90 and max_speed > 0")
        self.dt = dt
        self._kp_p = _vec3(position_kp, "position_kp")
        self._kp_v = _vec3(velocity_kp, "velocity_kp")
        self._ki_v = _vec3(velocity_ki, "velocity_ki")
        self._kd_v = _vec3(velocity_kd, "velocity_kd")
        self._kp_a = 2.0 * _vec3(attitude_kp, "attitude_kp")
        self._max_tilt = math.radians(max_tilt_deg)
        self._max_speed = max_speed
        self._feedforward = velocity_feedforward
        self._i_limit = integral_limit
        lim = limits or CommandLimits.from_stick_params(StickParams.from_quadrotor(self.params))
        self._w_lo, self._w_hi = lim.omega_min.copy(), lim.omega_max.copy()
        self._f_lo, self._f_hi = lim.f_z_min, lim.f_z_max
        self._integral = np.zeros(3)
        self._v_prev = np.zeros(3)
        self._have_prev = False

    lead_s = 0.0

    def reset(self) -> None:
        """Zero the velocity integrators and the derivative memory."""
        self._integral[:] = 0.0
        self._have_prev = False

    def sent(self, output: ControlOutput, automatic: bool) -> None:
        """Nothing to record: the cascade feeds back measured states only."""

    def step(self, t: float, estimate: StateEstimate, reference: Reference,
             preview: Reference | None = None) -> ControlOutput:
        """One cascade evaluation: body-rate set points [rad/s] and F_z [N]."""
        q = estimate.quaternion
        v = dcm_from_quat(q) @ estimate.velocity_body  # earth axes
        v_sp = self._kp_p * (reference.position - estimate.position)
        if self._feedforward:
            v_sp += reference.velocity
        speed = math.hypot(v_sp[0], v_sp[1])
        if speed > self._max_speed:
            v_sp[0:2] *= self._max_speed / speed
        v_sp[2] = min(max(v_sp[2], -self._max_speed), self._max_speed)
        e_v = v_sp - v
        accel = (v - self._v_prev) / self.dt if self._have_prev else np.zeros(3)
        self._v_prev[:] = v
        self._have_prev = True
        cmd = self._kp_v * e_v + self._ki_v * self._integral - self._kd_v * accel
        psi = reference.yaw
        c, s = math.cos(psi), math.sin(psi)
        fwd = c * cmd[0] + s * cmd[1]  # heading frame
        right = -s * cmd[0] + c * cmd[1]
        theta, phi = -fwd, right
        tilt = math.hypot(theta, phi)
        sat_xy = tilt > self._max_tilt
        if sat_xy:
            theta *= self._max_tilt / tilt
            phi *= self._max_tilt / tilt
        weight = self.params.mass * self.params.g
        f_z = cmd[2] + weight * (1.0 - 1.0 / (math.cos(theta) * math.cos(phi)))
        sat_z = not self._f_lo <= f_z <= self._f_hi
        f_z = min(max(f_z, self._f_lo), self._f_hi)
        self._integrate(e_v, sat_xy, sat_z)
        omega = self._attitude(q, phi, theta, psi)
        return ControlOutput(omega=omega, f_z=f_z)

    def _integrate(self, e_v: np.ndarray, sat_xy: bool, sat_z: bool) -> None:
        """Conditional integration: hold an axis whose output is saturated."""
        i = self._integral
        if not sat_xy:
            i[0:2] += self.dt * e_v[0:2]
        if not sat_z:
            i[2] += self.dt * e_v[2]
        np.clip(i, -self._i_limit, self._i_limit, out=i)

    def _attitude(self, q: np.ndarray, phi: float, theta: float, psi: float) -> np.ndarray:
        """Rates from the error quaternion ``q* ⊗ q_sp`` (3-2-1 set point, eq. 2.4)."""
        cf, sf = math.cos(0.5 * phi), math.sin(0.5 * phi)
        ct, st = math.cos(0.5 * theta), math.sin(0.5 * theta)
        cp, sp = math.cos(0.5 * psi), math.sin(0.5 * psi)
        d0 = cp * ct * cf + sp * st * sf  # q_sp = q_z(psi) ⊗ q_y(theta) ⊗ q_x(phi)
        d1 = cp * ct * sf - sp * st * cf
        d2 = cp * st * cf + sp * ct * sf
        d3 = sp * ct * cf - cp * st * sf
        a0, a1, a2, a3 = q[0], -q[1], -q[2], -q[3]  # conjugate of q
        e0 = a0 * d0 - a1 * d1 - a2 * d2 - a3 * d3
        e = np.array([
            a0 * d1 + a1 * d0 + a2 * d3 - a3 * d2,
            a0 * d2 - a1 * d3 + a2 * d0 + a3 * d1,
            a0 * d3 + a1 * d2 - a2 * d1 + a3 * d0,
        ])
        e *= self._kp_a if e0 >= 0.0 else -self._kp_a
        return np.clip(e, self._w_lo, self._w_hi, out=e)
