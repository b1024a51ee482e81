"""Making a trajectory flyable before flight: smooth corners, start and end at rest.

A controller that feeds the reference's acceleration and jerk forward needs a
reference whose acceleration is continuous wherever the vehicle flies it.
:func:`shape_for_flight` (``trajectory.shaping: min-jerk``) makes every
trajectory so:

* Dense samples (a :class:`PiecewiseLinear` whose knots are closer than the vehicle
  can stop between, :func:`~groundstation.control.splines.dense_rule`): the smooth
  curve fitted through them (:func:`fit_if_dense`,
  :mod:`~groundstation.control.splines`), whatever ``trajectory.shaping`` says: a
  file of samples means that curve.
* :class:`MinJerkPath`: the knots of a :class:`PiecewiseLinear` of corners (square,
  rectangle, sparse waypoints) at the same knot times, each segment flown along its
  straight line with a quintic time-scaling (:class:`~groundstation.control.minjerk.Quintic`):
  the speed is 0 at a knot where the direction changes and continuous through a
  knot where it does not (collinear segments), the acceleration 0 at every knot,
  so the path passes exactly through every corner at its time. Knot headings are
  blended the same way.
* :class:`TimeWarp`: a trajectory that does not start or end at rest (the
  figure-eight; any trajectory cut mid-lap) is flown on a warped clock
  ``sigma(t)`` whose rate rises from 0 to 1 with the quintic smoothstep over a
  ramp, stays 1, and falls back to 0 at the end. In between it is the original,
  ``ramp / 2`` late. Derivatives by the chain rule::

      p' = f' s1,   p'' = f'' s1^2 + f' s2,   p''' = f''' s1^3 + 3 f'' s1 s2 + f' s3

  (``s1, s2, s3`` the derivatives of ``sigma``). The ramp is the shortest (from
  1 s) whose eased start and end ask at most 90 % of the acceleration the tilt limit
  allows. Curves (fitted samples, polynomial files) are eased even with
  ``shaping: none``: a path is never refused for starting or ending in motion.

Every shaped trajectory describes itself in pieces (``pieces``: polynomial segments,
closed forms, the ease by the chain rule; :mod:`~groundstation.control.curve`) for
the feasibility check, and in words (:func:`describe`).

Set-point steps (:class:`~groundstation.control.trajectory.Hover` with a step)
are left alone: they are the step-response test.
"""

from __future__ import annotations

import math

import numpy as np

from groundstation.control.curve import (
    HoldSet,
    IntArray,
    PieceBounds,
    PieceSet,
    Piecewise,
    Samples,
    sample_pieces,
)
from groundstation.control.feasibility import FlightLimits
from groundstation.control.minjerk import (
    PEAK_ACCEL,
    PEAK_JERK,
    PEAK_RATE,
    Quintic,
)
from groundstation.control.polynomial import PiecewisePolynomial
from groundstation.control.splines import FittedPath, dense_rule, fit_samples
from groundstation.control.trajectory import (
    PiecewiseLinear,
    Trajectory,
    check_knots,
    knot_headings,
)
from groundstation.errors import TrajectoryError
from groundstation.types import FloatArray, Reference

COLLINEAR_COS = 1.0 - 1e-9
"""Two segments whose directions' cosine exceeds this are collinear (no stop at the knot)."""
REST_TOLERANCE = 1e-4
"""Speed [m/s], acceleration [m/s^2] and heading rate [rad/s] below which a trajectory is
at rest."""


def _knot_speeds(directions: FloatArray, speeds: FloatArray, periodic: bool) -> FloatArray:
    """(M + 1,) speeds at the knots of M segments: the slower neighbour's average speed
    where two segments of non-zero length go the same way, 0 elsewhere (and at the ends
    of an open path). directions : (M, k) unit vectors (zero for a zero-length segment)."""
    m = len(speeds)
    out = np.zeros(m + 1)
    joins = [(j - 1, j, j) for j in range(1, m)]
    if periodic:
        joins.append((m - 1, 0, 0))
    for before, after, knot in joins:
        same_way = float(directions[before] @ directions[after]) > COLLINEAR_COS
        if same_way:
            out[knot] = min(speeds[before], speeds[after])
    if periodic:
        out[m] = out[0]
    return out


