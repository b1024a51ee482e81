"""The identification flight (``trajectory.name: sysid``): doublets on each rate stick and
vertical sweeps, as a trajectory the controller flies.

ArduPilot's SystemID mode adds a chirp or doublet to one axis's input while the other
axes stay under the controller. Here the excitation is written into the reference
itself, so the flight is checked like any other before anything is connected (tilt,
tilt rate, heading rate, speed, lift and the volume: :mod:`.feasibility`) and every
failsafe acts as in any flight. The reference is the flat-output trajectory of a vehicle
that flies the doublets (hover model, eq. 4.22-4.24): a body rate ``w`` on the roll axis
is a jerk ``g w`` to the right, on the pitch axis a jerk ``-g w`` forward, on the yaw axis
the heading rate itself. ``lqr-ff`` feeds exactly those rates forward (its reference
model: ``omega_x = j_right / g``, ``omega_y = -j_forward / g``, ``omega_z = yaw_dot``),
so the rate sticks carry the doublets while its feedback holds the other axes; the
other controllers follow the same reference with a lag and excite less.

The flight, at ``center`` (NED [m]) and heading ``heading`` [rad] (the roll and pitch
moves are along the vehicle's right and forward axes), after a hold of ``hold_s``:

1. **roll, pitch, yaw**, one after the other: per pulse width ``T`` (from the rate
   loop's time constant, :data:`PULSE_WIDTHS_TAU`) a *doublet pair*: the rate ``+A`` for
   ``T``, ``-A`` for ``2T``, ``+A`` for ``T`` (the tilt, or the heading, returns to where
   it was and so, for roll and pitch, does the velocity), a hold, then the same with
   ``-A`` (back to the start), a hold. A doublet pair moves the vehicle by
   ``d = 2 g A T^3`` and back; its peak tilt is ``A T``.
2. **thrust**: climbs and descents of :data:`VERTICAL_CYCLES` cycles, each leg eased in
   and out (the velocity follows the quintic smoothstep) around a stretch at constant
   speed: the thrust stick sweeps around hover (the lift the accelerations ask), the
   constant-speed stretches give the induced inflow (eq. 3.9, App. C.2) and the holds
   the hover thrust.

Amplitudes come from the configured limits, each a share (:data:`LIMIT_SHARE`) of it:
the tilt ``A T`` at most that share of the trajectory tilt limit, the rate ``A`` of the
roll/pitch rate limit (``K x 2047``), the yaw rate of the heading-rate limit, the
vertical speed of the speed limit, every excursion within half the room to the volume
(less its margin). The rest of each limit is left to the feedback.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from groundstation.control.feasibility import FlightLimits, Volume
from groundstation.control.polynomial import PiecewisePolynomial
from groundstation.errors import TrajectoryError
from groundstation.types import FloatArray

__all__ = ["ExcitationPlan", "identification_flight", "plan_excitation"]

LIMIT_SHARE = 0.5
"""The share of each configured limit the excitation may use; the rest is the feedback's
(a vehicle whose rate gains are 30 % above the model's rotates 30 % further)."""
PULSE_WIDTHS_TAU = (2.5, 6.0)
"""Doublet pulse widths in rate-loop time constants: short ones show the delay and the
lag (the 0.064 s lag of Fig. 3.8 gives 0.16 s), long ones the gain at steady state."""
MIN_PULSE_S = 0.1
"""Shortest pulse [s]: five 50 Hz command periods."""
HOLD_S = 1.0
"""Rest between doublet pairs and around the vertical legs [s]: the closed loop settles."""
VERTICAL_CYCLES = 2
"""Climb-and-descend cycles of the thrust sweep."""
VERTICAL_EASE_S = 0.5
"""Each vertical leg's speed ramps in and out over this long [s]."""
VERTICAL_CRUISE_S = 1.2
"""Each vertical leg's stretch at constant speed [s] (the inflow needs 1 s in all)."""
MAX_VERTICAL_SPEED = 0.4
"""Fastest vertical leg [m/s] (App. C.2's climbs were of this order)."""
_DEGREE = 6  # the vertical ramps are degree 6 (the integral of the quintic smoothstep)


@dataclass(frozen=True)
class ExcitationPlan:
    """The amplitudes of an identification flight.

    widths : pulse widths T [s]; tilt : (len(widths),) peak tilt of each roll/pitch
    doublet [rad]; rate : the roll/pitch rate A per width [rad/s]; yaw_rate : the yaw
    rate per width [rad/s]; vertical_speed [m/s], vertical_cruise_s [s]: the legs
    """

    widths: tuple[float, ...]
    tilt: tuple[float, ...]
    rate: tuple[float, ...]
    yaw_rate: tuple[float, ...]
    vertical_speed: float
    vertical_cruise_s: float


def _room(center: FloatArray, volume: Volume) -> FloatArray:
    """(3,) the least distance from ``center`` to the allowed box along x, y, z [m]."""
    lo, hi = volume.allowed()
    return np.minimum(center - lo, hi - center)


def plan_excitation(center: FloatArray, limits: FlightLimits, volume: Volume,
                    rate_tau_s: float, *, share: float = LIMIT_SHARE) -> ExcitationPlan:
    """The amplitudes within ``share`` of ``limits`` and half the room in ``volume`` around
    ``center`` (NED [m]) for a rate loop of time constant ``rate_tau_s`` [s]; TrajectoryError
    when the centre leaves no room to excite in."""
    c = np.asarray(center, dtype=float)
    room = _room(c, volume)
    if np.any(room <= 0.0):
        raise TrajectoryError(f"identification flight: its centre {c.tolist()} is not inside "
                              f"{volume.name} less its margin")
    g = limits.gravity
    horizontal = 0.5 * float(min(room[0], room[1]))
    widths = tuple(max(MIN_PULSE_S, k * rate_tau_s) for k in PULSE_WIDTHS_TAU)
    tilt, rate, yaw = [], [], []
    for t in widths:
        theta = min(share * limits.max_tilt_rad, share * limits.max_rate_rad_s * t,
                    horizontal / (2.0 * g * t * t))  # d = 2 g A T^3 = 2 g theta T^2
        tilt.append(theta)
        rate.append(theta / t)
        yaw.append(share * limits.max_yaw_rate_rad_s)
    vertical_room = 0.5 * float(room[2])  # the legs climb from the centre and come back
    speed = min(MAX_VERTICAL_SPEED, share * limits.max_speed_m_s)
    cruise = VERTICAL_CRUISE_S
    if speed * (VERTICAL_EASE_S + cruise) > vertical_room:  # climb = v (ease + cruise)
        cruise = max(0.0, vertical_room / speed - VERTICAL_EASE_S)
        speed = min(speed, vertical_room / (VERTICAL_EASE_S + cruise))
    return ExcitationPlan(tuple(widths), tuple(tilt), tuple(rate), tuple(yaw), speed, cruise)


class _Builder:
    """Appends segments of constant jerk (roll, pitch), constant heading rate (yaw) or
    eased vertical speed, keeping the exact end state of each axis."""

    def __init__(self, center: FloatArray, heading: float) -> None:
        self.durations: list[float] = []
        self.coefficients: list[FloatArray] = []
        # body-aligned axes: forward, right (horizontal), down; and the heading
        self.p = np.array([0.0, 0.0, float(center[2])])
        self.v = np.zeros(3)
        self.a = np.zeros(3)
        self.yaw = heading
        self._origin = np.asarray(center, dtype=float)
        self._c, self._s = math.cos(heading), math.sin(heading)

    def _append(self, duration: float, local: FloatArray, yaw: FloatArray) -> None:
        """One segment: ``local`` (K+1, 3) forward, right, down coefficients; ``yaw`` (K+1,)."""
        coef = np.zeros((_DEGREE + 1, 4))
        fwd, right = local[:, 0], local[:, 1]
        coef[:, 0] = self._c * fwd - self._s * right
        coef[:, 1] = self._s * fwd + self._c * right
        coef[0, 0] += self._origin[0]
        coef[0, 1] += self._origin[1]
        coef[:, 2] = local[:, 2]
        coef[:, 3] = yaw
        self.durations.append(duration)
        self.coefficients.append(coef)

    def jerk(self, duration: float, jerk: FloatArray) -> None:
        """Constant jerk (3,) [m/s^3] in the body-aligned axes for ``duration`` [s]."""
        local = np.zeros((_DEGREE + 1, 3))
        local[0], local[1], local[2], local[3] = self.p, self.v, 0.5 * self.a, jerk / 6.0
        yaw = np.zeros(_DEGREE + 1)
        yaw[0] = self.yaw
        self._append(duration, local, yaw)
        h = duration
        self.p = self.p + self.v * h + 0.5 * self.a * h * h + jerk * h ** 3 / 6.0
        self.v = self.v + self.a * h + 0.5 * jerk * h * h
        self.a = self.a + jerk * h

    def hold(self, duration: float) -> None:
        """Rest for ``duration`` [s] (after a doublet pair the state is at rest)."""
        self.jerk(duration, np.zeros(3))

    def turn(self, duration: float, rate: float) -> None:
        """Heading rate ``rate`` [rad/s] for ``duration`` [s], position held."""
        local = np.zeros((_DEGREE + 1, 3))
        local[0] = self.p
        yaw = np.zeros(_DEGREE + 1)
        yaw[0], yaw[1] = self.yaw, rate
        self._append(duration, local, yaw)
        self.yaw += rate * duration

    def vertical(self, velocity: float, ease: float, cruise: float) -> None:
        """A vertical leg at ``velocity`` [m/s] (NED: negative climbs), its speed eased in
        and out over ``ease`` [s] (the quintic smoothstep ``S``) around ``cruise`` [s] at
        constant speed; it moves ``velocity (ease + cruise)``."""
        yaw = np.zeros(_DEGREE + 1)
        yaw[0] = self.yaw
        ramp = np.zeros(_DEGREE + 1)  # R(tau) = int_0^tau S(s / ease) ds, R(ease) = ease / 2
        ramp[4], ramp[5], ramp[6] = 2.5 / ease ** 3, -3.0 / ease ** 4, 1.0 / ease ** 5
        ease_in = velocity * ramp  # speed 0 -> velocity
        cruising = np.zeros(_DEGREE + 1)
        cruising[1] = velocity
        ease_out = cruising - velocity * ramp  # speed velocity -> 0
        for duration, poly, moved in ((ease, ease_in, 0.5 * ease),
                                      (cruise, cruising, cruise),
                                      (ease, ease_out, 0.5 * ease)):
            if duration <= 0.0:
                continue
            local = np.zeros((_DEGREE + 1, 3))
            local[0] = self.p
            local[:, 2] += poly
            self._append(duration, local, yaw)
            self.p[2] += velocity * moved

    def build(self, name: str, description: str) -> PiecewisePolynomial:
        breaks = np.concatenate([[0.0], np.cumsum(self.durations)])
        return PiecewisePolynomial(breaks, np.array(self.coefficients), name=name,
                                   description=description)


_DOUBLET = (1.0, -1.0, -1.0, 1.0)
"""A doublet pair's rate in units of A, each for one pulse width: +A for T, -A for 2T, +A
for T. Its integral (the tilt or heading) returns to zero, and for roll and pitch the
integral of that (the velocity) too."""


def identification_flight(center: FloatArray | list[float], heading: float,
                          limits: FlightLimits, volume: Volume, rate_tau_s: float, *,
                          share: float = LIMIT_SHARE,
                          name: str = "sysid") -> PiecewisePolynomial:
    """The identification flight (see the module docstring) as polynomial segments.

    center : (3,) NED [m] where it hovers and excites; heading : the heading [rad] it
    flies at (the roll moves go right of it, the pitch moves forward); limits, volume :
    what the reference may ask and where (:func:`plan_excitation`); rate_tau_s : the
    rate loop's time constant [s] (``vehicle.rate_loop_tau_s``). TrajectoryError if the
    centre leaves no room.
    """
    c = np.asarray(center, dtype=float)
    if c.shape != (3,) or not np.all(np.isfinite(c)) or not math.isfinite(heading):
        raise TrajectoryError(f"identification flight: centre {center!r} must be 3 finite "
                              f"numbers (NED, m) and the heading finite, found {heading!r}")
    plan = plan_excitation(c, limits, volume, rate_tau_s, share=share)
    g = limits.gravity
    b = _Builder(c, heading)
    b.hold(HOLD_S)
    # roll: a body rate w about x tilts the lift to the right: jerk g w to the right;
    # pitch: w about y (nose up) tilts it back: jerk -g w forward (eq. 4.22-4.24)
    for along, sense in ((1, 1.0), (0, -1.0)):  # roll (right), then pitch (forward)
        for width, rate in zip(plan.widths, plan.rate, strict=True):
            for sign in (1.0, -1.0):  # the second pair brings the vehicle back
                for k in _DOUBLET:
                    jerk = np.zeros(3)
                    jerk[along] = sense * g * sign * k * rate
                    b.jerk(width, jerk)
                b.v[:], b.a[:] = 0.0, 0.0  # exactly at rest (the sums are, to rounding)
                b.hold(HOLD_S)
    for width, rate in zip(plan.widths, plan.yaw_rate, strict=True):
        for sign in (1.0, -1.0):
            for k in _DOUBLET:
                b.turn(width, sign * k * rate)
            b.hold(HOLD_S)
    for _ in range(VERTICAL_CYCLES):
        for velocity in (-plan.vertical_speed, plan.vertical_speed):  # up, then down
            b.vertical(velocity, VERTICAL_EASE_S, plan.vertical_cruise_s)
            b.hold(HOLD_S)
    widths = ", ".join(f"{w:.2f}" for w in plan.widths)
    description = (
        f"identification flight at ({c[0]:g}, {c[1]:g}, {c[2]:g}) m, heading "
        f"{math.degrees(heading):g} deg: doublet pairs on roll, pitch and yaw (pulses "
        f"{widths} s; tilt up to {math.degrees(max(plan.tilt)):.1f} deg, rates up to "
        f"{max(plan.rate):.2f} rad/s, yaw rate {max(plan.yaw_rate):.2f} rad/s), then "
        f"{VERTICAL_CYCLES} climbs and descents at {plan.vertical_speed:.2f} m/s")
    return b.build(name, description)
