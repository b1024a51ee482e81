"""The simulated X-3D airframe: thesis eq. 3.19-3.22 plus rate-loop and motor lags.

State (plain Python floats, scalar math: a 2 ms step must be cheap):

* ``P`` position, NED [m]; the floor is ``z = 0`` (z down, so flying is z < 0)
* ``q`` attitude, scalar-first unit quaternion, ``R(q) = eCb`` (body FRD -> NED)
* ``v`` velocity relative to earth in body FRD axes [m/s]
* ``omega`` body rates, FRD [rad/s]: the on-board rate loop's output, a
  first-order lag (time constant ``rate_tau``) behind the set point ``K * u``
* ``lift`` body-z rotor force [N] (negative = up): a first-order lag
  (``motor_tau_s``) behind ``thrust_scale * F_lift(u_thrust)`` (eq. 3.7)

Dynamics, eq. 3.19-3.21::

    P_dot = eCb v
    q_dot = 0.5 q ⊗ [0, omega]
    v_dot = (b * lift + I_i v_3)/m e_3 + bCe [0, 0, g] - omega × v

with ``b(t) = 1 - droop * t / droop_time`` the battery factor (Ch. 5.2). The
induced inflow ``I_i v_3`` (eq. 3.9) is a rotor effect: it acts while the motors
turn (thrust stick > 0); with the motors stopped the vehicle falls freely.

What a lab throws at the vehicle, each off by default (the thesis's model):

* payload steps: ``m`` jumps by a factor at given times (``PlantParams.payload_steps``);
* wind and drag (``PlantParams.wind``): with ``v_a = v - bCe w(t)`` the airspeed in body
  axes, the rotors' drag ``-k_r s [v_a1, v_a2, 0]`` (``s = sqrt(|b lift| / (m0 g))`` the
  rotor speed over the nominal vehicle's hover speed, RotorPy's rotor drag summed over the
  rotors) with the inflow on the airspeed ``I_i v_a3`` along body z, and the frame's
  parasitic drag ``-c_D,i |v_a| v_a,i`` (RotorPy); with the wind at rest it is the drag
  of the vehicle's own motion;
* ground effect (``PlantParams.ground_effect``): the lift times Cheeseman and Bennett's
  ``1 / (1 - (R / 4 h)^2)`` at the rotors' height ``h`` above the floor.

The accelerometer (:meth:`Plant.specific_force`) feels all of them: they are forces.

Integration: the two lags are first-order linear with the set point held over a
step, so they are advanced exactly (``x += (sp - x)(1 - exp(-dt/tau))``) and
evaluated in closed form at the RK4 stage times; ``P, q, v`` take one classical
RK4 step with those ``omega(t)`` and ``lift(t)``; ``q`` is renormalised.

Ground contact: at ``z >= 0`` with ``b * lift + m g >= 0`` (lift not exceeding the
weight) the vehicle rests on the floor: it cannot sink, its velocity and rates
are zero and it sits level, keeping its heading. A descent through the floor
lands it the same way; the accelerometer feels that touchdown as the deceleration
``-v_body / impact_time`` for ``impact_time`` (the integral is the velocity lost),
so an estimator integrating the IMU sees the vehicle stop, also when its lift takes it
off the floor again at once.
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
        "_a_lift",
        "_a_lift_half",
        "_a_rate",
        "_a_rate_half",
        "_aero",
        "_droop_rate",
        "_faults",
        "_ground",
        "_impact",
        "_impact_until",
        "_inflow",
        "_payload",
        "_thrust_map",
        "_weight_nominal",
        "dt",
        "lift",
        "lift_sp",
        "mass",
        "on_ground",
        "params",
        "px",
        "py",
        "pz",
        "q0",
        "q1",
        "q2",
        "q3",
        "t",
        "vx",
        "vy",
        "vz",
        "wx",
        "wx_sp",
        "wy",
        "wy_sp",
        "wz",
        "wz_sp",
    )

    def __init__(self, params: PlantParams, dt: float) -> None:
        self.params = params
        self.dt = dt
        self._a_rate = _lag_gain(dt, params.rate_tau)
        self._a_rate_half = _lag_gain(0.5 * dt, params.rate_tau)
        self._a_lift = _lag_gain(dt, params.motor_tau_s)
        self._a_lift_half = _lag_gain(0.5 * dt, params.motor_tau_s)
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
        self._inflow = 0.0  # I_i while the motors turn, 0 when stopped
        self.on_ground = self.pz >= 0.0
        if self.on_ground:
            self.pz = 0.0
        self._impact = (0.0, 0.0, 0.0)  # touchdown deceleration felt by the IMU, FRD
        self._impact_until = -math.inf
        self._faults: list[tuple[float, float, float]] = list(params.thrust_faults)
        self.mass = params.mass  # the true mass now [kg]: payload steps change it
        self._payload = sorted(params.payload_steps)
        self._aero = params.wind
        self._ground = params.ground_effect
        self._weight_nominal = params.mass * params.g

    def add_thrust_fault(self, start: float, duration: float, lift_scale: float) -> None:
        """From ``start`` [s] for ``duration`` [s] the rotors give ``lift_scale`` times the
        lift they should (an ESC or motor fault: 2.0 doubles it, 0.5 halves it)."""
        self._faults.append((float(start), float(start) + float(duration), float(lift_scale)))

    def fault_factor(self, t: float) -> float:
        """Product of the lift scales of the thrust faults active at ``t`` [s] (1 without)."""
        factor = 1.0
        for begin, end, scale in self._faults:
            if begin <= t < end:
                factor *= scale
        return factor

    # ------------------------------------------------------------------ inputs
    def set_inputs(self, wx: float, wy: float, wz: float, lift: float) -> None:
        """Hold new set points: body rates FRD [rad/s] and rotor lift [N] (negative = up).

        ``lift`` already includes ``thrust_scale`` (see :meth:`lift_command`); 0 means
        the motors are stopped, which also removes the induced inflow (a rotor effect).
        """
        self.wx_sp, self.wy_sp, self.wz_sp, self.lift_sp = wx, wy, wz, lift
        self._inflow = self.params.inflow if lift != 0.0 else 0.0

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

    def lift_factor(self) -> float:
        """The rotors' lift now over the polynomial's: the battery, the ground effect and
        any thrust fault (the accelerometer feels all of them, up to its saturation)."""
        ground = self._ground
        factor = self.battery_factor() * (1.0 if ground is None else ground.factor(self.pz))
        return factor * self.fault_factor(self.t) if self._faults else factor

    def mass_at(self, t: float) -> float:
        """The true mass at time ``t`` [s] [kg]: the vehicle's times every payload step's
        factor whose time has come."""
        m = self.params.mass
        for when, factor in self._payload:
            if when <= t:
                m *= factor
        return m

    def wind_at(self, t: float) -> tuple[float, float, float]:
        """The wind at ``t`` [s], NED [m/s]; still air without ``PlantParams.wind``."""
        return (0.0, 0.0, 0.0) if self._aero is None else self._aero.at(t)

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
        if self._faults:
            batt *= self.fault_factor(self.t + 0.5 * dt)
        if self._ground is not None:
            batt *= self._ground.factor(self.pz)
        if self._payload:
            self.mass = self.mass_at(self.t + 0.5 * dt)
        l0 = self.lift
        l_sp = self.lift_sp
        if self.on_ground:
            if batt * l0 + self.mass * p.g >= 0.0:  # lift does not exceed the weight: stay
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
        if self._aero is None:
            self._rk4(dt, w0, wh, w1, batt * l0, batt * lh, batt * l1)
        else:
            self._rk4_aero(dt, w0, wh, w1, batt * l0, batt * lh, batt * l1)
        self.wx, self.wy, self.wz = w1
        self.lift = l1
        self.t += dt
        if self.pz >= 0.0:
            self.land()

    def _rk4(self, dt: float, w0: tuple[float, float, float], wh: tuple[float, float, float],
             w1: tuple[float, float, float], f0: float, fh: float, f1: float) -> None:
        """One RK4 step of (P, q, v) with rates and (battery-scaled) lift given at 0, dt/2, dt.

        Unrolled scalar stages: the position does not feed back, so a stage state is (q, v).
        """
        g = self.params.g
        inv_m = 1.0 / self.mass
        c = self._inflow * inv_m
        q0, q1, q2, q3 = self.q0, self.q1, self.q2, self.q3
        vx, vy, vz = self.vx, self.vy, self.vz
        h = 0.5 * dt
        a = _derivative(q0, q1, q2, q3, vx, vy, vz, *w0, f0 * inv_m, c, g)
        b = _derivative(q0 + h * a[3], q1 + h * a[4], q2 + h * a[5], q3 + h * a[6],
                        vx + h * a[7], vy + h * a[8], vz + h * a[9], *wh, fh * inv_m, c, g)
        d = _derivative(q0 + h * b[3], q1 + h * b[4], q2 + h * b[5], q3 + h * b[6],
                        vx + h * b[7], vy + h * b[8], vz + h * b[9], *wh, fh * inv_m, c, g)
        e = _derivative(q0 + dt * d[3], q1 + dt * d[4], q2 + dt * d[5], q3 + dt * d[6],
                        vx + dt * d[7], vy + dt * d[8], vz + dt * d[9], *w1, f1 * inv_m, c, g)
        self._apply_rk4(dt, a, b, d, e)

    def _rk4_aero(self, dt: float, w0: tuple[float, float, float],
                  wh: tuple[float, float, float], w1: tuple[float, float, float],
                  f0: float, fh: float, f1: float) -> None:
        """:meth:`_rk4` with the wind and drag of ``PlantParams.wind`` (see the module doc);
        the wind is taken at each stage's time, the rotor speed from each stage's lift."""
        aero = self._aero
        assert aero is not None
        g = self.params.g
        inv_m = 1.0 / self.mass
        c = self._inflow * inv_m
        rotor = aero.rotor_drag * inv_m if self._inflow != 0.0 else 0.0
        cx, cy, cz = (k * inv_m for k in aero.body_drag)
        inv_w = 1.0 / self._weight_nominal
        k0, kh, k1 = (rotor * math.sqrt(abs(f) * inv_w) for f in (f0, fh, f1))
        t = self.t
        wind0, windh, wind1 = aero.at(t), aero.at(t + 0.5 * dt), aero.at(t + dt)
        q0, q1, q2, q3 = self.q0, self.q1, self.q2, self.q3
        vx, vy, vz = self.vx, self.vy, self.vz
        h = 0.5 * dt
        a = _derivative_aero(q0, q1, q2, q3, vx, vy, vz, *w0, f0 * inv_m, c, g, *wind0, k0,
                             cx, cy, cz)
        b = _derivative_aero(q0 + h * a[3], q1 + h * a[4], q2 + h * a[5], q3 + h * a[6],
                             vx + h * a[7], vy + h * a[8], vz + h * a[9], *wh, fh * inv_m, c,
                             g, *windh, kh, cx, cy, cz)
        d = _derivative_aero(q0 + h * b[3], q1 + h * b[4], q2 + h * b[5], q3 + h * b[6],
                             vx + h * b[7], vy + h * b[8], vz + h * b[9], *wh, fh * inv_m, c,
                             g, *windh, kh, cx, cy, cz)
        e = _derivative_aero(q0 + dt * d[3], q1 + dt * d[4], q2 + dt * d[5], q3 + dt * d[6],
                             vx + dt * d[7], vy + dt * d[8], vz + dt * d[9], *w1, f1 * inv_m,
                             c, g, *wind1, k1, cx, cy, cz)
        self._apply_rk4(dt, a, b, d, e)

    def _apply_rk4(self, dt: float, a: tuple[float, ...], b: tuple[float, ...],
                   d: tuple[float, ...], e: tuple[float, ...]) -> None:
        """Combine the four RK4 stages into the new (P, q, v); renormalise q."""
        q0, q1, q2, q3 = self.q0, self.q1, self.q2, self.q3
        vx, vy, vz = self.vx, self.vy, self.vz
        s = dt / 6.0
        self.px += s * (a[0] + 2.0 * (b[0] + d[0]) + e[0])
        self.py += s * (a[1] + 2.0 * (b[1] + d[1]) + e[1])
        self.pz += s * (a[2] + 2.0 * (b[2] + d[2]) + e[2])
        q0 += s * (a[3] + 2.0 * (b[3] + d[3]) + e[3])
        q1 += s * (a[4] + 2.0 * (b[4] + d[4]) + e[4])
        q2 += s * (a[5] + 2.0 * (b[5] + d[5]) + e[5])
        q3 += s * (a[6] + 2.0 * (b[6] + d[6]) + e[6])
        self.vx = vx + s * (a[7] + 2.0 * (b[7] + d[7]) + e[7])
        self.vy = vy + s * (a[8] + 2.0 * (b[8] + d[8]) + e[8])
        self.vz = vz + s * (a[9] + 2.0 * (b[9] + d[9]) + e[9])
        n = 1.0 / math.sqrt(q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3)
        self.q0, self.q1, self.q2, self.q3 = q0 * n, q1 * n, q2 * n, q3 * n

    def land(self) -> None:
        """Rest on the floor: z = 0, no velocity or rates, level with the same heading."""
        k = -1.0 / self.params.impact_time
        self._impact = (k * self.vx, k * self.vy, k * self.vz)
        self._impact_until = self.t + self.params.impact_time
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

        In flight ``(0, 0, (b * lift + I_i v_3)/m)`` (``b`` the battery and the ground
        effect and a thrust fault; with ``PlantParams.wind`` the drag too, see the module
        doc); resting on the floor the contact force cancels gravity,
        so ``-bCe [0, 0, g]`` = (0, 0, -g) when level. For ``impact_time`` after a
        touchdown the floor's deceleration is added, whether the vehicle stays down or its
        lift takes it off again at once: the floor stopped it either way.
        """
        fx, fy, fz = self._contact_force() if self.on_ground else self._flight_force()
        if self.t < self._impact_until:  # still decelerating from the touchdown
            ix, iy, iz = self._impact
            return fx + ix, fy + iy, fz + iz
        return fx, fy, fz

    def _contact_force(self) -> tuple[float, float, float]:
        """Specific force at rest on the floor, FRD [m/s^2]: the contact cancels gravity."""
        g = self.params.g
        q0, q1, q2, q3 = self.q0, self.q1, self.q2, self.q3
        return (-g * 2.0 * (q1 * q3 - q0 * q2), -g * 2.0 * (q2 * q3 + q0 * q1),
                -g * (q0 * q0 - q1 * q1 - q2 * q2 + q3 * q3))

    def _flight_force(self) -> tuple[float, float, float]:
        """Specific force in flight, FRD [m/s^2]: the lift, the inflow and the drag."""
        lift = self.lift_factor() * self.lift
        if self._aero is None:
            return (0.0, 0.0, (lift + self._inflow * self.vz) / self.mass)
        ax, ay, az = self.air_velocity_body()
        rotor = (self._aero.rotor_drag * math.sqrt(abs(lift) / self._weight_nominal)
                 if self._inflow != 0.0 else 0.0)
        cx, cy, cz = self._aero.body_drag
        speed = math.sqrt(ax * ax + ay * ay + az * az)
        return (-(rotor + cx * speed) * ax / self.mass, -(rotor + cy * speed) * ay / self.mass,
                (lift + self._inflow * az - cz * speed * az) / self.mass)

    def air_velocity_body(self) -> tuple[float, float, float]:
        """The airspeed in body FRD axes [m/s]: the velocity less the wind (bCe w)."""
        wn, we, wd = self.wind_at(self.t)
        q0, q1, q2, q3 = self.q0, self.q1, self.q2, self.q3
        return (
            self.vx - ((q0 * q0 + q1 * q1 - q2 * q2 - q3 * q3) * wn
                       + 2.0 * (q1 * q2 + q0 * q3) * we + 2.0 * (q1 * q3 - q0 * q2) * wd),
            self.vy - (2.0 * (q1 * q2 - q0 * q3) * wn
                       + (q0 * q0 - q1 * q1 + q2 * q2 - q3 * q3) * we
                       + 2.0 * (q2 * q3 + q0 * q1) * wd),
            self.vz - (2.0 * (q1 * q3 + q0 * q2) * wn + 2.0 * (q2 * q3 - q0 * q1) * we
                       + (q0 * q0 - q1 * q1 - q2 * q2 + q3 * q3) * wd),
        )

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