class MinJerkPath(PiecewisePolynomial):
    """Straight segments between knots, each flown with a quintic time-scaling.

    Same arguments as :class:`PiecewiseLinear` (without smoothing); positions NED
    [m], headings [rad] (None: free heading). Before the first knot an open path
    holds ``points[0]`` at rest, after the last ``points[-1]``. Segment ``i`` is the
    polynomial ``p_i + d_i s_i(tau)`` (``d_i`` its unit direction, ``s_i`` the
    :class:`~groundstation.control.minjerk.Quintic`), so the feasibility check reads
    its coefficients.
    """

    def __init__(
        self,
        times: FloatArray | list[float],
        points: FloatArray | list[list[float]],
        *,
        periodic: bool = False,
        yaw: float | FloatArray | None = None,
        name: str = "path",
    ) -> None:
        t, p = check_knots(times, points, periodic)
        h = np.diff(t)
        delta = np.diff(p, axis=0)
        lengths = np.linalg.norm(delta, axis=1)
        direction = np.divide(delta, lengths[:, None], out=np.zeros_like(delta),
                              where=lengths[:, None] > 0.0)
        v = _knot_speeds(direction, lengths / h, periodic)
        yaws, free_heading = knot_headings(yaw, t.size)
        turn = np.diff(yaws)
        w = _knot_speeds(np.sign(turn)[:, None], np.abs(turn) / h, periodic)
        coef = np.zeros((len(h), 6, 4))
        for i in range(len(h)):
            s = Quintic.through(lengths[i], h[i], v[i], v[i + 1])
            psi = Quintic.through(turn[i], h[i], math.copysign(w[i], turn[i]),
                                  math.copysign(w[i + 1], turn[i]))
            for k, c in ((1, s.v0), (3, s.c3), (4, s.c4), (5, s.c5)):
                coef[i, k, :3] = c * direction[i]
            coef[i, [1, 3, 4, 5], 3] = (psi.v0, psi.c3, psi.c4, psi.c5)
        coef[:, 0, :3], coef[:, 0, 3] = p[:-1], yaws[:-1]
        corners = int(np.count_nonzero(v[:-1] == 0.0) if periodic
                      else np.count_nonzero(v[1:-1] == 0.0))
        ends = "a closed loop" if periodic else "from rest to rest"
        super().__init__(t, coef, periodic=periodic, free_heading=free_heading, name=name,
                         description=f"corners: {t.size} knots joined by straight min-jerk "
                         f"segments, {ends}, {corners} corners passed at rest")
        self.times, self.points, self.yaws = t, p, yaws


def min_jerk_path(path: PiecewiseLinear) -> MinJerkPath:
    """``path``'s knots, times and headings as a :class:`MinJerkPath` (its moving-average
    ``smoothing_s``, a blend of the raw corners, does not apply)."""
    yaw = None if path.free_heading else path.yaws
    return MinJerkPath(path.times, path.points, periodic=path.periodic, yaw=yaw, name=path.name)


