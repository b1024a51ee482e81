"""Can a trajectory be flown within the command limits? Checked once, before flight.

The check samples the trajectory and inverts the point-mass dynamics of the
quadrotor (thesis eq. 3.11 in earth axes): the rotors must supply

    F = m a - m g e3 - I_i v3 e3        (NED, e3 = down; lift points along -body z)

so the required lift is ``|F|``, the tilt is the angle between ``-F`` and the
vertical, and the tilt rate is the rate of change of the direction of ``F``.
These are compared with the vehicle's lift range (thrust map over the stick
range), the tilt limit and the body-rate limit (``K * 2047``). Discontinuities
(set-point steps, the sharp corners of the thesis's square) cannot be flown
exactly by any vehicle; they are measured and compared with the allowed jump
sizes so a step too large for the volume or a corner too sharp is refused with
advice (smooth the corners, slow down) instead of being discovered in flight.
With a :class:`Volume`, every sampled point must also lie inside the lab's box
shrunk by a margin (the floor excepted: a reference may go down to the floor),
and a start above the ceiling is refused (the take-off would climb there).

Every refusal is one line naming the time, the point (NED m) and the limit by
the name :class:`LimitNames` gives it (the configuration key, when the flight
core builds the limits from the configuration).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from groundstation.control.trajectory import Trajectory
from groundstation.errors import TrajectoryError
from groundstation.model import QuadrotorParams, ThrustMap
from groundstation.types import FloatArray

_VEHICLE = QuadrotorParams()
"""The vehicle model's defaults (mass, g, inflow)."""


@dataclass(frozen=True, slots=True)
class LimitNames:
    """How a refusal names each limit (the configuration key that sets it, if any)."""

    speed: str = "the speed limit"
    tilt: str = "the tilt limit"
    tilt_rate: str = "the body-rate limit"
    yaw_rate: str = "the yaw-rate limit"
    lift: str = "the rotors' lift range"
    position_jump: str = "the position-jump limit"
    velocity_jump: str = "the velocity-jump limit"


@dataclass(frozen=True, slots=True)
class FlightLimits:
    """What the vehicle can do (SI units).

    mass_kg, gravity [m/s^2], induced_inflow I_i [N s/m] (eq. 3.9, negative);
    lift_min_n, lift_max_n : range of the upward rotor force over the thrust
    stick range [N] (positive magnitudes); max_tilt_rad : tilt from vertical;
    max_rate_rad_s : largest roll/pitch body rate (``K * 2047``);
    max_yaw_rate_rad_s : largest yaw rate; max_speed_m_s : speed limit;
    max_position_jump_m, max_velocity_jump_m_s : largest discontinuities
    accepted (set-point steps, sharp corners); names : what refusals call them.
    """

    mass_kg: float = _VEHICLE.mass
    gravity: float = _VEHICLE.g
    induced_inflow: float = _VEHICLE.inflow
    lift_min_n: float = 0.9
    lift_max_n: float = 12.0
    max_tilt_rad: float = math.radians(20.0)
    max_rate_rad_s: float = 2.25
    max_yaw_rate_rad_s: float = 2.25
    max_speed_m_s: float = 1.5
    max_position_jump_m: float = 1.0
    max_velocity_jump_m_s: float = 0.5
    names: LimitNames = LimitNames()

    @classmethod
    def from_params(cls, params: QuadrotorParams, *, max_tilt_deg: float = 20.0,
                    max_speed_m_s: float = 1.5, max_position_jump_m: float = 1.0,
                    max_velocity_jump_m_s: float = 0.5,
                    max_yaw_rate_rad_s: float = math.inf,
                    names: LimitNames = LimitNames()) -> FlightLimits:
        """Limits of the vehicle model: lift range of the eq. 3.7 map over its monotonic
        stick range, rate limits ``|K| * 2047`` (eq. 3.22; the yaw rate also within
        ``max_yaw_rate_rad_s``), mass, g and I_i."""
        f_most, f_least = ThrustMap(params.thrust_poly).force_range
        k = [abs(v) * 2047 for v in params.k_rate]
        return cls(mass_kg=params.mass, gravity=params.g, induced_inflow=params.inflow,
                   lift_min_n=-f_least, lift_max_n=-f_most,
                   max_tilt_rad=math.radians(max_tilt_deg), max_rate_rad_s=min(k[0], k[1]),
                   max_yaw_rate_rad_s=min(k[2], max_yaw_rate_rad_s),
                   max_speed_m_s=max_speed_m_s, max_position_jump_m=max_position_jump_m,
                   max_velocity_jump_m_s=max_velocity_jump_m_s, names=names)

    @property
    def max_accel_m_s2(self) -> float:
        """Horizontal acceleration [m/s^2] the tilt limit allows in level flight,
        ``g tan(max_tilt)``."""
        return self.gravity * math.tan(self.max_tilt_rad)


