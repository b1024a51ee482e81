"""Trajectory primitives: a reference position and its derivatives at any time.

Every trajectory is a pure function of the time since it started; it holds no
clock and no state, so the loop, the tests and the feasibility check can sample
it anywhere (:class:`Trajectory` protocol). Positions are NED [m] (hovering 1 m
above the floor is ``z = -1``), velocities [m/s], accelerations [m/s^2], jerks
[m/s^3], headings [rad] and heading rates [rad/s]; every derivative is exact.

Heading: a trajectory built with ``yaw=None`` has a *free heading*
(``free_heading`` True): its yaw (0 unless it turns) is relative to the heading
the vehicle has at take-off, which the mission adds. A number is an absolute
heading. Headings are continuous (unwrapped): they may pass +-pi.

The shapes of thesis Ch. 11 (and the heading turn) are built from these primitives:

* :class:`Hover`: a fixed point, optionally with a step of the set point.
* :class:`PiecewiseLinear`: straight segments at constant speed between knots
  (square, rectangle, waypoints), open or periodic, with optional corner
  smoothing by a moving-average window of ``smoothing_s`` seconds. The
  moving average of a piecewise-linear path is computed exactly from its
  piecewise-quadratic antiderivative: the smoothed velocity is
  ``(p(t + T/2) - p(t - T/2)) / T`` and the acceleration the same difference of
  velocities, so the corners become parabolic blends with a bounded
  acceleration ``|Δv| / T`` while the straight parts are untouched.
* :class:`FigureEight`: a smooth lemniscate of Gerono with analytic derivatives.
* :class:`YawTurn`: hold a point while the heading turns (min-jerk profile).

:mod:`groundstation.control.shaping` makes any of them flyable before flight.
"""

from __future__ import annotations

import math
from typing import Protocol, runtime_checkable

import numpy as np

from groundstation.control.curve import (
    HoldSet,
    IntArray,
    PieceBounds,
    PieceSet,
    PolySet,
    Samples,
)
from groundstation.control.minjerk import smoothstep
from groundstation.errors import TrajectoryError
from groundstation.types import FloatArray, Reference

_ZERO3 = np.zeros(3)


@runtime_checkable
class Trajectory(Protocol):
    """A reference that can be sampled at any time since its start.

    ``duration`` [s] is the length of the interesting part: one lap for a
    periodic trajectory (it repeats afterwards), the end of the last segment
    for an open one (it holds its last point afterwards), ``0`` for a hover.
    ``free_heading``: True when the yaw is relative to the heading at take-off
    (the mission adds that heading), False when it is absolute.
    """

    name: str
    duration: float
    periodic: bool
    free_heading: bool

    def sample(self, t: float) -> Reference:
        """The reference at ``t`` seconds after the start (NED, SI units)."""
        ...


def _vec3(value: FloatArray | list[float] | tuple[float, ...], what: str) -> FloatArray:
    arr = np.asarray(value, dtype=float).reshape(-1)
    if arr.shape != (3,) or not np.all(np.isfinite(arr)):
        raise TrajectoryError(f"{what} must be 3 finite numbers (NED, m), found {value!r}")
    return arr


def _heading(yaw: float | None) -> tuple[float, bool]:
    """(yaw [rad], free_heading) of a ``yaw`` argument (None = free heading, yaw 0)."""
    if yaw is None:
        return 0.0, True
    if not math.isfinite(yaw):
        raise TrajectoryError(f"yaw must be finite, found {yaw!r}")
    return float(yaw), False


