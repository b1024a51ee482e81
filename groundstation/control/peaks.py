"""The peaks of a flown curve, proven: branch and bound over its pieces.

What :mod:`groundstation.control.feasibility` compares with the limits (its module doc
describes the method): the quantities of the point-mass inversion (:data:`QUANTITIES`:
each coordinate both ways, speed, acceleration, jerk, heading rate, the lift both ways,
tilt and tilt rate), each with the bound of its rate on a piece from the piece's
:class:`~groundstation.control.curve.PieceBounds`; :func:`read_curve` finds where each
peaks (:class:`Peak`: the value the curve takes, the bound proven, where, how many
pieces exceed the limit); :func:`slowdown` the time-scaling that brings the worst points
within a limit. Units SI (m, s, N, rad); positions NED.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from groundstation.control.curve import PieceBounds, PieceSet, Piecewise, Samples
from groundstation.control.trajectory import Trajectory
from groundstation.errors import TrajectoryError
from groundstation.types import FloatArray

JUMP_POSITION_M = 1e-2
"""Position jumps below this [m] are not reported."""
JUMP_VELOCITY_M_S = 1e-2
"""Velocity jumps below this [m/s] are not reported."""
BUDGET = 400_000
"""Most evaluations the branch and bound spends on one quantity; beyond, the proven bound
decides (a curve so wild is refused rather than checked for ever)."""


# ------------------------------------------------------------------ the quantities
@dataclass(frozen=True, slots=True)
class Vehicle:
    """m [kg], g [m/s^2], I_i [N s/m] of the point-mass inversion (build from
    :class:`~groundstation.control.feasibility.FlightLimits` fields)."""

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


def norm(x: FloatArray) -> FloatArray:
    """(n,) Euclidean norms of the rows of ``x`` (n, d)."""
    out: FloatArray = np.linalg.norm(x, axis=1)
    return out


def tilt_angle(veh: Vehicle, s: Samples) -> FloatArray:
    """(n,) tilt [rad] the references ``s`` need: the angle of ``-F`` from the vertical."""
    f = veh.force(s)
    lift = norm(f)
    with np.errstate(invalid="ignore", divide="ignore"):
        out: FloatArray = np.arccos(np.clip(-f[:, 2] / lift, -1.0, 1.0))
    return np.where(lift > 0.0, out, math.pi)


def tilt_rate_of(veh: Vehicle, s: Samples) -> FloatArray:
    """(n,) rate [rad/s] at which the thrust direction turns, ``|F x F'| / |F|^2``."""
    f = veh.force(s)
    lift2 = np.sum(f * f, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        out: FloatArray = norm(np.cross(f, veh.force_rate(s))) / lift2
    return np.where(lift2 > 0.0, out, math.inf)


Value = Callable[[Vehicle, Samples], FloatArray]
Slope = Callable[[Vehicle, PieceBounds, FloatArray, FloatArray], FloatArray]
"""(vehicle, piece bounds per interval, least lift on the interval [N] (may be <= 0),
interval length [s]) -> bound of |q'| on each interval."""


def _lift_slope(v: Vehicle, b: PieceBounds) -> FloatArray:
    out: FloatArray = v.m * b.jerk + abs(v.inflow) * b.accel
    return out


def _tilt_slope(v: Vehicle, b: PieceBounds, fmin: FloatArray, h: FloatArray) -> FloatArray:
    with np.errstate(divide="ignore"):
        out: FloatArray = np.where(fmin > 0.0, _lift_slope(v, b) / fmin, math.inf)
    return out


def _tilt_rate_slope(v: Vehicle, b: PieceBounds, fmin: FloatArray,
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
    most: float = math.inf
    """The largest value the quantity can take at all (minus a norm: 0; a tilt: pi)."""


def _coordinate(axis: int, sign: float) -> _Quantity:
    return _Quantity(f"{'xyz'[axis]}{'+' if sign > 0 else '-'}",
                     lambda v, s: sign * s.position[:, axis],
                     lambda v, b, f, h: b.speed, 1e-5,
                     lambda b: b.hi[:, axis] if sign > 0 else -b.lo[:, axis])


QUANTITIES: tuple[_Quantity, ...] = (
    *(_coordinate(axis, sign) for axis in range(3) for sign in (1.0, -1.0)),
    _Quantity("speed", lambda v, s: norm(s.velocity), lambda v, b, f, h: b.accel, 1e-4),
    _Quantity("accel", lambda v, s: norm(s.acceleration), lambda v, b, f, h: b.jerk, 1e-3),
    _Quantity("jerk", lambda v, s: norm(s.jerk), lambda v, b, f, h: b.snap, 1e-2),
    _Quantity("yaw_rate", lambda v, s: np.abs(s.yaw_rate), lambda v, b, f, h: b.yaw_accel,
              1e-4),
    _Quantity("lift_max", lambda v, s: norm(v.force(s)),
              lambda v, b, f, h: _lift_slope(v, b), 1e-3),
    _Quantity("lift_min", lambda v, s: -norm(v.force(s)),
              lambda v, b, f, h: _lift_slope(v, b), 1e-3, most=0.0),
    _Quantity("tilt", tilt_angle, _tilt_slope, 1e-5, most=math.pi),
    _Quantity("tilt_rate", tilt_rate_of, _tilt_rate_slope, 1e-3),
)
_BY_NAME = {q.name: q for q in QUANTITIES}


@dataclass
class Peak:
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


def _upper(curve: _Curve, veh: Vehicle, q: _Quantity, a: FloatArray, b: FloatArray,
           ends: tuple[FloatArray, FloatArray, FloatArray, FloatArray],
           piece: np.ndarray) -> FloatArray:
    """Proven bound of ``q`` on each interval ``[a, b]`` of ``piece`` from its values
    ``qa, qb`` and lifts ``fa, fb`` at the ends (``ends``): ``(qa + qb + L h) / 2``,
    within the piece's cap and the quantity's most; inf where nothing is proven."""
    qa, qb, fa, fb = ends
    h = b - a
    bounds = curve.bounds.take(piece)
    fmin = np.minimum(fa, fb) - _lift_slope(veh, bounds) * h / 2.0
    with np.errstate(invalid="ignore"):
        upper = np.where(h > 0.0, 0.5 * (qa + qb) + 0.5 * q.slope(veh, bounds, fmin, h) * h,
                         np.maximum(qa, qb))
    upper = np.where(np.isnan(upper), math.inf, upper)
    if q.cap is not None:
        upper = np.minimum(upper, np.maximum(q.cap(bounds), np.maximum(qa, qb)))
    out: FloatArray = np.minimum(upper, q.most)
    return out


def _maximise(curve: _Curve, grid: Samples, grid_piece: np.ndarray, veh: Vehicle,
              q: _Quantity, limit: float | None) -> Peak:
    """The peak of ``q`` over the curve by branch and bound (see the module doc), starting
    from ``grid`` (3 samples per piece: start, middle, end)."""
    values = q.value(veh, grid)
    lift = norm(veh.force(grid))
    n = len(curve)
    ia = np.concatenate([3 * np.arange(n), 3 * np.arange(n) + 1])
    ib = ia + 1
    a, b, piece = grid.t[ia], grid.t[ib], grid_piece[ia]
    qa, qb, fa, fb = values[ia], values[ib], lift[ia], lift[ib]
    seen_q, seen_t, seen_piece, seen = [values], [grid.t], [grid_piece], [grid]
    best = float(np.max(values))
    proven = -math.inf
    spent = 0
    while True:
        upper = _upper(curve, veh, q, a, b, (qa, qb, fa, fb), piece)
        tol = max(q.tol, 1e-4 * abs(best))
        need = upper > best + tol
        if limit is not None and best <= limit:
            need |= upper > limit
        # an interval narrower than a nanosecond (relative) is not split: its bound stands
        need &= (b - a) > 1e-9 * np.maximum(1.0, np.abs(b))
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
        qm, fm = q.value(veh, s), norm(veh.force(s))
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
    peak = Peak(value=best, t=float(all_t[k]), position=where.position[0].copy(),
                upper=max(proven, best), total=n, unit="pieces", worst=where)
    if limit is not None and peak.upper > limit:
        over = np.zeros(n)
        np.maximum.at(over, all_piece, np.where(all_q > limit, 1.0, 0.0))
        peak.count = int(np.count_nonzero(over)) or 1
        peak.worst = _worst_samples(seen, all_q, all_piece, limit) or where
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
class Reading:
    """The peaks of one trajectory, however it was read."""

    peaks: dict[str, Peak]
    position_jumps: list[tuple[float, float, FloatArray]]
    velocity_jumps: list[tuple[float, float, FloatArray]]
    method: str
    pieces: int
    start: FloatArray


def _exact(traj: Trajectory, sets: list[PieceSet], horizon: float, veh: Vehicle,
           limits_by_name: dict[str, float | None], rate_window_s: float) -> Reading:
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
    return Reading(peaks, pos_jumps, vel_jumps, "exact: rigorous bounds of every piece",
                    n, start)


def _unit(sets: list[PieceSet]) -> str:
    kinds = {s.kind for s in sets} - {"at rest"}
    return "segments" if kinds <= {"polynomial segments"} else "pieces"


def _piece_jumps(curve: _Curve, horizon: float, veh: Vehicle, rate_window_s: float,
                 peaks: dict[str, Peak], rate_limit: float | None
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
    dp = norm(right.position - left.position)
    dv = norm(right.velocity - left.velocity)
    fl, fr = veh.force(left), veh.force(right)
    cos = np.sum(fl * fr, axis=1) / np.maximum(norm(fl) * norm(fr), 1e-300)
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


def _sampled(traj: Trajectory, horizon: float, dt: float, veh: Vehicle,
             limits_by_name: dict[str, float | None], rate_window_s: float) -> Reading:
    """Samples every ``dt`` (a trajectory that cannot describe itself in pieces)."""
    t = np.arange(0.0, horizon + 0.5 * dt, dt)
    sm = Samples.of([traj.sample(float(x)) for x in t])
    f = veh.force(sm)
    lift = norm(f)
    direction = f / np.where(lift > 0.0, lift, 1.0)[:, None]
    lag = max(1, round(rate_window_s / dt))
    rate = np.zeros(len(t))
    if len(t) > lag:
        turned = norm(direction[lag:] - direction[:-lag]) / (lag * dt)
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
        peaks[name] = Peak(value=float(v[k]), t=float(t[k]), position=sm.position[k].copy(),
                            upper=float(v[k]), count=int(over.size), total=len(t),
                            unit="samples",
                            worst=sm.take(over[np.argsort(-v[over])][:64]) if over.size
                            else sm.take(np.array([k])))
    pos, vel = _sampled_jumps(sm, dt)
    return Reading(peaks, pos, vel, f"sampled every {dt:g} s (nothing proven between "
                    "samples)", len(t), sm.position[0].copy())


def _sampled_jumps(sm: Samples, dt: float) -> tuple[list[tuple[float, float, FloatArray]],
                                                     list[tuple[float, float, FloatArray]]]:
    """Wherever the position (velocity) changes by more than the trapezoid of its
    derivative predicts (reported at the sample after the jump)."""
    out = []
    for x, dx, tol in ((sm.position, sm.velocity, JUMP_POSITION_M),
                       (sm.velocity, sm.acceleration, JUMP_VELOCITY_M_S)):
        residual = norm(np.diff(x, axis=0) - 0.5 * (dx[1:] + dx[:-1]) * dt)
        out.append([(float(sm.t[k + 1]), float(residual[k]), sm.position[k + 1].copy())
                    for k in np.flatnonzero(residual > tol)])
    return out[0], out[1]


def _closed_forms(traj: Trajectory, horizon: float, veh: Vehicle,
                  limits_by_name: dict[str, float | None]) -> Reading | None:
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
        peaks[q.name] = Peak(value=float(v[k]), t=float(sm.t[k]),
                              position=sm.position[k].copy(), upper=float(v[k]),
                              count=1 if bad else 0, total=len(times), unit="closed form",
                              worst=sm.take(np.array([k])))
    if not broken:
        return None
    return Reading(peaks, [], [], "closed form (refused before any sampling)", len(times),
                    sm.position[0].copy())


def scaled(s: Samples, k: FloatArray) -> Samples:
    """``s`` on a clock slowed by ``k`` (n,): derivatives divided by k, k^2, k^3."""
    c = k[:, None]
    return Samples(s.t, s.position, s.velocity / c, s.acceleration / c ** 2, s.jerk / c ** 3,
                   s.yaw, s.yaw_rate / k)


def slowdown(veh: Vehicle, name: str, pk: Peak, limit: float) -> float | None:
    """The least time-scaling k that brings the worst points within ``limit`` (bisection
    per point, the largest taken, rounded up to 0.01), or None if none does."""
    if pk.worst is None or len(pk.worst) == 0:
        return None
    q = _BY_NAME[name]
    pts = pk.worst
    if name in ("speed", "yaw_rate"):  # homogeneous of degree -1 in k: exact
        k = float(np.max(q.value(veh, pts))) / limit
        return math.ceil(k * 100.0 - 1e-9) / 100.0
    lo, hi = np.ones(len(pts)), np.full(len(pts), 1e12)
    if np.any(q.value(veh, scaled(pts, hi)) > limit):
        return None
    for _ in range(100):
        mid = np.sqrt(lo * hi)
        ok = q.value(veh, scaled(pts, mid)) <= limit
        lo, hi = np.where(ok, lo, mid), np.where(ok, mid, hi)
    return math.ceil(float(np.max(hi)) * 100.0 - 1e-9) / 100.0



def read_curve(traj: Trajectory, horizon: float, veh: Vehicle,
               limits: dict[str, float | None], *, dt: float = 0.01,
               rate_window_s: float = 0.1) -> Reading:
    """The peaks of ``traj`` over ``[0, horizon]`` [s] (see
    :mod:`groundstation.control.feasibility`): from its closed forms if a limit in
    ``limits`` (by quantity name, minima negated, None for none) breaks there, else by
    branch and bound over its pieces, else from samples every ``dt``. TrajectoryError if
    its pieces' bounds are not finite."""
    reading = _closed_forms(traj, horizon, veh, limits)
    if reading is not None:
        return reading
    sets = traj.pieces(0.0, horizon + (1e-9 if traj.periodic else 0.0)) \
        if isinstance(traj, Piecewise) else None
    if sets is None:
        return _sampled(traj, horizon, dt, veh, limits, rate_window_s)
    pb = PieceBounds.concatenate([s.bounds() for s in sets])
    if not all(np.all(np.isfinite(getattr(pb, k))) for k in
               ("lo", "hi", "speed", "accel", "jerk", "snap", "yaw_rate")):
        raise TrajectoryError(f"trajectory {traj.name!r} cannot be flown:\n  its "
                              "positions or derivatives are not finite numbers")
    return _exact(traj, sets, horizon, veh, limits, rate_window_s)