def _derivative(q0: float, q1: float, q2: float, q3: float, vx: float, vy: float, vz: float,
                wx: float, wy: float, wz: float, lift_m: float, inflow_m: float,
                g: float) -> tuple[float, ...]:
    """Eq. 3.19-3.21: (P_dot (3), q_dot (4), v_dot (3)) for attitude q, body velocity v,
    rates w, lift / m [m/s^2] (battery applied) and I_i / m [1/s] (0 with motors off)."""
    # eCb (body -> NED), rows r0, r1, r2
    r20 = 2.0 * (q1 * q3 - q0 * q2)
    r21 = 2.0 * (q2 * q3 + q0 * q1)
    r22 = q0 * q0 - q1 * q1 - q2 * q2 + q3 * q3
    return (
        (q0 * q0 + q1 * q1 - q2 * q2 - q3 * q3) * vx + 2.0 * (q1 * q2 - q0 * q3) * vy
        + 2.0 * (q1 * q3 + q0 * q2) * vz,
        2.0 * (q1 * q2 + q0 * q3) * vx + (q0 * q0 - q1 * q1 + q2 * q2 - q3 * q3) * vy
        + 2.0 * (q2 * q3 - q0 * q1) * vz,
        r20 * vx + r21 * vy + r22 * vz,
        0.5 * (-wx * q1 - wy * q2 - wz * q3),
        0.5 * (wx * q0 + wz * q2 - wy * q3),
        0.5 * (wy * q0 - wz * q1 + wx * q3),
        0.5 * (wz * q0 + wy * q1 - wx * q2),
        g * r20 - (wy * vz - wz * vy),
        g * r21 - (wz * vx - wx * vz),
        g * r22 + lift_m + inflow_m * vz - (wx * vy - wy * vx),
    )