class Hover:
    """Hold ``point``; optionally step by ``step`` at ``step_time`` (a set-point change).

    point : (3,) NED [m]; step : (3,) NED offset [m]; step_time [s]; yaw [rad]
    (None: free heading). The step is a discontinuity: velocity, acceleration and
    jerk stay zero, so the controller sees a pure set-point change as in the
    thesis's Fig. 11.4 (shaping leaves it: it is the test).
    """

    periodic = False

    def __init__(
        self,
        point: FloatArray | list[float],
        *,
        step: FloatArray | list[float] | None = None,
        step_time: float = 1.0,
        yaw: float | None = None,
        name: str = "hover",
    ) -> None:
        self.name = name
        self._p0 = _vec3(point, "hover point")
        self._p1 = self._p0 + (_vec3(step, "step") if step is not None else 0.0)
        if not (math.isfinite(step_time) and step_time >= 0.0):
            raise TrajectoryError(f"step_time must be a finite time >= 0 s, found {step_time!r}")
        self._t_step = float(step_time)
        self.duration = self._t_step if step is not None else 0.0
        self._yaw, self.free_heading = _heading(yaw)

    def sample(self, t: float) -> Reference:
        """Set point before / after the step; zero velocity, acceleration and jerk."""
        p = self._p0 if t < self._t_step else self._p1
        return Reference(t=t, position=p.copy(), velocity=np.zeros(3),
                         acceleration=np.zeros(3), yaw=self._yaw)

    @property
    def description(self) -> str:
        """What it is, for people."""
        if self.duration == 0.0:
            return "a fixed point (closed form)"
        return (f"a set-point step of {float(np.linalg.norm(self._p1 - self._p0)):.2f} m at "
                f"{self._t_step:g} s, left as it is (the step response is the test)")

    def pieces(self, t0: float, t1: float) -> list[PieceSet]:
        """At rest; with a step, two pieces (the step is the jump between them)."""
        if self.duration == 0.0 or not t0 < self._t_step < t1:
            p = self._p0 if t1 <= self._t_step else self._p1
            return [HoldSet(t0, t1, p, self._yaw)]
        return [HoldSet(t0, self._t_step, self._p0, self._yaw),
                HoldSet(self._t_step, t1, self._p1, self._yaw)]