@dataclass(frozen=True, slots=True)
class Volume:
    """The box a reference must stay in: (min, max) per NED axis [m].

    margin_m : how far inside the sides and the ceiling (``z[0]``) a reference
    must stay (tracking error, braking room); the floor (``z[1]``) has none.
    name : what refusals call the box; axis ``x`` is ``{name}_x``.
    """

    x: tuple[float, float]
    y: tuple[float, float]
    z: tuple[float, float]
    margin_m: float = 0.0
    name: str = "volume"


@dataclass(frozen=True, slots=True)
class FeasibilityReport:
    """Worst values met along the trajectory, and the limits they broke (if any)."""

    max_speed_m_s: float
    max_tilt_rad: float
    max_tilt_rate_rad_s: float
    max_yaw_rate_rad_s: float
    min_lift_n: float
    max_lift_n: float
    position_jumps: list[tuple[float, float]] = field(default_factory=list)
    velocity_jumps: list[tuple[float, float]] = field(default_factory=list)
    problems: list[str] = field(default_factory=list)

    @property
    def feasible(self) -> bool:
        """True when no limit is broken."""
        return not self.problems


@dataclass(frozen=True, slots=True)
class _Samples:
    """The trajectory sampled every ``dt``: times (N,), positions, velocities and
    accelerations (N, 3), headings and heading rates (N,)."""

    t: FloatArray
    p: FloatArray
    v: FloatArray
    a: FloatArray
    yaw: FloatArray
    yaw_rate: FloatArray

    def at(self, k: int) -> str:
        """The start of a refusal line: the time and the point of sample ``k``."""
        x, y, z = self.p[k]
        return f"at t = {self.t[k]:.2f} s, ({x:.2f}, {y:.2f}, {z:.2f}) m: "


def _sample(traj: Trajectory, dt: float, horizon_s: float | None) -> _Samples:
    """Over ``[0, horizon_s]``; by default one period, or the flight and 1 s after."""
    if horizon_s is None:
        horizon_s = traj.duration if traj.periodic else traj.duration + 1.0
    elif traj.periodic and traj.duration > 0.0:
        horizon_s = min(horizon_s, traj.duration)
    t = np.arange(0.0, horizon_s + 0.5 * dt, dt)
    refs = [traj.sample(float(tk)) for tk in t]
    return _Samples(t=t, p=np.array([r.position for r in refs]),
                    v=np.array([r.velocity for r in refs]),
                    a=np.array([r.acceleration for r in refs]),
                    yaw=np.array([r.yaw for r in refs]),
                    yaw_rate=np.array([r.yaw_rate for r in refs]))


def _jumps(t: FloatArray, x: FloatArray, dx: FloatArray, tol: float) -> list[tuple[int, float]]:
    """(index, size) wherever x changes by more than the trapezoid of its derivative
    predicts (the index of the sample after the jump)."""
    dt = np.diff(t)[:, None]
    residual = np.linalg.norm(np.diff(x, axis=0) - 0.5 * (dx[1:] + dx[:-1]) * dt, axis=1)
    return [(int(k + 1), float(residual[k])) for k in np.flatnonzero(residual > tol)]


