"""Making a trajectory flyable before flight: smooth corners, start and end at rest.

A controller that feeds the reference's acceleration and jerk forward needs a
reference whose acceleration is continuous wherever the vehicle flies it.
:func:`shape_for_flight` (``trajectory.shaping: min-jerk``) makes every
trajectory so:

* :class:`MinJerkPath`: the knots of a :class:`PiecewiseLinear` (square,
  rectangle, waypoints) at the same knot times, each segment flown along its
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

  (``s1, s2, s3`` the derivatives of ``sigma``). The ramp is chosen so the extra
  acceleration ``|f'| s2`` fits in the acceleration the tilt limit leaves.

Set-point steps (:class:`~groundstation.control.trajectory.Hover` with a step)
are left alone: they are the step-response test.
"""

from __future__ import annotations

import math

import numpy as np

from groundstation.control.minjerk import PEAK_RATE, Quintic, smoothstep, smoothstep_integral
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
REST_TOLERANCE = 1e-6
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


class MinJerkPath:
    """Straight segments between knots, each flown with a quintic time-scaling.

    Same arguments as :class:`PiecewiseLinear` (without smoothing); positions NED
    [m], headings [rad] (None: free heading). Before the first knot an open path
    holds ``points[0]`` at rest, after the last ``points[-1]``.
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
        self.name = name
        self.periodic = periodic
        self.duration = float(t[-1])
        self._t, self._p = t, p
        h = np.diff(t)
        delta = np.diff(p, axis=0)
        lengths = np.linalg.norm(delta, axis=1)
        self._dir: FloatArray = np.divide(delta, lengths[:, None], out=np.zeros_like(delta),
                                          where=lengths[:, None] > 0.0)
        v = _knot_speeds(self._dir, lengths / h, periodic)
        self._s = [Quintic.through(lengths[i], h[i], v[i], v[i + 1]) for i in range(len(h))]
        self._yaws, self.free_heading = knot_headings(yaw, t.size)
        turn = np.diff(self._yaws)
        w = _knot_speeds(np.sign(turn)[:, None], np.abs(turn) / h, periodic)
        self._psi = [Quintic.through(turn[i], h[i], math.copysign(w[i], turn[i]),
                                     math.copysign(w[i + 1], turn[i])) for i in range(len(h))]

    def _locate(self, t: float) -> tuple[int, float, float, bool]:
        """(segment, time into it, whole periods, moving): ``moving`` False outside an open
        path's time span (at rest there)."""
        laps = 0.0
        if self.periodic:
            laps = math.floor(t / self.duration)
            t -= laps * self.duration
        moving = self.periodic or 0.0 <= t < self.duration
        t = min(max(t, 0.0), self.duration)
        i = int(np.searchsorted(self._t, t, side="right")) - 1
        i = min(max(i, 0), len(self._t) - 2)
        return i, t - self._t[i], laps, moving

    def sample(self, t: float) -> Reference:
        """Exact position, velocity, acceleration, jerk, heading and heading rate at ``t``."""
        i, tau, laps, moving = self._locate(t)
        s, ds, dds, ddds = self._s[i].at(tau)
        y, dy, _, _ = self._psi[i].at(tau)
        d = self._dir[i]
        yaw = float(self._yaws[i] + y + laps * (self._yaws[-1] - self._yaws[0]))
        if not moving:
            return Reference(t=t, position=self._p[i] + s * d, velocity=np.zeros(3), yaw=yaw)
        return Reference(t=t, position=self._p[i] + s * d, velocity=ds * d,
                         acceleration=dds * d, jerk=ddds * d, yaw=yaw, yaw_rate=float(dy))


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
        if not (span_s > 0.0 and ramp_s > 0.0):
            raise TrajectoryError(f"a time warp needs span_s > 0 and ramp_s > 0, found "
                                  f"{span_s!r}, {ramp_s!r}")
        self.base = base
        self.name = base.name
        self.free_heading = base.free_heading
        self.span_s = float(span_s)
        self.ramp_s = min(float(ramp_s), self.span_s)
        self.duration = self.span_s + self.ramp_s

    def clock(self, t: float) -> tuple[float, float, float, float]:
        """``sigma(t)`` [s] and its first three derivatives."""
        r, end = self.ramp_s, self.duration
        if t <= 0.0:
            return 0.0, 0.0, 0.0, 0.0
        if t >= end:
            return self.span_s, 0.0, 0.0, 0.0
        if t < r:
            s, ds, dds, _ = smoothstep(t / r)
            return r * smoothstep_integral(t / r), s, ds / r, dds / r**2
        if t <= end - r:
            return t - 0.5 * r, 1.0, 0.0, 0.0
        x = (end - t) / r
        s, ds, dds, _ = smoothstep(x)
        return self.span_s - r * smoothstep_integral(x), s, -ds / r, dds / r**2

    def sample(self, t: float) -> Reference:
        """``base`` at ``sigma(t)`` with the chain-rule derivatives."""
        sg, s1, s2, s3 = self.clock(t)
        f = self.base.sample(sg)
        v, a = f.velocity, f.acceleration
        return Reference(t=t, position=f.position, velocity=v * s1,
                         acceleration=a * (s1 * s1) + v * s2,
                         jerk=f.jerk * s1**3 + a * (3.0 * s1 * s2) + v * s3,
                         yaw=f.yaw, yaw_rate=f.yaw_rate * s1)