class PiecewiseLinear:
    """Straight segments between knots, traversed at constant speed per segment.

    times : (N,) strictly increasing knot times [s], starting at 0
    points : (N, 3) knot positions, NED [m]
    periodic : the path repeats with period ``times[-1]``; then ``points[-1]``
        must equal ``points[0]`` (the loop is closed)
    smoothing_s : width T [s] of the moving-average window that rounds the
        corners (0 = sharp corners as flown in the thesis); must be shorter
        than the shortest segment
    yaw : None (free heading, yaw 0), a constant heading [rad], or (N,) headings
        at the knots [rad], unwrapped (a step of more than pi between knots is
        taken the short way) and interpolated linearly (not smoothed)

    Before the first knot an open path holds ``points[0]``, after the last it
    holds ``points[-1]``. :func:`groundstation.control.shaping.min_jerk_path`
    flies the same knots with a smooth time-scaling per segment.
    """

    def __init__(
        self,
        times: FloatArray | list[float],
        points: FloatArray | list[list[float]],
        *,
        periodic: bool = False,
        smoothing_s: float = 0.0,
        yaw: float | FloatArray | None = None,
        name: str = "path",
    ) -> None:
        t, p = check_knots(times, points, periodic)
        self.name = name
        self.periodic = periodic
        self.duration = float(t[-1])
        self._t: FloatArray = t
        self._p: FloatArray = p
        self._v: FloatArray = np.diff(p, axis=0) / np.diff(t)[:, None]  # (N-1, 3) per segment
        # antiderivative of p at the knots (exact: trapezoid of a linear segment)
        seg = 0.5 * (p[1:] + p[:-1]) * np.diff(t)[:, None]
        self._integral: FloatArray = np.vstack([np.zeros(3), np.cumsum(seg, axis=0)])
        if not (math.isfinite(smoothing_s) and smoothing_s >= 0.0):
            raise TrajectoryError(f"smoothing_s must be >= 0 s, found {smoothing_s!r}")
        if smoothing_s > 0.0 and smoothing_s >= float(np.min(np.diff(t))):
            raise TrajectoryError(
                f"corner smoothing {smoothing_s:g} s must be shorter than the shortest "
                f"segment ({float(np.min(np.diff(t))):g} s)"
            )
        self.smoothing_s = float(smoothing_s)
        self._yaws, self.free_heading = knot_headings(yaw, t.size)
        self._yaw_rates: FloatArray = np.diff(self._yaws) / np.diff(t)

    @property
    def times(self) -> FloatArray:
        """(N,) knot times [s] (a copy)."""
        return self._t.copy()

    @property
    def points(self) -> FloatArray:
        """(N, 3) knot positions, NED [m] (a copy)."""
        return self._p.copy()

    @property
    def yaws(self) -> FloatArray:
        """(N,) knot headings [rad], unwrapped (a copy)."""
        return self._yaws.copy()

    def _yaw(self, t: float) -> tuple[float, float]:
        """Heading [rad] and its rate [rad/s] at ``t`` (continuous across laps)."""
        i, tau, laps = self._locate(t)
        yaw = self._yaws[i] + self._yaw_rates[i] * tau + laps * (self._yaws[-1] - self._yaws[0])
        moving = self.periodic or 0.0 <= t < self.duration
        return float(yaw), float(self._yaw_rates[i]) if moving else 0.0

    # -- exact piecewise evaluation of p, v and the antiderivative of p
    def _locate(self, t: float) -> tuple[int, float, float]:
        """(segment index, time into it, number of whole periods or 0)."""
        laps = 0.0
        if self.periodic:
            laps = math.floor(t / self.duration)
            t -= laps * self.duration
        t = min(max(t, self._t[0]), self._t[-1])
        i = int(np.searchsorted(self._t, t, side="right")) - 1
        i = min(max(i, 0), len(self._t) - 2)
        return i, t - self._t[i], laps

    def _pos(self, t: float) -> FloatArray:
        i, tau, _ = self._locate(t)
        out: FloatArray = self._p[i] + self._v[i] * tau
        return out

    def _vel(self, t: float) -> FloatArray:
        if not self.periodic and (t < self._t[0] or t >= self._t[-1]):
            return _ZERO3
        i, _, _ = self._locate(t)
        out: FloatArray = self._v[i]
        return out

    def _antiderivative(self, t: float) -> FloatArray:
        """∫_0^t p(s) ds, with the constant extensions of an open path."""
        out: FloatArray
        if not self.periodic and t > self._t[-1]:
            out = self._integral[-1] + self._p[-1] * (t - self._t[-1])
        elif not self.periodic and t < 0.0:
            out = self._p[0] * t
        else:
            i, tau, laps = self._locate(t)
            within = self._integral[i] + self._p[i] * tau + 0.5 * self._v[i] * tau * tau
            out = laps * self._integral[-1] + within
        return out

    def sample(self, t: float) -> Reference:
        """Position, velocity and acceleration at ``t`` (smoothed if ``smoothing_s`` > 0)."""
        big_t = self.smoothing_s
        yaw, yaw_rate = self._yaw(t)
        if big_t == 0.0:
            return Reference(t=t, position=self._pos(t), velocity=self._vel(t).copy(),
                             acceleration=np.zeros(3), yaw=yaw, yaw_rate=yaw_rate)
        lo, hi = t - 0.5 * big_t, t + 0.5 * big_t
        pos = (self._antiderivative(hi) - self._antiderivative(lo)) / big_t
        vel = (self._pos(hi) - self._pos(lo)) / big_t  # _pos holds the end points
        acc = (self._vel(hi) - self._vel(lo)) / big_t
        # the moving average's acceleration is piecewise constant: its jerk is 0 where
        # defined (impulses at the window's edges are not representable)
        return Reference(t=t, position=pos, velocity=vel, acceleration=acc, yaw=yaw,
                         yaw_rate=yaw_rate)

    @property
    def description(self) -> str:
        """What it is, for people."""
        blend = f", corners blended over {self.smoothing_s:g} s" if self.smoothing_s else \
            ", sharp corners"
        return (f"raw corners (shaping none): {len(self._t)} knots joined by straight "
                f"segments at constant speed{blend}")

    def pieces(self, t0: float, t1: float) -> list[PieceSet] | None:
        """The straight segments as degree-1 polynomials (laps unrolled if periodic, at
        rest outside an open path); None with corner smoothing (not described piecewise)."""
        if self.smoothing_s > 0.0:
            return None
        coef = np.zeros((len(self._t) - 1, 2, 4))
        coef[:, 0, :3], coef[:, 1, :3] = self._p[:-1], self._v
        coef[:, 0, 3], coef[:, 1, 3] = self._yaws[:-1], self._yaw_rates
        if not self.periodic:
            out: list[PieceSet] = []
            if t0 < 0.0:
                out.append(HoldSet(t0, 0.0, self._p[0], float(self._yaws[0])))
            out.append(PolySet(self._t[:-1], self._t[1:], coef))
            if t1 > self.duration:
                out.append(HoldSet(self.duration, t1, self._p[-1], float(self._yaws[-1])))
            return out
        period, turn = self.duration, float(self._yaws[-1] - self._yaws[0])
        sets: list[PieceSet] = []
        for lap in range(math.floor(t0 / period), math.ceil(t1 / period)):
            lap_coef = coef.copy()
            lap_coef[:, 0, 3] += lap * turn
            sets.append(PolySet(self._t[:-1] + lap * period, self._t[1:] + lap * period,
                                lap_coef))
        return sets