@dataclass(frozen=True, slots=True)
class _Worst:
    """Where each quantity peaks: sample indices."""

    speed: int
    tilt: int
    tilt_rate: int
    yaw_rate: int
    lift_min: int
    lift_max: int
    position_jumps: list[tuple[int, float]]
    velocity_jumps: list[tuple[int, float]]


def check_feasibility(
    traj: Trajectory,
    limits: FlightLimits,
    *,
    volume: Volume | None = None,
    horizon_s: float | None = None,
    dt: float = 0.01,
    rate_window_s: float = 0.1,
    raise_on_error: bool = True,
) -> FeasibilityReport:
    """Check ``traj`` against ``limits`` (and ``volume``); raise TrajectoryError listing
    every problem, one line each.

    horizon_s : how long the trajectory is flown [s] (default: one period, or the
    open trajectory and 1 s after); a periodic one is checked over one period at most.
    The tilt rate is the change of the thrust direction over ``rate_window_s``
    (about the rate loop's rise time, 0.14 s in Fig. 3.8): a small tilt step,
    as at the start of a smoothed corner, is realised by the rate loop within
    that time, while a sustained rotation must stay below the rate limit.
    Position jumps under 1 cm and velocity jumps under 1 cm/s are ignored.
    With ``raise_on_error=False`` the report is returned with its ``problems``.
    """
    sm = _sample(traj, dt, horizon_s)
    m, g = limits.mass_kg, limits.gravity
    force = m * sm.a
    force[:, 2] -= m * g + limits.induced_inflow * sm.v[:, 2]
    lift = np.linalg.norm(force, axis=1)
    tilt = np.arccos(np.clip(-force[:, 2] / lift, -1.0, 1.0))
    direction = force / lift[:, None]
    lag = max(1, round(rate_window_s / dt))
    tilt_rate = np.linalg.norm(direction[lag:] - direction[:-lag], axis=1) / (lag * dt)
    yaw_rate = np.abs(sm.yaw_rate)
    yaw_rate[1:] = np.maximum(yaw_rate[1:], np.abs(np.diff(np.unwrap(sm.yaw))) / dt)
    speed = np.linalg.norm(sm.v, axis=1)
    worst = _Worst(
        speed=int(np.argmax(speed)), tilt=int(np.argmax(tilt)),
        tilt_rate=int(np.argmax(tilt_rate)) + lag // 2 if tilt_rate.size else 0,
        yaw_rate=int(np.argmax(yaw_rate)), lift_min=int(np.argmin(lift)),
        lift_max=int(np.argmax(lift)), position_jumps=_jumps(sm.t, sm.p, sm.v, 1e-2),
        velocity_jumps=_jumps(sm.t, sm.v, sm.a, 1e-2),
    )
    report = FeasibilityReport(
        max_speed_m_s=float(speed[worst.speed]),
        max_tilt_rad=float(tilt[worst.tilt]),
        max_tilt_rate_rad_s=float(np.max(tilt_rate, initial=0.0)),
        max_yaw_rate_rad_s=float(yaw_rate[worst.yaw_rate]),
        min_lift_n=float(lift[worst.lift_min]),
        max_lift_n=float(lift[worst.lift_max]),
        position_jumps=[(float(sm.t[k]), size) for k, size in worst.position_jumps],
        velocity_jumps=[(float(sm.t[k]), size) for k, size in worst.velocity_jumps],
    )
    report.problems.extend(_problems(report, limits, sm, worst))
    if volume is not None:
        report.problems.extend(_volume_problems(sm, volume))
    if report.problems and raise_on_error:
        raise TrajectoryError(
            f"trajectory {traj.name!r} cannot be flown:\n  " + "\n  ".join(report.problems)
        )
    return report


