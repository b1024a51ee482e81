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

from groundstation.control.curve import PieceBounds, PieceSet, Piecewise, Samples
from groundstation.control.trajectory import Trajectory
from groundstation.errors import TrajectoryError
from groundstation.model import QuadrotorParams, ThrustMap
from groundstation.types import FloatArray

_VEHICLE = QuadrotorParams()
"""The vehicle model's defaults (mass, g, inflow)."""

JUMP_POSITION_M = 1e-2
"""Position jumps below this [m] are not reported."""
JUMP_VELOCITY_M_S = 1e-2
"""Velocity jumps below this [m/s] are not reported."""
BUDGET = 400_000
"""Most evaluations the branch and bound spends on one quantity; beyond, the proven bound
decides (a curve so wild is refused rather than checked for ever)."""


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


# ------------------------------------------------------------------ the quantities
@dataclass(frozen=True, slots=True)
class _Vehicle:
    """m [kg], g [m/s^2], I_i [N s/m] of the point-mass inversion."""

    m: float
    g: float
    inflow: float

    def force(self, s: Samples) -> FloatArray:
        """(n, 3) required rotor force F [N]."""
        f = self.m * s.acceleration
        f[:, 2] -= self.m * self.g + self.inflow * s.velocity[:, 2]
        return f

    def force_rate(self, s: Samples) -> FloatArray:
        """(n, 3) its derivative F' [N/s]."""
        f = self.m * s.jerk
        f[:, 2] -= self.inflow * s.acceleration[:, 2]
        return f


def _norm(x: FloatArray) -> FloatArray:
    out: FloatArray = np.linalg.norm(x, axis=1)
    return out


def _tilt(veh: _Vehicle, s: Samples) -> FloatArray:
    f = veh.force(s)
    lift = _norm(f)
    with np.errstate(invalid="ignore", divide="ignore"):
        out: FloatArray = np.arccos(np.clip(-f[:, 2] / lift, -1.0, 1.0))
    return np.where(lift > 0.0, out, math.pi)