def knot_headings(yaw: float | FloatArray | None, n: int) -> tuple[FloatArray, bool]:
    """(n,) unwrapped knot headings [rad] and free_heading from a ``yaw`` argument."""
    if yaw is None:
        return np.zeros(n), True
    yaws = np.broadcast_to(np.asarray(yaw, dtype=float), (n,))
    if not np.all(np.isfinite(yaws)):
        raise TrajectoryError("yaw must be finite")
    return np.unwrap(yaws), False


def check_knots(times: FloatArray | list[float], points: FloatArray | list[list[float]],
                periodic: bool) -> tuple[FloatArray, FloatArray]:
    """The knot times (N,) [s] and points (N, 3) [m] as float arrays; TrajectoryError
    unless they describe a valid path."""
    t = np.asarray(times, dtype=float).reshape(-1)
    p = np.asarray(points, dtype=float)
    if t.ndim != 1 or t.size < 2:
        raise TrajectoryError(f"a path needs at least 2 knots, found {t.size}")
    if p.shape != (t.size, 3):
        raise TrajectoryError(f"points must have shape ({t.size}, 3), found {p.shape}")
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(p))):
        raise TrajectoryError("knot times and points must be finite")
    if t[0] != 0.0:
        raise TrajectoryError(f"the first knot time must be 0 s, found {t[0]:g} s")
    if np.any(np.diff(t) <= 0.0):
        k = int(np.argmax(np.diff(t) <= 0.0))
        raise TrajectoryError(
            f"knot times must increase strictly: t[{k + 1}] = {t[k + 1]:g} s follows "
            f"t[{k}] = {t[k]:g} s"
        )
    if periodic and not np.allclose(p[0], p[-1], atol=1e-9):
        raise TrajectoryError("a periodic path must end where it starts (closed loop)")
    return t, p


