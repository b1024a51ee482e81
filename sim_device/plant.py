"""The simulated X-3D airframe: thesis eq. 3.19-3.22 plus rate-loop and motor lags.

State (plain Python floats, scalar math: a 2 ms step must be cheap):

* ``P`` position, NED [m]; the floor is ``z = 0`` (z down, so flying is z < 0)
* ``q`` attitude, scalar-first unit quaternion, ``R(q) = eCb`` (body FRD -> NED)
* ``v`` velocity relative to earth in body FRD axes [m/s]
* ``omega`` body rates, FRD [rad/s]: the on-board rate loop's output, a
  first-order lag (time constant ``rate_tau``) behind the set point ``K * u``
* ``lift`` body-z rotor force [N] (negative = up): a first-order lag
  (``thrust_tau``) behind ``thrust_scale * F_lift(u_thrust)`` (eq. 3.7)

Dynamics, eq. 3.19-3.21::

    P_dot = eCb v
    q_dot = 0.5 q ⊗ [0, omega]
    v_dot = (b * lift + I_i v_3)/m e_3 + bCe [0, 0, g] - omega × v

with ``b(t) = 1 - droop * t / droop_time`` the battery factor (Ch. 5.2).

Integration: the two lags are first-order linear with the set point held over a
step, so they are advanced exactly (``x += (sp - x)(1 - exp(-dt/tau))``) and
evaluated in closed form at the RK4 stage times; ``P, q, v`` take one classical
RK4 step with those ``omega(t)`` and ``lift(t)``; ``q`` is renormalised.

Ground contact: at ``z >= 0`` with ``b * lift + m g >= 0`` (lift not exceeding the
weight) the vehicle rests on the floor: it cannot sink, its velocity and rates
are zero and it sits level, keeping its heading. A descent through the floor
lands it the same way.
"""

from __future__ import annotations

import math

from groundstation.model.thrust import ThrustMap
from sim_device.params import PlantParams