def ease_ramp_s(base: Trajectory, span_s: float, max_accel: float, *,
                min_ramp_s: float = 1.0, dt: float = 0.02) -> float:
    """Ramp [s] for :class:`TimeWarp` so the warp's extra acceleration ``|f'| sigma''``
    (at most ``PEAK_RATE |f'| / ramp``) fits in 90 % of ``max_accel`` [m/s^2] less the
    base's own largest acceleration; at least ``min_ramp_s``, rounded up to 0.1 s."""
    times = np.arange(0.0, span_s + 0.5 * dt, dt)
    refs = [base.sample(float(t)) for t in times]
    v_max = max(float(np.linalg.norm(r.velocity)) for r in refs)
    a_max = max(float(np.linalg.norm(r.acceleration)) for r in refs)
    budget = 0.9 * max_accel - a_max
    if budget <= 0.1 * max_accel:  # the base alone nearly breaks the limit: the check says so
        budget = 0.1 * max_accel
    ramp = max(min_ramp_s, PEAK_RATE * v_max / budget)
    return math.ceil(ramp * 10.0 - 1e-9) / 10.0


def at_rest(trajectory: Trajectory, t: float) -> bool:
    """True when ``trajectory`` has no speed, acceleration or heading rate at ``t``."""
    r = trajectory.sample(t)
    return bool(np.linalg.norm(r.velocity) < REST_TOLERANCE
                and np.linalg.norm(r.acceleration) < REST_TOLERANCE
                and abs(r.yaw_rate) < REST_TOLERANCE)


def shape_for_flight(trajectory: Trajectory, duration_s: float,
                     max_accel: float) -> tuple[Trajectory, float]:
    """The flyable version of ``trajectory`` flown for ``duration_s`` [s], and how long to
    fly it [s].

    A :class:`PiecewiseLinear` becomes a :class:`MinJerkPath`; then, unless the
    result is at rest at 0 and at ``duration_s``, it is wrapped in a
    :class:`TimeWarp` (ramp from :func:`ease_ramp_s` for ``max_accel`` [m/s^2], the
    horizontal acceleration the tilt limit allows) and flown ``ramp`` longer.
    """
    if isinstance(trajectory, PiecewiseLinear):
        trajectory = min_jerk_path(trajectory)
    if duration_s <= 0.0 or (at_rest(trajectory, 0.0) and at_rest(trajectory, duration_s)):
        return trajectory, duration_s
    warp = TimeWarp(trajectory, duration_s, ease_ramp_s(trajectory, duration_s, max_accel))
    return warp, warp.duration