def _derivative_aero(q0: float, q1: float, q2: float, q3: float, vx: float, vy: float,
                     vz: float, wx: float, wy: float, wz: float, lift_m: float,
                     inflow_m: float, g: float, wn: float, we: float, wd: float,
                     rotor_m: float, cx_m: float, cy_m: float, cz_m: float) -> tuple[float, ...]:
    """:func:`_derivative` with drag on the airspeed: wind ``(wn, we, wd)`` NED [m/s], rotor
    drag / m ``rotor_m`` [1/s] at this stage's rotor speed, parasitic drag / m ``c*_m``
    [1/m] (see the module doc)."""
    s0, s1, s2, s3 = q0 * q0, q1 * q1, q2 * q2, q3 * q3
    r00, r11, r22 = s0 + s1 - s2 - s3, s0 - s1 + s2 - s3, s0 - s1 - s2 + s3
    r01, r10 = 2.0 * (q1 * q2 - q0 * q3), 2.0 * (q1 * q2 + q0 * q3)
    r02, r20 = 2.0 * (q1 * q3 + q0 * q2), 2.0 * (q1 * q3 - q0 * q2)
    r12, r21 = 2.0 * (q2 * q3 - q0 * q1), 2.0 * (q2 * q3 + q0 * q1)
    ax = vx - (r00 * wn + r10 * we + r20 * wd)  # airspeed, body axes: v - eCb^T w
    ay = vy - (r01 * wn + r11 * we + r21 * wd)
    az = vz - (r02 * wn + r12 * we + r22 * wd)
    speed = math.sqrt(ax * ax + ay * ay + az * az)
    return (
        r00 * vx + r01 * vy + r02 * vz,
        r10 * vx + r11 * vy + r12 * vz,
        r20 * vx + r21 * vy + r22 * vz,
        0.5 * (-wx * q1 - wy * q2 - wz * q3),
        0.5 * (wx * q0 + wz * q2 - wy * q3),
        0.5 * (wy * q0 - wz * q1 + wx * q3),
        0.5 * (wz * q0 + wy * q1 - wx * q2),
        g * r20 - (rotor_m + cx_m * speed) * ax - (wy * vz - wz * vy),
        g * r21 - (rotor_m + cy_m * speed) * ay - (wz * vx - wx * vz),
        g * r22 + lift_m + inflow_m * az - cz_m * speed * az - (wx * vy - wy * vx),
    )


def _lag_gain(dt: float, tau: float) -> float:
    """Fraction of the remaining error a first-order lag closes in ``dt`` (1 if tau = 0)."""
    return 1.0 if tau <= 0.0 else -math.expm1(-dt / tau)