class FigureEight:
    """A lemniscate of Gerono in the horizontal plane at constant height.

    ``y = a sin(w t)``, ``x = (a / 2) sin(2 w t)`` with ``w = 2 pi / period``,
    centred on ``center`` (NED [m]): the figure is ``2a`` wide along y (east) and
    ``a`` along x (north) and starts at the centre heading north-east, at speed
    ``sqrt(2) a w`` (not at rest: :mod:`~groundstation.control.shaping` eases it in
    and out). Velocity, acceleration and jerk are the exact derivatives; yaw
    constant (None: free heading).
    """

    periodic = True

    def __init__(
        self,
        center: FloatArray | list[float],
        *,
        width_m: float = 1.0,
        period_s: float = 20.0,
        yaw: float | None = None,
        name: str = "figure-eight",
    ) -> None:
        if not (math.isfinite(width_m) and math.isfinite(period_s) and width_m > 0.0
                and period_s > 0.0):
            raise TrajectoryError(f"figure-eight needs a finite width_m > 0 and period_s > 0, "
                                  f"found {width_m!r}, {period_s!r}")
        self.name = name
        self.duration = float(period_s)
        self._c = _vec3(center, "figure-eight centre")
        self._a = 0.5 * float(width_m)
        self._w = 2.0 * math.pi / float(period_s)
        self._yaw, self.free_heading = _heading(yaw)

    def sample(self, t: float) -> Reference:
        """Exact position, velocity, acceleration and jerk of the lemniscate at ``t``."""
        a, w = self._a, self._w
        s1, c1 = math.sin(w * t), math.cos(w * t)
        s2, c2 = math.sin(2 * w * t), math.cos(2 * w * t)
        pos = self._c + np.array([0.5 * a * s2, a * s1, 0.0])
        vel = np.array([a * w * c2, a * w * c1, 0.0])
        acc = np.array([-2.0 * a * w * w * s2, -a * w * w * s1, 0.0])
        jerk = np.array([-4.0 * a * w ** 3 * c2, -a * w ** 3 * c1, 0.0])
        return Reference(t=t, position=pos, velocity=vel, acceleration=acc, yaw=self._yaw,
                         jerk=jerk)

    @property
    def description(self) -> str:
        """What it is, for people."""
        return (f"closed form: a lemniscate {2 * self._a:g} m (east) x {self._a:g} m "
                f"(north), {self.duration:g} s a lap")

    def peaks(self) -> tuple[float, float, float, float]:
        """Closed-form peaks over a lap: speed ``sqrt(2) a w`` (at the centre),
        acceleration ``17/8 a w^2`` (where ``sin^2(w t) = 17/32``), jerk ``sqrt(17) a w^3``
        (at the centre) and snap ``257/32 a w^4`` (``sin^2(w t) = 257/512``), with the half
        width ``a`` [m] and ``w = 2 pi / period`` [rad/s]: e.g. ``|a|^2 = a^2 w^4 u (17 -
        16 u)`` with ``u = sin^2(w t)``, largest at ``u = 17/32``."""
        a, w = self._a, self._w
        return (math.sqrt(2.0) * a * w, 17.0 / 8.0 * a * w * w, math.sqrt(17.0) * a * w ** 3,
                257.0 / 32.0 * a * w ** 4)

    def critical_times(self, t0: float, t1: float) -> list[float]:
        """The times in ``[t0, t1]`` (first lap in it) where the speed, acceleration, jerk
        and each coordinate peak (see :meth:`peaks`)."""
        star = math.asin(math.sqrt(17.0 / 32.0))
        angles = [k * math.pi / 4.0 for k in range(8)] + [star, math.pi - star,
                                                           math.pi + star, 2 * math.pi - star]
        lap = math.floor(t0 / self.duration) if math.isfinite(t0 / self.duration) else 0
        out = []
        for base in (lap, lap + 1):
            out += [(base + th / (2 * math.pi)) * self.duration for th in angles]
        return sorted(t for t in out if t0 <= t <= t1)

    def pieces(self, t0: float, t1: float) -> list[PieceSet]:
        """The closed form over ``[t0, t1]`` in pieces of at most 1/16 lap."""
        n = min(max(1, math.ceil(16.0 * (t1 - t0) / self.duration)), 4096)
        edges = np.linspace(t0, t1, n + 1)
        return [_EightSet(self, edges[:-1], edges[1:])]

    def sample_many(self, t: FloatArray) -> Samples:
        """:meth:`sample` at many times ``t`` (n,) [s] at once."""
        t = np.asarray(t, dtype=float)
        a, w, c = self._a, self._w, self._c
        s1, c1, s2, c2 = np.sin(w * t), np.cos(w * t), np.sin(2 * w * t), np.cos(2 * w * t)
        zero = np.zeros_like(t)
        pos = np.stack([c[0] + 0.5 * a * s2, c[1] + a * s1, np.full_like(t, c[2])], axis=1)
        vel = np.stack([a * w * c2, a * w * c1, zero], axis=1)
        acc = np.stack([-2.0 * a * w * w * s2, -a * w * w * s1, zero], axis=1)
        jerk = np.stack([-4.0 * a * w ** 3 * c2, -a * w ** 3 * c1, zero], axis=1)
        return Samples(t.copy(), pos, vel, acc, jerk, np.full_like(t, self._yaw), zero.copy())


