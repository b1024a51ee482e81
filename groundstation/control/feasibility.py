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
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from groundstation.control.trajectory import Trajectory
from groundstation.errors import TrajectoryError
from groundstation.model import QuadrotorParams, ThrustMap
from groundstation.types import FloatArray


@dataclass(frozen=True, slots=True)
class FlightLimits:
    """What the vehicle can do (SI units).

    mass_kg, gravity [m/s^2], induced_inflow I_i [N s/m] (eq. 3.9, negative);
    lift_min_n, lift_max_n : range of the upward rotor force over the thrust
    stick range [N] (positive magnitudes); max_tilt_rad : tilt from vertical;
    max_rate_rad_s : largest roll/pitch body rate (``K * 2047``);
    max_yaw_rate_rad_s : largest yaw rate; max_speed_m_s : speed limit;
    max_position_jump_m, max_velocity_jump_m_s : largest discontinuities
    accepted (set-point steps, sharp corners).
    """

    mass_kg: float = 0.60
    gravity: float = 9.82
    induced_inflow: float = -0.423
    lift_min_n: float = 0.9
    lift_max_n: float = 12.0
    max_tilt_rad: float = math.radians(20.0)
    max_rate_rad_s: float = 2.25
    max_yaw_rate_rad_s: float = 2.25
    max_speed_m_s: float = 1.5
    max_position_jump_m: float = 1.0
    max_velocity_jump_m_s: float = 0.5

    @classmethod
    def from_params(cls, params: QuadrotorParams, *, max_tilt_deg: float = 20.0,
                    max_speed_m_s: float = 1.5, max_position_jump_m: float = 1.0,
                    max_velocity_jump_m_s: float = 0.5) -> FlightLimits:
        """Limits of the vehicle model: lift range of the eq. 3.7 map over its monotonic
        stick range, rate limits ``|K| * 2047`` (eq. 3.22), mass, g and I_i."""
        f_most, f_least = ThrustMap(params.thrust_poly).force_range
        k = [abs(v) * 2047 for v in params.k_rate]
        return cls(mass_kg=params.mass, gravity=params.g, induced_inflow=params.inflow,
                   lift_min_n=-f_least, lift_max_n=-f_most,
                   max_tilt_rad=math.radians(max_tilt_deg), max_rate_rad_s=min(k[0], k[1]),
                   max_yaw_rate_rad_s=k[2], max_speed_m_s=max_speed_m_s,
                   max_position_jump_m=max_position_jump_m,
                   max_velocity_jump_m_s=max_velocity_jump_m_s)


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


def _sample(traj: Trajectory, dt: float) -> tuple[FloatArray, FloatArray, FloatArray,
                                                   FloatArray, FloatArray]:
    """Times, positions, velocities, accelerations, yaws over one period / the flight."""
    horizon = traj.duration if traj.periodic else traj.duration + 1.0
    t = np.arange(0.0, horizon + 0.5 * dt, dt)
    refs = [traj.sample(float(tk)) for tk in t]
    p = np.array([r.position for r in refs])
    v = np.array([r.velocity for r in refs])
    a = np.array([r.acceleration for r in refs])
    yaw = np.array([r.yaw for r in refs])
    return t, p, v, a, yaw


def _jumps(t: FloatArray, x: FloatArray, dx: FloatArray, tol: float) -> list[tuple[float, float]]:
    """(time, size) wherever x changes by more than the trapezoid of its derivative predicts."""
    dt = np.diff(t)[:, None]
    residual = np.linalg.norm(np.diff(x, axis=0) - 0.5 * (dx[1:] + dx[:-1]) * dt, axis=1)
    return [(float(t[k + 1]), float(residual[k])) for k in np.flatnonzero(residual > tol)]


