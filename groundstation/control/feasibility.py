"""Can a trajectory be flown within the command limits? Checked once, before flight.

The check inverts the point-mass dynamics of the quadrotor (thesis eq. 3.11 in earth
axes): the rotors must supply

    F = m a - m g e3 - I_i v3 e3        (NED, e3 = down; lift points along -body z)

so the required lift is ``|F|``, the tilt is the angle between ``-F`` and the vertical,
and the tilt rate is the rate at which the direction of ``F`` turns, ``|F x F'| / |F|^2``
with ``F' = m j - I_i a3 e3``. These, the speed, the heading rate and every coordinate
are compared with the vehicle's lift range (thrust map over the stick range), the tilt
limit, the body-rate limit (``K * 2047``), the speed and heading-rate limits and the
volume. Peak acceleration and jerk are reported (the flight core's envelope).

It works on the curve that will be flown, not on samples that can fall on knots:

1. **Closed forms first** (no sampling): a trajectory that knows where its peaks are
   (``critical_times``: the figure-eight's centre crossing and lobes, the middle of a
   heading turn) is evaluated there; a limit broken at one of those points is broken,
   and the refusal comes at once (a figure-eight of period 1e-9 s, a turn in 1 ns).
   Derivatives that are not finite are refused too.
2. **Every piece, bounded** (:mod:`groundstation.control.curve`): a trajectory that can
   describe itself in pieces (polynomial segments from their coefficients, the
   figure-eight from its closed form, eased clocks by the chain rule) gives rigorous
   bounds of its derivatives on each piece. Each quantity q is then maximised by
   branch and bound: with ``|q'| <= L`` on ``[a, b]``, no value between the samples
   ``q(a)`` and ``q(b)`` exceeds ``(q(a) + q(b) + L (b - a)) / 2``; intervals whose
   bound could still beat the best sample (by more than the quantity's tolerance) or
   cross the limit are halved until none can. The bounds per quantity: a coordinate
   ``|v|``, the speed ``|a|``, the acceleration ``|j|``, the jerk ``|snap|``, the lift
   ``F' <= m J + |I_i| A``, the tilt ``F' / F_min``, the tilt rate
   ``F'' / F_min + 2 F'^2 / F_min^2`` (``F_min`` the least lift on the interval:
   ``min(|F(a)|, |F(b)|) - F' (b - a) / 2``). The peak found is a value the curve
   takes, within the tolerance of the true peak, and the verdict uses the proven bound:
   nothing is accepted that could break a limit between two samples.
   Jumps between pieces are measured exactly (position, velocity; an acceleration jump
   is a tilt step the rate loop makes within ``rate_window_s``, so it counts as that
   tilt rate).
3. A trajectory that cannot describe itself (a run-time plan) is sampled every ``dt``
   as before; between samples nothing is proven (the tilt rate is the change of the
   thrust direction over ``rate_window_s``, a position or velocity that changes by more
   than the trapezoid of its derivative predicts is a jump).

Every refusal is at most one line per limit, naming the worst point (time, position,
value, limit by the name :class:`LimitNames` gives it), how many pieces (or samples)
break it, and what to change: "slow it down by k = 1.37" is the time-scaling that
brings the worst points within the limit (stretching time by k divides speed and
heading rate by k, acceleration by k^2, jerk and tilt rate by k^3; the tilt and the lift
follow from those and gravity). With a :class:`Volume`, every point must lie inside
the box less its margin at the sides and the ceiling; the floor has no margin (a
reference may go down to the floor: take-off, landing, the thesis's 2 cm hover), and a
start above the ceiling is refused (the take-off would climb there).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from groundstation.control.peaks import Peak, Reading, Vehicle, read_curve, slowdown
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
    must stay (tracking error, braking room); the floor (``z[1]``) has none: a
    reference may go down to the floor (take-off and landing start and end there).
    name : what refusals call the box; axis ``x`` is ``{name}_x``.
    """

    x: tuple[float, float]
    y: tuple[float, float]
    z: tuple[float, float]
    margin_m: float = 0.0
    name: str = "volume"

    def allowed(self) -> tuple[FloatArray, FloatArray]:
        """(lowest, highest) NED point (3,) a reference may reach [m]: the box less the
        margin, except at the floor (``z[1]``), which has no margin."""
        m = self.margin_m
        return (np.array([self.x[0] + m, self.y[0] + m, self.z[0] + m]),
                np.array([self.x[1] - m, self.y[1] - m, self.z[1]]))

    def contains(self, point: FloatArray) -> bool:
        """True when ``point`` (3,) NED [m] is in :meth:`allowed`."""
        lo, hi = self.allowed()
        p = np.asarray(point, dtype=float)
        return bool(np.all(lo <= p) and np.all(p <= hi))