class _EightSet:
    """Pieces of a :class:`FigureEight`, bounded by its closed-form peaks."""

    kind = "closed form"

    def __init__(self, eight: FigureEight, start: FloatArray, end: FloatArray) -> None:
        self.eight, self.start, self.end = eight, start, end

    def evaluate(self, index: IntArray, t: FloatArray) -> Samples:
        """The closed form at ``t``."""
        return self.eight.sample_many(t)

    def bounds(self) -> PieceBounds:
        """The lap's peaks and box (``centre -+ (a/2, a, 0)``) for every piece."""
        m = len(self.start)
        speed, accel, jerk, snap = self.eight.peaks()
        reach = np.array([0.5 * self.eight._a, self.eight._a, 0.0])
        full = np.ones(m)
        return PieceBounds(lo=np.tile(self.eight._c - reach, (m, 1)),
                           hi=np.tile(self.eight._c + reach, (m, 1)), speed=speed * full,
                           accel=accel * full, jerk=jerk * full, snap=snap * full,
                           yaw_rate=0.0 * full, yaw_accel=0.0 * full)


class YawTurn:
    """Hold ``center`` while the heading turns by ``turn`` [rad] over ``period_s``.

    The heading follows the min-jerk profile ``yaw + turn * S(t / period_s)``
    (:func:`~groundstation.control.minjerk.smoothstep`): it starts and ends at rest,
    with the peak rate ``15/8 * turn / period_s``. ``yaw`` [rad] is the heading at
    the start (None: free heading, the turn is relative to the heading at take-off).
    Open: afterwards the heading holds at ``yaw + turn``.
    """

    periodic = False

    def __init__(
        self,
        center: FloatArray | list[float],
        *,
        turn: float = 2.0 * math.pi,
        period_s: float = 20.0,
        yaw: float | None = None,
        name: str = "yaw-turn",
    ) -> None:
        if not (math.isfinite(turn) and math.isfinite(period_s) and period_s > 0.0):
            raise TrajectoryError(
                f"yaw-turn needs a finite turn and period_s > 0, found {turn!r}, {period_s!r}")
        self.name = name
        self.duration = float(period_s)
        self._c = _vec3(center, "yaw-turn centre")
        self._turn = float(turn)
        self._yaw, self.free_heading = _heading(yaw)

    def sample(self, t: float) -> Reference:
        """The centre at rest; the heading and its rate at ``t``."""
        s, ds, _, _ = smoothstep(t / self.duration)
        return Reference(t=t, position=self._c.copy(), velocity=np.zeros(3),
                         yaw=self._yaw + self._turn * s, yaw_rate=self._turn * ds / self.duration)

    @property
    def description(self) -> str:
        """What it is, for people."""
        return (f"closed form: a heading turn of {math.degrees(self._turn):g} deg over "
                f"{self.duration:g} s (min-jerk), holding position")

    def critical_times(self, t0: float, t1: float) -> list[float]:
        """Mid-turn, where the heading rate peaks at ``15/8 turn / period``."""
        mid = 0.5 * self.duration
        return [mid] if t0 <= mid <= t1 else []

    def pieces(self, t0: float, t1: float) -> list[PieceSet]:
        """The turn as one quintic in the heading (``turn S(t / T)``), at rest around it."""
        big_t, turn = self.duration, self._turn
        coef = np.zeros((1, 6, 4))
        coef[0, 0, :3] = self._c
        coef[0, 0, 3] = self._yaw
        coef[0, 3:, 3] = [10.0 * turn / big_t ** 3, -15.0 * turn / big_t ** 4,
                          6.0 * turn / big_t ** 5]
        out: list[PieceSet] = []
        if t0 < 0.0:
            out.append(HoldSet(t0, 0.0, self._c, self._yaw))
        out.append(PolySet(np.zeros(1), np.array([big_t]), coef))
        if t1 > big_t:
            out.append(HoldSet(big_t, t1, self._c, self._yaw + turn))
        return out