class Plant:
    """Rigid-body plant with its own integrator state (see the module docstring).

    params : physical parameters; dt : fixed step [s].
    Inputs are set with :meth:`set_inputs` and held until changed.
    """

    __slots__ = (
        "_a_lift", "_a_lift_half", "_a_rate", "_a_rate_half", "_droop_rate", "_thrust_map",
        "dt", "lift", "lift_sp", "on_ground", "params",
        "px", "py", "pz", "q0", "q1", "q2", "q3", "t",
        "vx", "vy", "vz", "wx", "wx_sp", "wy", "wy_sp", "wz", "wz_sp",
    )

    def __init__(self, params: PlantParams, dt: float) -> None:
        self.params = params
        self.dt = dt
        self._a_rate = _lag_gain(dt, params.rate_tau)
        self._a_rate_half = _lag_gain(0.5 * dt, params.rate_tau)
        self._a_lift = _lag_gain(dt, params.thrust_tau)
        self._a_lift_half = _lag_gain(0.5 * dt, params.thrust_tau)
        self._droop_rate = params.battery_droop / params.battery_droop_time
        a3, a2, a1, a0 = params.thrust_poly
        self._thrust_map = ThrustMap((a3, a2, a1, a0))
        self.t = 0.0
        self.px, self.py, self.pz = params.initial_position
        half = 0.5 * params.initial_yaw
        self.q0, self.q1, self.q2, self.q3 = math.cos(half), 0.0, 0.0, math.sin(half)
        self.vx = self.vy = self.vz = 0.0
        self.wx = self.wy = self.wz = 0.0
        self.wx_sp = self.wy_sp = self.wz_sp = 0.0
        self.lift = self.lift_sp = 0.0
        self.on_ground = self.pz >= 0.0
        if self.on_ground:
            self.pz = 0.0

    # ------------------------------------------------------------------ inputs
    def set_inputs(self, wx: float, wy: float, wz: float, lift: float) -> None:
        """Hold new set points: body rates FRD [rad/s] and rotor lift [N] (negative = up).

        ``lift`` already includes ``thrust_scale`` (see :meth:`lift_command`).
        """
        self.wx_sp, self.wy_sp, self.wz_sp, self.lift_sp = wx, wy, wz, lift

    def lift_command(self, thrust: int) -> float:
        """Lift set point [N] for a thrust stick: ``thrust_scale * F_lift(u)`` (eq. 3.7).

        A thrust stick of 0 stops the motors: no lift at all.
        """
        if thrust <= 0:
            return 0.0
        return self.params.thrust_scale * self._thrust_map.force(float(thrust))

    def battery_factor(self, t: float | None = None) -> float:
        """Fraction of nominal lift the battery delivers at time ``t`` [s] (default now)."""
        return max(0.5, 1.0 - self._droop_rate * (self.t if t is None else t))

    # ------------------------------------------------------------------ stepping
    def run(self, steps: int) -> None:
        """Advance ``steps`` fixed steps of ``dt``."""
        for _ in range(steps):
            self.step()

    def step(self) -> None:
        """Advance one step of ``dt``: lags exactly, rigid body by RK4, then ground contact."""
        p = self.params
        dt = self.dt
        batt = max(0.5, 1.0 - self._droop_rate * (self.t + 0.5 * dt))
        l0 = self.lift
        l_sp = self.lift_sp
        if self.on_ground:
            if batt * l0 + p.mass * p.g >= 0.0:  # lift does not exceed the weight: stay
                self.lift = l0 + (l_sp - l0) * self._a_lift
                self.t += dt
                return
            self.on_ground = False
        w0 = (self.wx, self.wy, self.wz)
        sp = (self.wx_sp, self.wy_sp, self.wz_sp)
        ah, af = self._a_rate_half, self._a_rate
        wh = (w0[0] + (sp[0] - w0[0]) * ah, w0[1] + (sp[1] - w0[1]) * ah,
              w0[2] + (sp[2] - w0[2]) * ah)
        w1 = (w0[0] + (sp[0] - w0[0]) * af, w0[1] + (sp[1] - w0[1]) * af,
              w0[2] + (sp[2] - w0[2]) * af)
        lh = l0 + (l_sp - l0) * self._a_lift_half
        l1 = l0 + (l_sp - l0) * self._a_lift
        self._rk4(dt, w0, wh, w1, batt * l0, batt * lh, batt * l1)
        self.wx, self.wy, self.wz = w1
        self.lift = l1
        self.t += dt
        if self.pz >= 0.0:
            self.land()

    def _rk4(self, dt: float, w0: tuple[float, float, float], wh: tuple[float, float, float],
             w1: tuple[float, float, float], f0: float, fh: float, f1: float) -> None:
        """One RK4 step of (P, q, v) with rates and (battery-scaled) lift given at 0, dt/2, dt."""
        x = (self.px, self.py, self.pz, self.q0, self.q1, self.q2, self.q3,
             self.vx, self.vy, self.vz)
        deriv = self._derivative
        k1 = deriv(x, w0, f0)
        h = 0.5 * dt
        k2 = deriv(tuple([a + h * b for a, b in zip(x, k1, strict=True)]), wh, fh)
        k3 = deriv(tuple([a + h * b for a, b in zip(x, k2, strict=True)]), wh, fh)
        k4 = deriv(tuple([a + dt * b for a, b in zip(x, k3, strict=True)]), w1, f1)
        s = dt / 6.0
        px, py, pz, q0, q1, q2, q3, vx, vy, vz = [
            a + s * (b1 + 2.0 * (b2 + b3) + b4)
            for a, b1, b2, b3, b4 in zip(x, k1, k2, k3, k4, strict=True)
        ]
        n = 1.0 / math.sqrt(q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3)
        self.px, self.py, self.pz = px, py, pz
        self.q0, self.q1, self.q2, self.q3 = q0 * n, q1 * n, q2 * n, q3 * n
        self.vx, self.vy, self.vz = vx, vy, vz

    def _derivative(self, x: tuple[float, ...], w: tuple[float, float, float],
                    lift: float) -> tuple[float, ...]:
        """Eq. 3.19-3.21 for state x = (P, q, v), rates w, lift [N] (battery applied)."""
        _, _, _, q0, q1, q2, q3, vx, vy, vz = x
        wx, wy, wz = w
        p = self.params
        # eCb (body -> NED), rows r0, r1, r2
        r00 = q0 * q0 + q1 * q1 - q2 * q2 - q3 * q3
        r01 = 2.0 * (q1 * q2 - q0 * q3)
        r02 = 2.0 * (q1 * q3 + q0 * q2)
        r10 = 2.0 * (q1 * q2 + q0 * q3)
        r11 = q0 * q0 - q1 * q1 + q2 * q2 - q3 * q3
        r12 = 2.0 * (q2 * q3 - q0 * q1)
        r20 = 2.0 * (q1 * q3 - q0 * q2)
        r21 = 2.0 * (q2 * q3 + q0 * q1)
        r22 = q0 * q0 - q1 * q1 - q2 * q2 + q3 * q3
        g = p.g
        return (
            r00 * vx + r01 * vy + r02 * vz,
            r10 * vx + r11 * vy + r12 * vz,
            r20 * vx + r21 * vy + r22 * vz,
            0.5 * (-wx * q1 - wy * q2 - wz * q3),
            0.5 * (wx * q0 + wz * q2 - wy * q3),
            0.5 * (wy * q0 - wz * q1 + wx * q3),
            0.5 * (wz * q0 + wy * q1 - wx * q2),
            g * r20 - (wy * vz - wz * vy),
            g * r21 - (wz * vx - wx * vz),
            g * r22 + (lift + p.inflow * vz) / p.mass - (wx * vy - wy * vx),
        )

    def land(self) -> None:
        """Rest on the floor: z = 0, no velocity or rates, level with the same heading."""
        self.pz = 0.0
        self.vx = self.vy = self.vz = 0.0
        self.wx = self.wy = self.wz = 0.0
        yaw = self.yaw()
        self.q0, self.q1, self.q2, self.q3 = math.cos(0.5 * yaw), 0.0, 0.0, math.sin(0.5 * yaw)
        self.on_ground = True

    # ------------------------------------------------------------------ outputs
    def yaw(self) -> float:
        """Heading [rad] (3-2-1 Euler psi) of the current attitude."""
        q0, q1, q2, q3 = self.q0, self.q1, self.q2, self.q3
        return math.atan2(2.0 * (q0 * q3 + q1 * q2), 1.0 - 2.0 * (q2 * q2 + q3 * q3))

    def tilt_cos(self) -> float:
        """cos of the angle between body z and earth z (1 = level), R[2, 2]."""
        q0, q1, q2, q3 = self.q0, self.q1, self.q2, self.q3
        return q0 * q0 - q1 * q1 - q2 * q2 + q3 * q3

    def specific_force(self) -> tuple[float, float, float]:
        """What an ideal accelerometer reads, FRD [m/s^2]: non-gravitational force / m.

        In flight ``(0, 0, (b * lift + I_i v_3)/m)``; resting on the floor the contact
        force cancels gravity, so ``-bCe [0, 0, g]`` = (0, 0, -g) when level.
        """
        p = self.params
        q0, q1, q2, q3 = self.q0, self.q1, self.q2, self.q3
        if self.on_ground:
            g = p.g
            return (-g * 2.0 * (q1 * q3 - q0 * q2), -g * 2.0 * (q2 * q3 + q0 * q1),
                    -g * (q0 * q0 - q1 * q1 - q2 * q2 + q3 * q3))
        return (0.0, 0.0, (self.battery_factor() * self.lift + p.inflow * self.vz) / p.mass)

    def velocity_ned(self) -> tuple[float, float, float]:
        """Velocity relative to earth in NED axes [m/s] (eCb v)."""
        q0, q1, q2, q3 = self.q0, self.q1, self.q2, self.q3
        vx, vy, vz = self.vx, self.vy, self.vz
        return (
            (q0 * q0 + q1 * q1 - q2 * q2 - q3 * q3) * vx + 2.0 * (q1 * q2 - q0 * q3) * vy
            + 2.0 * (q1 * q3 + q0 * q2) * vz,
            2.0 * (q1 * q2 + q0 * q3) * vx + (q0 * q0 - q1 * q1 + q2 * q2 - q3 * q3) * vy
            + 2.0 * (q2 * q3 - q0 * q1) * vz,
            2.0 * (q1 * q3 - q0 * q2) * vx + 2.0 * (q2 * q3 + q0 * q1) * vy
            + (q0 * q0 - q1 * q1 - q2 * q2 + q3 * q3) * vz,
        )


def _lag_gain(dt: float, tau: float) -> float:
    """Fraction of the remaining error a first-order lag closes in ``dt`` (1 if tau = 0)."""
    return 1.0 if tau <= 0.0 else -math.expm1(-dt / tau)