def _tilt_rate(veh: _Vehicle, s: Samples) -> FloatArray:
    f = veh.force(s)
    lift2 = np.sum(f * f, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        out: FloatArray = _norm(np.cross(f, veh.force_rate(s))) / lift2
    return np.where(lift2 > 0.0, out, math.inf)


Value = Callable[[_Vehicle, Samples], FloatArray]
Slope = Callable[[_Vehicle, PieceBounds, FloatArray, FloatArray], FloatArray]
"""(vehicle, piece bounds per interval, least lift on the interval [N] (may be <= 0),
interval length [s]) -> bound of |q'| on each interval."""


def _lift_slope(v: _Vehicle, b: PieceBounds) -> FloatArray:
    out: FloatArray = v.m * b.jerk + abs(v.inflow) * b.accel
    return out


def _tilt_slope(v: _Vehicle, b: PieceBounds, fmin: FloatArray, h: FloatArray) -> FloatArray:
    with np.errstate(divide="ignore"):
        out: FloatArray = np.where(fmin > 0.0, _lift_slope(v, b) / fmin, math.inf)
    return out


def _tilt_rate_slope(v: _Vehicle, b: PieceBounds, fmin: FloatArray,
                     h: FloatArray) -> FloatArray:
    fp = _lift_slope(v, b)
    fpp = v.m * b.snap + abs(v.inflow) * b.jerk
    with np.errstate(divide="ignore", invalid="ignore"):
        out: FloatArray = np.where(fmin > 0.0, fpp / fmin + 2.0 * fp * fp / (fmin * fmin),
                                   math.inf)
    return out


@dataclass(frozen=True, slots=True)
class _Quantity:
    """One quantity to maximise: its value, the bound of its rate, its tolerance [its unit]
    and whether its slope needs the least lift."""

    name: str
    value: Value
    slope: Slope
    tol: float
    cap: Callable[[PieceBounds], FloatArray] | None = None
    """A bound of the quantity on the whole piece, if it has one (a coordinate: the
    piece's box), which the interval bounds never exceed."""


def _coordinate(axis: int, sign: float) -> _Quantity:
    return _Quantity(f"{'xyz'[axis]}{'+' if sign > 0 else '-'}",
                     lambda v, s: sign * s.position[:, axis],
                     lambda v, b, f, h: b.speed, 1e-5,
                     lambda b: b.hi[:, axis] if sign > 0 else -b.lo[:, axis])


QUANTITIES: tuple[_Quantity, ...] = (
    *(_coordinate(axis, sign) for axis in range(3) for sign in (1.0, -1.0)),
    _Quantity("speed", lambda v, s: _norm(s.velocity), lambda v, b, f, h: b.accel, 1e-4),
    _Quantity("accel", lambda v, s: _norm(s.acceleration), lambda v, b, f, h: b.jerk, 1e-3),
    _Quantity("jerk", lambda v, s: _norm(s.jerk), lambda v, b, f, h: b.snap, 1e-2),
    _Quantity("yaw_rate", lambda v, s: np.abs(s.yaw_rate), lambda v, b, f, h: b.yaw_accel,
              1e-4),
    _Quantity("lift_max", lambda v, s: _norm(v.force(s)),
              lambda v, b, f, h: _lift_slope(v, b), 1e-3),
    _Quantity("lift_min", lambda v, s: -_norm(v.force(s)),
              lambda v, b, f, h: _lift_slope(v, b), 1e-3),
    _Quantity("tilt", _tilt, _tilt_slope, 1e-5),
    _Quantity("tilt_rate", _tilt_rate, _tilt_rate_slope, 1e-3),
)
_BY_NAME = {q.name: q for q in QUANTITIES}


@dataclass
class _Peak:
    """Where a quantity peaks: its value (taken by the curve), time [s], position (3,)
    NED [m]; ``upper`` the proven bound (= value where nothing is proven); ``count``
    pieces or samples beyond the limit out of ``total``; ``unit`` what they are
    (segments, samples, closed form); ``worst`` samples to size the slow-down from."""

    value: float
    t: float
    position: FloatArray
    upper: float
    count: int = 0
    total: int = 0
    unit: str = "pieces"
    worst: Samples | None = None


# ------------------------------------------------------------------ branch and bound
class _Curve:
    """The pieces of a trajectory over ``[0, horizon]``, flattened: piece k spans
    ``[start[k], end[k]]`` (clipped to the horizon) in set ``owner[k]`` as its piece
    ``local[k]``."""

    def __init__(self, sets: list[PieceSet], horizon: float) -> None:
        self.sets = sets
        start = np.concatenate([s.start for s in sets])
        end = np.concatenate([s.end for s in sets])
        owner = np.concatenate([np.full(len(s.start), k) for k, s in enumerate(sets)])
        local = np.concatenate([np.arange(len(s.start)) for s in sets])
        bounds = PieceBounds.concatenate([s.bounds() for s in sets])
        self.raw = (start, end, owner, local)
        lo, hi = np.maximum(start, 0.0), np.minimum(end, horizon)
        keep = np.flatnonzero((hi > lo) | ((hi == lo) & (horizon == 0.0) & (lo == 0.0)))
        self.start, self.end = lo[keep], hi[keep]
        self.owner, self.local = owner[keep], local[keep]
        self.bounds = bounds.take(keep)

    def __len__(self) -> int:
        return len(self.start)

    def evaluate(self, piece: FloatArray | np.ndarray, t: FloatArray) -> Samples:
        """Piece ``piece[k]`` (index into the clipped pieces) at ``t[k]``."""
        out = Samples.empty(len(t))
        for k, s in enumerate(self.sets):
            rows = np.flatnonzero(self.owner[piece] == k)
            if rows.size:
                out.put(rows, s.evaluate(self.local[piece[rows]], t[rows]))
        return out

    def evaluate_raw(self, index: np.ndarray, t: FloatArray) -> Samples:
        """Unclipped piece ``index[k]`` at ``t[k]`` (for the jumps between pieces)."""
        _, _, owner, local = self.raw
        out = Samples.empty(len(t))
        for k, s in enumerate(self.sets):
            rows = np.flatnonzero(owner[index] == k)
            if rows.size:
                out.put(rows, s.evaluate(local[index[rows]], t[rows]))
        return out


def _earliest_best(values: FloatArray, times: FloatArray, tol: float) -> int:
    """Index of the earliest value within ``tol`` of the largest (ties: first in time)."""
    top = float(np.max(values))
    near = np.flatnonzero(values >= top - tol)
    return int(near[np.argmin(times[near])])


def _maximise(curve: _Curve, grid: Samples, grid_piece: np.ndarray, veh: _Vehicle,
              q: _Quantity, limit: float | None) -> _Peak:
    """The peak of ``q`` over the curve by branch and bound (see the module doc), starting
    from ``grid`` (3 samples per piece: start, middle, end)."""
    values = q.value(veh, grid)
    lift = _norm(veh.force(grid))
    n = len(curve)
    ia = np.concatenate([3 * np.arange(n), 3 * np.arange(n) + 1])
    ib = ia + 1
    a, b, piece = grid.t[ia], grid.t[ib], grid_piece[ia]
    qa, qb, fa, fb = values[ia], values[ib], lift[ia], lift[ib]
    seen_q, seen_t, seen_piece, seen = [values], [grid.t], [grid_piece], [grid]
    best = float(np.max(values))
    proven = -math.inf
    spent = 0
    for _ in range(200):
        h = b - a
        b_int = curve.bounds.take(piece)
        fmin = np.minimum(fa, fb) - _lift_slope(veh, b_int) * h / 2.0
        slope = q.slope(veh, b_int, fmin, h)
        with np.errstate(invalid="ignore"):
            upper = np.where(h > 0.0, 0.5 * (qa + qb) + 0.5 * slope * h, np.maximum(qa, qb))
        upper = np.where(np.isnan(upper), math.inf, upper)
        if q.cap is not None:
            upper = np.minimum(upper, np.maximum(q.cap(b_int), np.maximum(qa, qb)))
        tol = max(q.tol, 1e-4 * abs(best))
        need = upper > best + tol
        if limit is not None and best <= limit:
            need |= upper > limit
        need &= h > 1e-9 * np.maximum(1.0, np.abs(b))
        if np.any(~need):
            proven = max(proven, float(np.max(upper[~need])))
        if not np.any(need) or spent + int(np.count_nonzero(need)) > BUDGET:
            if np.any(need):
                proven = max(proven, float(np.max(upper[need])))
            break
        a, b, piece = a[need], b[need], piece[need]
        qa, qb, fa, fb = qa[need], qb[need], fa[need], fb[need]
        mid = 0.5 * (a + b)
        s = curve.evaluate(piece, mid)
        qm, fm = q.value(veh, s), _norm(veh.force(s))
        spent += len(mid)
        seen_q.append(qm)
        seen_t.append(mid)
        seen_piece.append(piece)
        seen.append(s)
        best = max(best, float(np.max(qm)))
        a, b = np.concatenate([a, mid]), np.concatenate([mid, b])
        piece = np.concatenate([piece, piece])
        qa, qb = np.concatenate([qa, qm]), np.concatenate([qm, qb])
        fa, fb = np.concatenate([fa, fm]), np.concatenate([fm, fb])
    all_q, all_t = np.concatenate(seen_q), np.concatenate(seen_t)
    all_piece = np.concatenate(seen_piece)
    k = _earliest_best(all_q, all_t, 1e-9 * max(1.0, abs(best)))
    chunk = int(np.searchsorted(np.cumsum([len(x) for x in seen_q]), k, side="right"))
    offset = k - int(sum(len(x) for x in seen_q[:chunk]))
    where = seen[chunk].take(np.array([offset]))
    peak = _Peak(value=best, t=float(all_t[k]), position=where.position[0].copy(),
                 upper=max(proven, best), total=n, unit="pieces", worst=where)
    if limit is not None and peak.upper > limit:
        over = np.zeros(n)
        np.maximum.at(over, all_piece, np.where(all_q > limit, 1.0, 0.0))
        peak.count = int(np.count_nonzero(over)) or 1
        peak.worst = _worst_samples(seen, all_q, all_piece, limit)
    return peak


def _worst_samples(seen: list[Samples], q: FloatArray, piece: np.ndarray,
                   limit: float) -> Samples | None:
    """The largest sample of each of the (at most 64) worst pieces beyond ``limit``."""
    every = Samples(*(np.concatenate([getattr(s, name) for s in seen]) for name in
                      ("t", "position", "velocity", "acceleration", "jerk", "yaw",
                       "yaw_rate")))
    over = np.flatnonzero(q > limit)
    if over.size == 0:
        return None
    order = over[np.lexsort((-q[over], piece[over]))]
    first = order[np.concatenate([[True], piece[order][1:] != piece[order][:-1]])]
    first = first[np.argsort(-q[first])][:64]
    return every.take(first)


# ------------------------------------------------------------------ reading the curve
@dataclass
class _Reading:
    """The peaks of one trajectory, however it was read."""

    peaks: dict[str, _Peak]
    position_jumps: list[tuple[float, float, FloatArray]]
    velocity_jumps: list[tuple[float, float, FloatArray]]
    method: str
    pieces: int
    start: FloatArray


def _horizon(traj: Trajectory, horizon_s: float | None) -> float:
    if horizon_s is None:
        return traj.duration if traj.periodic else traj.duration + 1.0
    if traj.periodic and traj.duration > 0.0:
        return min(horizon_s, traj.duration)
    return horizon_s


def _exact(traj: Trajectory, sets: list[PieceSet], horizon: float, veh: _Vehicle,
           limits_by_name: dict[str, float | None], rate_window_s: float) -> _Reading:
    """Branch and bound over the pieces; jumps between them."""
    curve = _Curve(sets, horizon)
    n = len(curve)
    grid_t = np.column_stack([curve.start, 0.5 * (curve.start + curve.end),
                              curve.end]).reshape(-1)
    grid_piece = np.repeat(np.arange(n), 3)
    grid = curve.evaluate(grid_piece, grid_t)
    peaks = {q.name: _maximise(curve, grid, grid_piece, veh, q, limits_by_name.get(q.name))
             for q in QUANTITIES}
    for p in peaks.values():
        p.unit = _unit(sets)
    pos_jumps, vel_jumps = _piece_jumps(curve, horizon, veh, rate_window_s, peaks,
                                        limits_by_name.get("tilt_rate"))
    start = curve.evaluate(np.array([0]), np.array([curve.start[0]])).position[0]
    return _Reading(peaks, pos_jumps, vel_jumps, "exact: rigorous bounds of every piece",
                    n, start)


def _unit(sets: list[PieceSet]) -> str:
    kinds = {s.kind for s in sets} - {"at rest"}
    return "segments" if kinds <= {"polynomial segments"} else "pieces"


def _piece_jumps(curve: _Curve, horizon: float, veh: _Vehicle, rate_window_s: float,
                 peaks: dict[str, _Peak], rate_limit: float | None
                 ) -> tuple[list[tuple[float, float, FloatArray]],
                            list[tuple[float, float, FloatArray]]]:
    """Position and velocity jumps where one piece ends and the next begins (within the
    horizon); an acceleration jump is a tilt step, flown as a tilt rate over
    ``rate_window_s`` (it raises the tilt-rate peak if larger)."""
    start, end, _, _ = curve.raw
    joins = np.flatnonzero((end[:-1] > 0.0) & (end[:-1] <= horizon + 1e-12))
    if joins.size == 0:
        return [], []
    t = end[joins]
    left = curve.evaluate_raw(joins, t)
    right = curve.evaluate_raw(joins + 1, np.maximum(start[joins + 1], t))
    dp = _norm(right.position - left.position)
    dv = _norm(right.velocity - left.velocity)
    fl, fr = veh.force(left), veh.force(right)
    cos = np.sum(fl * fr, axis=1) / np.maximum(_norm(fl) * _norm(fr), 1e-300)
    step = np.arccos(np.clip(cos, -1.0, 1.0)) / rate_window_s
    pos = [(float(t[k]), float(dp[k]), right.position[k]) for k in range(len(t))
           if dp[k] > JUMP_POSITION_M]
    vel = [(float(t[k]), float(dv[k]), right.position[k]) for k in range(len(t))
           if dv[k] > JUMP_VELOCITY_M_S and dp[k] <= JUMP_POSITION_M]
    rate = peaks["tilt_rate"]
    k = int(np.argmax(step))
    if step[k] > rate.value and dv[k] <= JUMP_VELOCITY_M_S and dp[k] <= JUMP_POSITION_M:
        rate.value, rate.upper = float(step[k]), max(rate.upper, float(step[k]))
        rate.t, rate.position = float(t[k]), right.position[k].copy()
        rate.worst = None
        if rate_limit is not None:
            rate.count = max(rate.count, int(np.count_nonzero(step > rate_limit)))
    return pos, vel


def _sampled(traj: Trajectory, horizon: float, dt: float, veh: _Vehicle,
             limits_by_name: dict[str, float | None], rate_window_s: float) -> _Reading:
    """Samples every ``dt`` (a trajectory that cannot describe itself in pieces)."""
    t = np.arange(0.0, horizon + 0.5 * dt, dt)
    sm = Samples.of([traj.sample(float(x)) for x in t])
    f = veh.force(sm)
    lift = _norm(f)
    direction = f / np.where(lift > 0.0, lift, 1.0)[:, None]
    lag = max(1, round(rate_window_s / dt))
    rate = np.zeros(len(t))
    if len(t) > lag:
        turned = _norm(direction[lag:] - direction[:-lag]) / (lag * dt)
        rate[lag // 2: lag // 2 + len(turned)] = turned
    yaw_rate = np.abs(sm.yaw_rate)
    yaw_rate[1:] = np.maximum(yaw_rate[1:], np.abs(np.diff(np.unwrap(sm.yaw))) / dt)
    values = {q.name: q.value(veh, sm) for q in QUANTITIES}
    values["tilt_rate"], values["yaw_rate"] = rate, yaw_rate
    peaks = {}
    for name, v in values.items():
        k = _earliest_best(v, t, 1e-12 * max(1.0, float(np.max(np.abs(v)))))
        limit = limits_by_name.get(name)
        over = np.flatnonzero(v > limit) if limit is not None else np.array([], dtype=int)
        peaks[name] = _Peak(value=float(v[k]), t=float(t[k]), position=sm.position[k].copy(),
                            upper=float(v[k]), count=int(over.size), total=len(t),
                            unit="samples",
                            worst=sm.take(over[np.argsort(-v[over])][:64]) if over.size
                            else sm.take(np.array([k])))
    pos, vel = _sampled_jumps(sm, dt)
    return _Reading(peaks, pos, vel, f"sampled every {dt:g} s (nothing proven between "
                    "samples)", len(t), sm.position[0].copy())


def _sampled_jumps(sm: Samples, dt: float) -> tuple[list[tuple[float, float, FloatArray]],
                                                     list[tuple[float, float, FloatArray]]]:
    """Wherever the position (velocity) changes by more than the trapezoid of its
    derivative predicts (reported at the sample after the jump)."""
    out = []
    for x, dx, tol in ((sm.position, sm.velocity, JUMP_POSITION_M),
                       (sm.velocity, sm.acceleration, JUMP_VELOCITY_M_S)):
        residual = _norm(np.diff(x, axis=0) - 0.5 * (dx[1:] + dx[:-1]) * dt)
        out.append([(float(sm.t[k + 1]), float(residual[k]), sm.position[k + 1].copy())
                    for k in np.flatnonzero(residual > tol)])
    return out[0], out[1]


def _closed_forms(traj: Trajectory, horizon: float, veh: _Vehicle,
                  limits_by_name: dict[str, float | None]) -> _Reading | None:
    """The quantities at the trajectory's closed-form critical times (and its ends): a
    reading if one of them breaks a limit there (a definite refusal), else None."""
    find = getattr(traj, "critical_times", None)
    if find is None:
        return None
    times = [0.0, horizon] + [float(x) for x in find(0.0, horizon)]
    sm = Samples.of([traj.sample(x) for x in times])
    peaks, broken = {}, False
    for q in QUANTITIES:
        v = q.value(veh, sm)
        k = int(np.nanargmax(np.where(np.isfinite(v), v, math.inf)))
        limit = limits_by_name.get(q.name)
        bad = limit is not None and not float(v[k]) <= limit
        broken |= bad
        peaks[q.name] = _Peak(value=float(v[k]), t=float(sm.t[k]),
                              position=sm.position[k].copy(), upper=float(v[k]),
                              count=1 if bad else 0, total=len(times), unit="closed form",
                              worst=sm.take(np.array([k])))
    if not broken:
        return None
    return _Reading(peaks, [], [], "closed form (refused before any sampling)", len(times),
                    sm.position[0].copy())


# ------------------------------------------------------------------ the check
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
    veh = _Vehicle(limits.mass_kg, limits.gravity, limits.induced_inflow)
    bounds = _limit_values(limits, volume)
    reading = _closed_forms(traj, horizon, veh, bounds)
    if reading is None:
        sets = traj.pieces(0.0, horizon + (1e-9 if traj.periodic else 0.0)) \
            if isinstance(traj, Piecewise) else None
        if sets is not None:
            pb = PieceBounds.concatenate([s.bounds() for s in sets])
            if not all(np.all(np.isfinite(getattr(pb, k))) for k in
                       ("lo", "hi", "speed", "accel", "jerk", "snap", "yaw_rate")):
                raise TrajectoryError(f"trajectory {traj.name!r} cannot be flown:\n  its "
                                      "positions or derivatives are not finite numbers")
            reading = _exact(traj, sets, horizon, veh, bounds, rate_window_s)
        else:
            reading = _sampled(traj, horizon, dt, veh, bounds, rate_window_s)
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


def _report(r: _Reading, lim: FlightLimits, volume: Volume | None) -> FeasibilityReport:
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
def _at(pk: _Peak) -> str:
    """The start of a refusal line: the time and the point."""
    x, y, z = pk.position
    return f"at t = {pk.t:.2f} s, ({x:.2f}, {y:.2f}, {z:.2f}) m: "


def _how_many(pk: _Peak) -> str:
    if pk.unit == "closed form":
        return " (closed form)"
    return f" (beyond it in {pk.count} of {pk.total} {pk.unit})"


def _scaled(s: Samples, k: FloatArray) -> Samples:
    """``s`` on a clock slowed by ``k`` (n,): derivatives divided by k, k^2, k^3."""
    c = k[:, None]
    return Samples(s.t, s.position, s.velocity / c, s.acceleration / c ** 2, s.jerk / c ** 3,
                   s.yaw, s.yaw_rate / k)


def _slowdown(veh: _Vehicle, name: str, pk: _Peak, limit: float) -> float | None:
    """The least time-scaling k that brings the worst points within ``limit`` (bisection
    per point, the largest taken, rounded up to 0.01), or None if none does."""
    if pk.worst is None or len(pk.worst) == 0:
        return None
    q = _BY_NAME[name]
    pts = pk.worst
    lo, hi = np.ones(len(pts)), np.full(len(pts), 1e6)
    if np.any(q.value(veh, _scaled(pts, hi)) > limit):
        return None
    for _ in range(80):
        mid = np.sqrt(lo * hi)
        ok = q.value(veh, _scaled(pts, mid)) <= limit
        lo, hi = np.where(ok, lo, mid), np.where(ok, mid, hi)
    return math.ceil(float(np.max(hi)) * 100.0 - 1e-9) / 100.0


def _slow_text(veh: _Vehicle, name: str, pk: _Peak, limit: float) -> str:
    k = _slowdown(veh, name, pk, limit)
    if k is None:
        return "slowing it down does not help"
    return f"slow it down by k = {k:.2f} (stretch its times by {k:.2f})"


def _shown(pk: _Peak, limit: float, fmt: Callable[[float], str], sign: float = 1.0) -> str:
    """The peak's value for a refusal; where only the proven bound breaks the limit (no
    sample does), both."""
    if pk.value <= limit < pk.upper:
        return f"{fmt(sign * pk.value)} (up to {fmt(sign * pk.upper)} between samples)"
    return fmt(sign * pk.value)


def _problems(r: _Reading, lim: FlightLimits) -> list[str]:
    """At most one line per broken limit, at its worst point."""
    n, p, out = lim.names, r.peaks, []
    veh = _Vehicle(lim.mass_kg, lim.gravity, lim.induced_inflow)

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


def _volume_problems(r: _Reading, vol: Volume) -> list[str]:
    """One line per side of the box the trajectory leaves, at its worst point."""
    out = []
    margin = vol.margin_m
    less = f" less the {margin:.2f} m margin" if margin > 0.0 else ""
    lo, hi = vol.allowed()
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
            out.append(f"{_at(low)}{name} = {low.position[axis]:.2f} m is outside {box}{less}"
                       f"{_how_many(low)}: move or shrink the path")
        if not high.upper <= hi[axis]:
            where = "below the floor: " if floor else ""
            out.append(f"{_at(high)}{name} = {high.position[axis]:.2f} m is {where}outside {box}"
                       f"{'' if floor else less}{_how_many(high)}: move or shrink the path")
    return out