class TimeWarp:
    """``base`` over its times ``[0, span_s]`` on an eased clock (see the module doc).

    ramp_s : length [s] of the speed-up and of the slow-down (at most ``span_s``).
    The warped trajectory is open, lasts ``span_s + ramp_s`` and is at rest at
    ``base(0)`` before its start and at ``base(span_s)`` after its end.
    """

    periodic = False

    def __init__(self, base: Trajectory, span_s: float, ramp_s: float) -> None:
        if not (math.isfinite(span_s) and math.isfinite(ramp_s) and span_s > 0.0
                and ramp_s > 0.0):
            raise TrajectoryError(f"a time warp needs finite span_s > 0 and ramp_s > 0, "
                                  f"found {span_s!r}, {ramp_s!r}")
        self.base = base
        self.name = base.name
        self.free_heading = base.free_heading
        self.span_s = float(span_s)
        self.ramp_s = min(float(ramp_s), self.span_s)
        self.duration = self.span_s + self.ramp_s

    def clock(self, t: float) -> tuple[float, float, float, float]:
        """``sigma(t)`` [s] and its first three derivatives: :meth:`clocks` at one time, in
        scalars (called every tick; the same operations in the same order)."""
        r, end = self.ramp_s, self.duration
        t = min(max(float(t), 0.0), end)
        if t < r:
            x = t / r
        elif t > end - r:
            x = (end - t) / r
        else:
            return t - 0.5 * r, 1.0, 0.0, 0.0
        x2 = x * x
        y = 1.0 - x
        rate = 30.0 * x2 * (y * y)
        bend = 60.0 * x * (1.0 - x) * (1.0 - 2.0 * x)
        integral = x2 * x2 * (2.5 - 3.0 * x + x2)
        step = x2 * x * (10.0 - 15.0 * x + 6.0 * x2)
        s3 = bend / r ** 2
        if t < r:
            return r * integral, step, rate / r, s3
        return self.span_s - r * integral, step, -rate / r, s3

    def clocks(self, t: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """``sigma`` [s] and its first three derivatives at the times ``t`` (n,): on a
        ramp ``sigma' = S(x)``, ``x`` the fraction of the ramp (the quintic smoothstep),
        so ``sigma'' = S'(x) / r`` and ``sigma''' = S''(x) / r^2``; 1, 0, 0 in between."""
        r, end = self.ramp_s, self.duration
        t = np.clip(np.asarray(t, dtype=float), 0.0, end)
        rising = t < r
        falling = (t > end - r) & ~rising
        ramp = rising | falling
        x = np.where(rising, t / r, np.where(falling, (end - t) / r, 0.5))
        x2 = x * x
        rate = 30.0 * x2 * (1.0 - x) ** 2  # S'(x)
        bend = 60.0 * x * (1.0 - x) * (1.0 - 2.0 * x)  # S''(x)
        integral = x2 * x2 * (2.5 - 3.0 * x + x2)  # int_0^x S(u) du
        step = x2 * x * (10.0 - 15.0 * x + 6.0 * x2)  # S(x)
        sigma = np.where(rising, r * integral,
                         np.where(falling, self.span_s - r * integral, t - 0.5 * r))
        s1 = np.where(ramp, step, 1.0)
        s2 = np.where(rising, rate / r, np.where(falling, -rate / r, 0.0))
        s3 = np.where(ramp, bend / r ** 2, 0.0)
        return sigma, s1, s2, s3

    def sample(self, t: float) -> Reference:
        """``base`` at ``sigma(t)`` with the chain-rule derivatives."""
        sg, s1, s2, s3 = self.clock(t)
        f = self.base.sample(sg)
        v, a = f.velocity, f.acceleration
        return Reference(t=t, position=f.position, velocity=v * s1,
                         acceleration=a * (s1 * s1) + v * s2,
                         jerk=f.jerk * s1**3 + a * (3.0 * s1 * s2) + v * s3,
                         yaw=f.yaw, yaw_rate=f.yaw_rate * s1)

    def warped(self, t: FloatArray, base: Samples) -> Samples:
        """Samples ``base`` of the base at ``sigma(t)`` as the warp's samples at ``t``."""
        _, s1, s2, s3 = self.clocks(t)
        v, a, j = base.velocity, base.acceleration, base.jerk
        c1, c2, c3 = s1[:, None], s2[:, None], s3[:, None]
        return Samples(np.asarray(t, dtype=float).copy(), base.position, v * c1,
                       a * c1 * c1 + v * c2, j * c1 ** 3 + a * (3.0 * c1 * c2) + v * c3,
                       base.yaw, base.yaw_rate * s1)

    def inverse(self, sigma: FloatArray) -> FloatArray:
        """The times ``t`` (n,) at which ``sigma(t)`` equals ``sigma`` (n,) [s] (bisection:
        sigma is strictly increasing on the flight)."""
        sigma = np.clip(np.asarray(sigma, dtype=float), 0.0, self.span_s)
        lo, hi = np.zeros_like(sigma), np.full_like(sigma, self.duration)
        for _ in range(64):
            mid = 0.5 * (lo + hi)
            below = self.clocks(mid)[0] < sigma
            lo, hi = np.where(below, mid, lo), np.where(below, hi, mid)
        return 0.5 * (lo + hi)

    def critical_times(self, t0: float, t1: float) -> list[float]:
        """The base's critical times on the warped clock: the warp visits the same points,
        so each is a time a peak position is reached (and, between the ramps, a peak
        speed or acceleration)."""
        find = getattr(self.base, "critical_times", None)
        if find is None:
            return []
        times = np.array([float(x) for x in find(0.0, self.span_s)])
        if times.size == 0:
            return []
        return [float(x) for x in self.inverse(times) if t0 <= x <= t1]

    def pieces(self, t0: float, t1: float) -> list[PieceSet] | None:
        """The base's pieces on the eased clock (:class:`_WarpSet`), at rest before the
        start and after the end; None if the base has no pieces."""
        base_sets = self.base.pieces(0.0, self.span_s) if isinstance(self.base, Piecewise) \
            else None
        if base_sets is None:
            return None
        out: list[PieceSet] = []
        if t0 < 0.0:
            first = self.base.sample(0.0)
            out.append(HoldSet(t0, 0.0, first.position, first.yaw))
        for bs in base_sets:
            lo = np.maximum(bs.start, 0.0)
            hi = np.minimum(bs.end, self.span_s)
            keep = np.flatnonzero(hi > lo)
            if keep.size == 0:
                continue
            edges = self.inverse(np.concatenate([lo[keep], hi[keep]]))
            out.append(_WarpSet(self, bs, keep, edges[: keep.size], edges[keep.size:]))
        if t1 > self.duration:
            last = self.base.sample(self.span_s)
            out.append(HoldSet(self.duration, t1, last.position, last.yaw))
        return out

    def sample_many(self, t: FloatArray) -> Samples:
        """:meth:`sample` at many times ``t`` (n,) [s] at once."""
        t = np.asarray(t, dtype=float)
        sets = self.pieces(min(0.0, float(np.min(t, initial=0.0))),
                           max(float(np.max(t, initial=0.0)), self.duration))
        if sets is None:
            return Samples.of([self.sample(float(x)) for x in t])
        return sample_pieces(sets, t)


class _WarpSet:
    """Pieces of a base trajectory flown on a :class:`TimeWarp`'s clock."""

    kind = "eased"

    def __init__(self, warp: TimeWarp, base: PieceSet, index: IntArray, start: FloatArray,
                 end: FloatArray) -> None:
        self.warp, self.base, self.index = warp, base, index
        self.start, self.end = start, end

    def evaluate(self, index: IntArray, t: FloatArray) -> Samples:
        """The base piece at ``sigma(t)``, by the chain rule."""
        sigma = self.warp.clocks(t)[0]
        return self.warp.warped(t, self.base.evaluate(self.index[index], sigma))

    def bounds(self) -> PieceBounds:
        """The chain rule on the base's bounds V, A, J, S (speed to snap), with
        ``|s1| <= 1`` and, on a ramp of length r, ``|s2| <= (15/8) / r``,
        ``|s3| <= (10 / sqrt 3) / r^2``, ``|s4| <= 60 / r^3`` (the smoothstep's peaks;
        0 between the ramps): ``|p''| <= A + V s2``, ``|p'''| <= J + 3 A s2 + V s3``,
        ``|p''''| <= S + 6 J s2 + A (3 s2^2 + 4 s3) + V s4``."""
        b = self.base.bounds().take(self.index)
        r, w = self.warp.ramp_s, self.warp
        eased = (self.start < r) | (self.end > w.duration - r)
        s2 = np.where(eased, PEAK_RATE / r, 0.0)
        s3 = np.where(eased, PEAK_ACCEL / r ** 2, 0.0)
        s4 = np.where(eased, PEAK_JERK / r ** 3, 0.0)
        return PieceBounds(lo=b.lo, hi=b.hi, speed=b.speed, accel=b.accel + b.speed * s2,
                           jerk=b.jerk + 3.0 * b.accel * s2 + b.speed * s3,
                           snap=(b.snap + 6.0 * b.jerk * s2 + b.accel * (3.0 * s2 ** 2 + 4.0 * s3)
                                 + b.speed * s4),
                           yaw_rate=b.yaw_rate, yaw_accel=b.yaw_accel + b.yaw_rate * s2)


def ease_ramp_s(base: Trajectory, span_s: float, max_accel: float, *,
                min_ramp_s: float = 1.0, dt: float = 0.02) -> float:
    """Ramp [s] for :class:`TimeWarp`: the shortest of ``min_ramp_s``, then 25 % longer
    each, whose eased start and end ask at most 90 % of ``max_accel`` [m/s^2] (or the
    base's own largest acceleration, if that is more), judged on 200 samples of each
    ramp; rounded up to 0.1 s. If none does, the ramp that keeps the warp's extra
    acceleration ``|f'| sigma''`` (at most ``PEAK_RATE |f'| / ramp``) within 90 % of
    ``max_accel`` less the base's largest acceleration (a tenth of ``max_accel`` at
    least). At most ``span_s``. The feasibility check then proves the result.

    The base's largest speed and acceleration are the bounds of its pieces when it has
    them, else the largest of samples every ``dt`` (at most 100 001)."""
    sets = base.pieces(0.0, span_s) if isinstance(base, Piecewise) else None
    if sets is not None:
        bounds = PieceBounds.concatenate([ps.bounds() for ps in sets])
        v_max, a_max = float(np.max(bounds.speed)), float(np.max(bounds.accel))
    else:
        times = np.linspace(0.0, span_s, min(100_001, max(2, int(span_s / dt) + 1)))
        refs = [base.sample(float(t)) for t in times]
        v_max = max(float(np.linalg.norm(r.velocity)) for r in refs)
        a_max = max(float(np.linalg.norm(r.acceleration)) for r in refs)
    budget = max(0.9 * max_accel - a_max, 0.1 * max_accel)
    longest = max(min_ramp_s, PEAK_RATE * v_max / budget)
    if not math.isfinite(longest):
        raise TrajectoryError(f"trajectory {base.name!r}: its speed or acceleration is not "
                              "finite")
    target = max(0.9 * max_accel, a_max)
    ramp = min_ramp_s
    while ramp < min(longest, span_s):
        warp = TimeWarp(base, span_s, ramp)
        r = warp.ramp_s
        t = np.concatenate([np.linspace(0.0, r, 200), np.linspace(span_s, span_s + r, 200)])
        sampled = warp.sample_many(t)
        if float(np.max(np.linalg.norm(sampled.acceleration, axis=1))) <= target:
            break
        ramp *= 1.25
    ramp = min(ramp, longest)
    return math.ceil(ramp * 10.0 - 1e-9) / 10.0


def at_rest(trajectory: Trajectory, t: float) -> bool:
    """True when ``trajectory`` has no speed, acceleration or heading rate just before
    ``t`` (the left limit: an open path holds its end at rest from its end on)."""
    r = trajectory.sample(math.nextafter(t, -math.inf) if t > 0.0 else t)
    return bool(np.linalg.norm(r.velocity) < REST_TOLERANCE
                and np.linalg.norm(r.acceleration) < REST_TOLERANCE
                and abs(r.yaw_rate) < REST_TOLERANCE)


def fit_if_dense(path: PiecewiseLinear, limits: FlightLimits) -> FittedPath | None:
    """``path``'s knots fitted as a smooth curve if they are dense samples (see
    :func:`~groundstation.control.splines.dense_rule`), None if they are corners."""
    if path.periodic:
        return None
    rule = dense_rule(path.times, path.points, path.yaws, max_speed=limits.max_speed_m_s,
                      max_accel=limits.max_accel_m_s2,
                      max_yaw_rate=limits.max_yaw_rate_rad_s)
    if not rule.dense:
        return None
    return fit_samples(path.times, path.points, path.yaws, rule=rule,
                       free_heading=path.free_heading, name=path.name)


def shape_for_flight(trajectory: Trajectory, duration_s: float, max_accel: float, *,
                     limits: FlightLimits | None = None,
                     shaping: str = "min-jerk") -> tuple[Trajectory, float]:
    """The flyable version of ``trajectory`` flown for ``duration_s`` [s], and how long to
    fly it [s].

    A :class:`PiecewiseLinear` of dense samples (for ``limits``; by default those of
    :class:`FlightLimits` with ``max_accel``) becomes the smooth curve fitted through
    them (:func:`fit_if_dense`), one of corners a :class:`MinJerkPath` (with
    ``shaping="min-jerk"``; ``"none"`` keeps the raw corners). Then, unless the result
    is at rest at 0 and at ``duration_s``, it is wrapped in a :class:`TimeWarp` (ramp
    from :func:`ease_ramp_s` for ``max_accel`` [m/s^2], the horizontal acceleration the
    tilt limit allows) and flown ``ramp`` longer. With ``shaping="none"`` only curves
    (fitted samples, polynomial files) are eased: the thesis's shapes stay raw.
    """
    if limits is None:
        limits = FlightLimits(max_tilt_rad=math.atan(max_accel / FlightLimits().gravity))
    if isinstance(trajectory, PiecewiseLinear):
        fitted = fit_if_dense(trajectory, limits)
        if fitted is not None:
            trajectory = fitted
        elif shaping == "min-jerk":
            trajectory = min_jerk_path(trajectory)
    curve = isinstance(trajectory, PiecewisePolynomial) and not isinstance(trajectory,
                                                                            MinJerkPath)
    if shaping != "min-jerk" and not curve:
        return trajectory, duration_s
    if duration_s <= 0.0 or (at_rest(trajectory, 0.0) and at_rest(trajectory, duration_s)):
        return trajectory, duration_s
    warp = TimeWarp(trajectory, duration_s, ease_ramp_s(trajectory, duration_s, max_accel))
    return warp, warp.duration


def describe(trajectory: Trajectory) -> str:
    """One line saying what ``trajectory`` is: fitted samples (with the noise and the
    residual), corners, polynomial segments, a closed form; eased or not."""
    base = trajectory.base if isinstance(trajectory, TimeWarp) else trajectory
    what = getattr(base, "description", "") or f"{type(base).__name__} {base.name!r}"
    if isinstance(trajectory, TimeWarp):
        what += (f"; eased in and out over {trajectory.ramp_s:.1f} s (it starts or ends "
                 "moving)")
    return what