def check_feasibility(
    traj: Trajectory,
    limits: FlightLimits,
    *,
    dt: float = 0.01,
    rate_window_s: float = 0.1,
    raise_on_error: bool = True,
) -> FeasibilityReport:
    """Check ``traj`` against ``limits``; raise TrajectoryError listing every problem.

    The tilt rate is the change of the thrust direction over ``rate_window_s``
    (about the rate loop's rise time, 0.14 s in Fig. 3.8): a small tilt step,
    as at the start of a smoothed corner, is realised by the rate loop within
    that time, while a sustained rotation must stay below the rate limit.
    Position jumps under 1 cm and velocity jumps under 1 cm/s are ignored.
    With ``raise_on_error=False`` the report is returned with its ``problems``.
    """
    t, p, v, a, yaw = _sample(traj, dt)
    m, g = limits.mass_kg, limits.gravity
    force = m * a
    force[:, 2] -= m * g + limits.induced_inflow * v[:, 2]
    lift = np.linalg.norm(force, axis=1)
    tilt = np.arccos(np.clip(-force[:, 2] / lift, -1.0, 1.0))
    direction = force / lift[:, None]
    lag = max(1, round(rate_window_s / dt))
    tilt_rate = np.linalg.norm(direction[lag:] - direction[:-lag], axis=1) / (lag * dt)
    yaw_rate = np.abs(np.diff(np.unwrap(yaw))) / dt
    report = FeasibilityReport(
        max_speed_m_s=float(np.max(np.linalg.norm(v, axis=1))),
        max_tilt_rad=float(np.max(tilt)),
        max_tilt_rate_rad_s=float(np.max(tilt_rate, initial=0.0)),
        max_yaw_rate_rad_s=float(np.max(yaw_rate, initial=0.0)),
        min_lift_n=float(np.min(lift)),
        max_lift_n=float(np.max(lift)),
        position_jumps=_jumps(t, p, v, 1e-2),
        velocity_jumps=_jumps(t, v, a, 1e-2),
    )
    report.problems.extend(_problems(report, limits, float(t[np.argmax(tilt)])))
    if report.problems and raise_on_error:
        raise TrajectoryError(
            f"trajectory {traj.name!r} cannot be flown:\n  " + "\n  ".join(report.problems)
        )
    return report


def _problems(r: FeasibilityReport, lim: FlightLimits, t_tilt: float) -> list[str]:
    """One human-readable line per broken limit."""
    out = []
    if r.max_speed_m_s > lim.max_speed_m_s:
        out.append(f"speed {r.max_speed_m_s:.2f} m/s exceeds {lim.max_speed_m_s:.2f} m/s: "
                   "slow it down (longer period)")
    if r.max_tilt_rad > lim.max_tilt_rad:
        out.append(f"needs {math.degrees(r.max_tilt_rad):.1f} deg tilt at t = {t_tilt:.2f} s, "
                   f"limit {math.degrees(lim.max_tilt_rad):.1f} deg: slow it down or "
                   "smooth the corners over a longer time")
    if r.max_tilt_rate_rad_s > lim.max_rate_rad_s:
        out.append(f"needs a tilt rate of {r.max_tilt_rate_rad_s:.2f} rad/s, limit "
                   f"{lim.max_rate_rad_s:.2f} rad/s: smooth the corners over a longer time")
    if r.max_yaw_rate_rad_s > lim.max_yaw_rate_rad_s:
        out.append(f"needs a yaw rate of {r.max_yaw_rate_rad_s:.2f} rad/s, limit "
                   f"{lim.max_yaw_rate_rad_s:.2f} rad/s")
    if r.max_lift_n > lim.lift_max_n or r.min_lift_n < lim.lift_min_n:
        out.append(f"needs lift between {r.min_lift_n:.2f} and {r.max_lift_n:.2f} N, the rotors "
                   f"give {lim.lift_min_n:.2f} to {lim.lift_max_n:.2f} N")
    for tj, size in r.position_jumps:
        if size > lim.max_position_jump_m:
            out.append(f"position jumps by {size:.2f} m at t = {tj:.2f} s, limit "
                       f"{lim.max_position_jump_m:.2f} m: use a smaller step")
    for tj, size in r.velocity_jumps:
        if size > lim.max_velocity_jump_m_s:
            out.append(f"velocity jumps by {size:.2f} m/s at t = {tj:.2f} s, limit "
                       f"{lim.max_velocity_jump_m_s:.2f} m/s: set corner smoothing or slow down")
    return out