def _problems(r: FeasibilityReport, lim: FlightLimits, sm: _Samples, w: _Worst) -> list[str]:
    """One human-readable line per broken limit, naming the time and the point."""
    n, out = lim.names, []
    if r.max_speed_m_s > lim.max_speed_m_s:
        out.append(f"{sm.at(w.speed)}speed {r.max_speed_m_s:.2f} m/s exceeds {n.speed} = "
                   f"{lim.max_speed_m_s:.2f} m/s: slow it down (longer period)")
    if r.max_tilt_rad > lim.max_tilt_rad:
        out.append(f"{sm.at(w.tilt)}needs {math.degrees(r.max_tilt_rad):.1f} deg tilt, "
                   f"{n.tilt} = {math.degrees(lim.max_tilt_rad):.1f} deg: slow it down or "
                   "smooth the corners over a longer time")
    if r.max_tilt_rate_rad_s > lim.max_rate_rad_s:
        out.append(f"{sm.at(w.tilt_rate)}needs a tilt rate of {r.max_tilt_rate_rad_s:.2f} "
                   f"rad/s, {n.tilt_rate} = {lim.max_rate_rad_s:.2f} rad/s: smooth the corners "
                   "over a longer time")
    if r.max_yaw_rate_rad_s > lim.max_yaw_rate_rad_s:
        out.append(f"{sm.at(w.yaw_rate)}needs a yaw rate of "
                   f"{math.degrees(r.max_yaw_rate_rad_s):.1f} deg/s, {n.yaw_rate} = "
                   f"{math.degrees(lim.max_yaw_rate_rad_s):.1f} deg/s: turn more slowly")
    lift_range = f"the rotors give {lim.lift_min_n:.2f} to {lim.lift_max_n:.2f} N ({n.lift})"
    if r.max_lift_n > lim.lift_max_n:
        out.append(f"{sm.at(w.lift_max)}needs {r.max_lift_n:.2f} N of lift, {lift_range}")
    if r.min_lift_n < lim.lift_min_n:
        out.append(f"{sm.at(w.lift_min)}needs {r.min_lift_n:.2f} N of lift, {lift_range}")
    for k, size in w.position_jumps:
        if size > lim.max_position_jump_m:
            out.append(f"{sm.at(k)}position jumps by {size:.2f} m, {n.position_jump} = "
                       f"{lim.max_position_jump_m:.2f} m: use a smaller step")
    for k, size in w.velocity_jumps:
        if size > lim.max_velocity_jump_m_s:
            out.append(f"{sm.at(k)}velocity jumps by {size:.2f} m/s, {n.velocity_jump} = "
                       f"{lim.max_velocity_jump_m_s:.2f} m/s: shape it (min-jerk), set "
                       "corner smoothing or slow down")
    return out


def _volume_problems(sm: _Samples, vol: Volume) -> list[str]:
    """One line per side of the box the trajectory leaves, at its worst point."""
    out = []
    margin = vol.margin_m
    less = f" less the {margin:.2f} m margin" if margin > 0.0 else ""
    for axis, (lo, hi) in enumerate((vol.x, vol.y, vol.z)):
        name = "xyz"[axis]
        box = f"{vol.name}_{name} [{lo:.2f}, {hi:.2f}]"
        col = sm.p[:, axis]
        floor = name == "z"  # z[1] is the floor: no margin there
        if col[0] < lo + margin and floor:
            out.append(f"{sm.at(0)}the start height {-col[0]:.2f} m is above the ceiling: "
                       f"z = {col[0]:.2f} m is outside {box}{less}")
        elif col.min() < lo + margin:
            k = int(np.argmin(col))
            out.append(f"{sm.at(k)}{name} = {col[k]:.2f} m is outside {box}{less}")
        if col.max() > hi - (0.0 if floor else margin):
            k = int(np.argmax(col))
            where = "below the floor: " if floor else ""
            out.append(f"{sm.at(k)}{name} = {col[k]:.2f} m is {where}outside {box}"
                       f"{'' if floor else less}")
    return out