@dataclass(frozen=True, slots=True)
class FeasibilityReport:
    """Worst values met along the trajectory, and the limits they broke (if any).

    Speeds [m/s], tilts [rad], rates [rad/s], lifts [N], accelerations [m/s^2], jerks
    [m/s^3]; ``extent_min_m``/``extent_max_m`` the lowest and highest NED coordinates
    reached; jumps as (time [s], size); ``method`` how the curve was read (exact pieces,
    or samples every dt); ``pieces`` how many pieces (or samples) it was read as.
    """

    max_speed_m_s: float
    max_tilt_rad: float
    max_tilt_rate_rad_s: float
    max_yaw_rate_rad_s: float
    min_lift_n: float
    max_lift_n: float
    position_jumps: list[tuple[float, float]] = field(default_factory=list)
    velocity_jumps: list[tuple[float, float]] = field(default_factory=list)
    problems: list[str] = field(default_factory=list)
    max_accel_m_s2: float = 0.0
    max_jerk_m_s3: float = 0.0
    extent_min_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    extent_max_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    method: str = ""
    pieces: int = 0

    @property
    def feasible(self) -> bool:
        """True when no limit is broken."""
        return not self.problems


# ------------------------------------------------------------------ the check
def _horizon(traj: Trajectory, horizon_s: float | None) -> float:
    """How long ``traj`` is checked [s] (see :func:`check_feasibility`)."""
    if horizon_s is None:
        return traj.duration if traj.periodic else traj.duration + 1.0
    if traj.periodic and traj.duration > 0.0:
        return min(horizon_s, traj.duration)
    return horizon_s


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
    every broken limit, one line each (see the module doc).

    horizon_s : how long the trajectory is flown [s] (default: one period, or the
    open trajectory and 1 s after); a periodic one is checked over one period at most.
    dt : the sampling step [s] for a trajectory that cannot describe itself in pieces.
    rate_window_s : the time [s] in which the rate loop makes a tilt step (about its
    rise time, 0.14 s in Fig. 3.8): an acceleration jump counts as its tilt over this
    time (and a sampled trajectory's tilt rate is the change over it).
    Position jumps under 1 cm and velocity jumps under 1 cm/s are ignored.
    With ``raise_on_error=False`` the report is returned with its ``problems``.
    """
    horizon = _horizon(traj, horizon_s)
    if not (math.isfinite(horizon) and horizon >= 0.0):
        raise TrajectoryError(f"trajectory {traj.name!r}: the time it is flown, "
                              f"{horizon!r} s, is not a finite time")
    veh = Vehicle(limits.mass_kg, limits.gravity, limits.induced_inflow)
    reading = read_curve(traj, horizon, veh, _limit_values(limits, volume), dt=dt,
                         rate_window_s=rate_window_s)
    report = _report(reading, limits, volume)
    if report.problems and raise_on_error:
        raise TrajectoryError(
            f"trajectory {traj.name!r} cannot be flown:\n  " + "\n  ".join(report.problems)
        )
    return report


def _limit_values(lim: FlightLimits, volume: Volume | None) -> dict[str, float | None]:
    """Each quantity's limit in the sense it is maximised (minima negated)."""
    out: dict[str, float | None] = {
        "speed": lim.max_speed_m_s, "yaw_rate": lim.max_yaw_rate_rad_s,
        "lift_max": lim.lift_max_n, "lift_min": -lim.lift_min_n, "tilt": lim.max_tilt_rad,
        "tilt_rate": lim.max_rate_rad_s,
    }
    if volume is not None:
        lo, hi = volume.allowed()
        for axis in range(3):
            out[f"{'xyz'[axis]}+"] = float(hi[axis])
            out[f"{'xyz'[axis]}-"] = -float(lo[axis])
    return out


def _report(r: Reading, lim: FlightLimits, volume: Volume | None) -> FeasibilityReport:
    p = r.peaks
    report = FeasibilityReport(
        max_speed_m_s=p["speed"].value, max_tilt_rad=p["tilt"].value,
        max_tilt_rate_rad_s=p["tilt_rate"].value, max_yaw_rate_rad_s=p["yaw_rate"].value,
        min_lift_n=-p["lift_min"].value, max_lift_n=p["lift_max"].value,
        position_jumps=[(t, size) for t, size, _ in r.position_jumps],
        velocity_jumps=[(t, size) for t, size, _ in r.velocity_jumps],
        max_accel_m_s2=p["accel"].value, max_jerk_m_s3=p["jerk"].value,
        extent_min_m=(-p["x-"].value, -p["y-"].value, -p["z-"].value),
        extent_max_m=(p["x+"].value, p["y+"].value, p["z+"].value),
        method=r.method, pieces=r.pieces)
    report.problems.extend(_problems(r, lim))
    if volume is not None:
        report.problems.extend(_volume_problems(r, volume))
    return report


# ------------------------------------------------------------------ refusals
def _m(v: float) -> str:
    """A coordinate [m] to the centimetre, without a minus sign on zero."""
    text = f"{v:.2f}"
    return "0.00" if text == "-0.00" else text


def _at(pk: Peak) -> str:
    """The start of a refusal line: the time (to the centisecond, or three digits below
    10 ms) and the point."""
    x, y, z = pk.position
    when = f"{pk.t:.3g}" if 0.0 < abs(pk.t) < 0.01 else f"{pk.t:.2f}"
    return f"at t = {when} s, ({_m(x)}, {_m(y)}, {_m(z)}) m: "


def _how_many(pk: Peak) -> str:
    if pk.unit == "closed form":
        return " (closed form)"
    return f" (beyond it in {pk.count} of {pk.total} {pk.unit})"


def _slow_text(veh: Vehicle, name: str, pk: Peak, limit: float) -> str:
    if pk.value <= limit:  # no sample beyond it: only the bound between samples is
        return "it comes so close to the limit that it cannot be shown within it: slow it " \
            "down a little"
    k = slowdown(veh, name, pk, limit)
    if k is None:
        return "slowing it down does not help"
    return f"slow it down by k = {k:.2f} (stretch its times by {k:.2f})"


def _shown(pk: Peak, limit: float, fmt: Callable[[float], str], sign: float = 1.0) -> str:
    """The peak's value for a refusal; where only the proven bound breaks the limit (no
    sample does), both."""
    if pk.value <= limit < pk.upper:
        bound = "up to" if sign > 0 else "as little as"
        return (f"{fmt(sign * pk.value + 0.0)} ({bound} {fmt(sign * pk.upper + 0.0)} between "
                "samples)")  # + 0.0: no minus sign on a zero
    return fmt(sign * pk.value + 0.0)


def _problems(r: Reading, lim: FlightLimits) -> list[str]:
    """At most one line per broken limit, at its worst point."""
    n, p, out = lim.names, r.peaks, []
    veh = Vehicle(lim.mass_kg, lim.gravity, lim.induced_inflow)

    def two(v: float) -> str:
        return f"{v:.2f}"

    def deg(v: float) -> str:
        return f"{math.degrees(v):.1f}"

    pk = p["speed"]
    if not pk.upper <= lim.max_speed_m_s:
        out.append(f"{_at(pk)}speed {_shown(pk, lim.max_speed_m_s, two)} m/s exceeds "
                   f"{n.speed} = {lim.max_speed_m_s:.2f} m/s{_how_many(pk)}: "
                   f"{_slow_text(veh, 'speed', pk, lim.max_speed_m_s)}")
    pk = p["tilt"]
    if not pk.upper <= lim.max_tilt_rad:
        out.append(f"{_at(pk)}needs {_shown(pk, lim.max_tilt_rad, deg)} deg tilt, {n.tilt} = "
                   f"{deg(lim.max_tilt_rad)} deg{_how_many(pk)}: "
                   f"{_slow_text(veh, 'tilt', pk, lim.max_tilt_rad)} or smooth the corners "
                   "over a longer time")
    pk = p["tilt_rate"]
    if not pk.upper <= lim.max_rate_rad_s:
        out.append(f"{_at(pk)}needs a tilt rate of {_shown(pk, lim.max_rate_rad_s, two)} "
                   f"rad/s, {n.tilt_rate} = {lim.max_rate_rad_s:.2f} rad/s{_how_many(pk)}: "
                   f"{_slow_text(veh, 'tilt_rate', pk, lim.max_rate_rad_s)} or smooth the "
                   "corners over a longer time")
    pk = p["yaw_rate"]
    if not pk.upper <= lim.max_yaw_rate_rad_s:
        out.append(f"{_at(pk)}needs a yaw rate of {_shown(pk, lim.max_yaw_rate_rad_s, deg)} "
                   f"deg/s, {n.yaw_rate} = {deg(lim.max_yaw_rate_rad_s)} deg/s{_how_many(pk)}: "
                   f"turn more slowly: {_slow_text(veh, 'yaw_rate', pk, lim.max_yaw_rate_rad_s)}")
    lift_range = f"the rotors give {lim.lift_min_n:.2f} to {lim.lift_max_n:.2f} N ({n.lift})"
    pk = p["lift_max"]
    if not pk.upper <= lim.lift_max_n:
        out.append(f"{_at(pk)}needs {_shown(pk, lim.lift_max_n, two)} N of lift, "
                   f"{lift_range}{_how_many(pk)}: "
                   f"{_slow_text(veh, 'lift_max', pk, lim.lift_max_n)}")
    pk = p["lift_min"]
    if not pk.upper <= -lim.lift_min_n:
        out.append(f"{_at(pk)}needs {_shown(pk, -lim.lift_min_n, two, -1.0)} N of lift, "
                   f"{lift_range}{_how_many(pk)}: "
                   f"{_slow_text(veh, 'lift_min', pk, -lim.lift_min_n)}")
    for jumps, limit, what, name, advice in (
            (r.position_jumps, lim.max_position_jump_m, "position", n.position_jump,
             "use a smaller step"),
            (r.velocity_jumps, lim.max_velocity_jump_m_s, "velocity", n.velocity_jump,
             "shape it (min-jerk), set corner smoothing or slow down")):
        over = [j for j in jumps if j[1] > limit]
        if over:
            t, size, (x, y, z) = max(over, key=lambda j: j[1])
            unit = "m" if what == "position" else "m/s"
            out.append(f"at t = {t:.2f} s, ({x:.2f}, {y:.2f}, {z:.2f}) m: {what} jumps by "
                       f"{size:.2f} {unit}, {name} = {limit:.2f} {unit} ({len(over)} such "
                       f"jumps): {advice}")
    return out


VOLUME_TOLERANCE_M = 1e-3
"""How far a proven extent may pass a side of the allowed box and still be inside [m]: the
branch and bound stops refining within a fraction of a millimetre of the true extent
(0.19 mm for a min-jerk corner at rest on the ceiling's margin), so a path that touches a
side exactly has a bound a hair beyond it; 1 mm is far below any margin."""


def _volume_problems(r: Reading, vol: Volume) -> list[str]:
    """One line per side of the box the trajectory leaves, at its worst point."""
    out = []
    margin = vol.margin_m
    less = f" less the {margin:.2f} m margin" if margin > 0.0 else ""
    lo, hi = vol.allowed()
    lo, hi = lo - VOLUME_TOLERANCE_M, hi + VOLUME_TOLERANCE_M
    for axis, (box_lo, box_hi) in enumerate((vol.x, vol.y, vol.z)):
        name = "xyz"[axis]
        box = f"{vol.name}_{name} [{box_lo:.2f}, {box_hi:.2f}]"
        low, high = r.peaks[f"{name}-"], r.peaks[f"{name}+"]
        floor = name == "z"  # z[1] is the floor: no margin there
        if floor and r.start[2] < lo[2]:
            out.append(f"at t = 0.00 s, ({r.start[0]:.2f}, {r.start[1]:.2f}, "
                       f"{r.start[2]:.2f}) m: the start height {-r.start[2]:.2f} m is above "
                       f"the ceiling: z = {r.start[2]:.2f} m is outside {box}{less}")
        elif not -low.upper >= lo[axis]:
            claim = _side(name, low.position[axis], -low.upper, f"{box}{less}",
                          inside=low.position[axis] >= lo[axis])
            out.append(f"{_at(low)}{claim}{_how_many(low)}: move or shrink the path")
        if not high.upper <= hi[axis]:
            claim = _side(name, high.position[axis], high.upper,
                          f"{box}{'' if floor else less}",
                          inside=high.position[axis] <= hi[axis],
                          where="below the floor: " if floor else "")
            out.append(f"{_at(high)}{claim}{_how_many(high)}: move or shrink the path")
    return out


def _side(name: str, value: float, bound: float, box: str, *, inside: bool,
          where: str = "") -> str:
    """A refusal's claim about one side of ``box``: the worst point is outside it, or, with
    no sample beyond it and only the proven bound (a curve too fast or too large to pin
    down between its samples), that it cannot be shown inside."""
    if inside:
        return (f"{name} cannot be shown inside {box} (the worst sample, {value:.2f} m, "
                f"is inside; the proven bound between samples reaches {bound:.2f} m)")
    return f"{name} = {value:.2f} m is {where}outside {box}"
