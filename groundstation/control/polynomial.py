"""A trajectory made of polynomial segments: fitted sample files, polynomial files, min-jerk paths.

:class:`PiecewisePolynomial` holds, per segment, the polynomials of x, y, z (NED [m])
and the heading [rad] in the time since the segment's start, lowest power first (the
layout of uav_trajectories' files and of ``scipy.interpolate.PPoly`` reversed). Every
derivative is exact, and the feasibility check reads the coefficients themselves
(:meth:`PiecewisePolynomial.pieces`), so nothing between two samples escapes it.

Outside ``[0, duration]`` an open trajectory is at rest at its first or last point
(if it starts or ends moving, :func:`~groundstation.control.shaping.shape_for_flight`
eases it in and out); a periodic one repeats, its heading continuing lap after lap.
"""

from __future__ import annotations

import bisect
import math

import numpy as np

from groundstation.control.curve import HoldSet, PieceSet, PolySet, Samples, sample_pieces
from groundstation.errors import TrajectoryError
from groundstation.types import FloatArray, Reference


class PiecewisePolynomial:
    """Position and heading as polynomials of time, one set per segment.

    breaks : (M + 1,) segment boundaries [s], strictly increasing from 0;
    coefficients : (M, K + 1, 4) coefficients of x, y, z (NED [m]) and yaw [rad] in
        ``tau = t - breaks[i]`` [s], lowest power first;
    periodic : repeats with period ``breaks[-1]`` (the path must then close);
    free_heading : the yaw is relative to the heading at take-off (the mission adds it);
    description : one line saying what the trajectory was made from (for people).
    """

    def __init__(self, breaks: FloatArray | list[float], coefficients: FloatArray, *,
                 periodic: bool = False, free_heading: bool = False,
                 name: str = "polynomial", description: str = "") -> None:
        b = np.asarray(breaks, dtype=float).reshape(-1)
        c = np.asarray(coefficients, dtype=float)
        if b.size < 2 or c.ndim != 3 or c.shape[0] != b.size - 1 or c.shape[2] != 4:
            raise TrajectoryError(f"polynomial trajectory: {b.size} breaks need coefficients "
                                  f"of shape ({b.size - 1}, K + 1, 4), found {c.shape}")
        if not (np.all(np.isfinite(b)) and np.all(np.isfinite(c))):
            raise TrajectoryError("polynomial trajectory: breaks and coefficients must be "
                                  "finite")
        if b[0] != 0.0 or np.any(np.diff(b) <= 0.0):
            raise TrajectoryError("polynomial trajectory: segment times must start at 0 and "
                                  "increase strictly")
        self.name = name
        self.periodic = periodic
        self.free_heading = free_heading
        self.description = description
        self.breaks: FloatArray = b
        self.coefficients: FloatArray = c
        self.duration = float(b[-1])
        self._set = PolySet(b[:-1], b[1:], c)
        self._break_list = b.tolist()
        first = self._set.evaluate(np.array([0]), np.array([0.0]))
        last = self._set.evaluate(np.array([b.size - 2]), np.array([self.duration]))
        self._first, self._last = first.reference(0), last.reference(0)
        self._lap_yaw = float(last.yaw[0] - first.yaw[0])
        if periodic and not np.allclose(first.position, last.position, atol=1e-6):
            raise TrajectoryError("a periodic polynomial path must end where it starts")

    @property
    def segments(self) -> int:
        """Number of segments M."""
        return int(self.coefficients.shape[0])

    @property
    def degree(self) -> int:
        """Polynomial degree K."""
        return int(self.coefficients.shape[1] - 1)

    def sample(self, t: float) -> Reference:
        """Exact position, velocity, acceleration, jerk, heading and heading rate at ``t``."""
        laps = 0.0
        if self.periodic:
            laps = math.floor(t / self.duration)
            t -= laps * self.duration
        elif t < 0.0 or t >= self.duration:
            end = self._first if t < 0.0 else self._last
            return Reference(t=t, position=end.position.copy(), velocity=np.zeros(3),
                             yaw=end.yaw)
        i = min(bisect.bisect_right(self._break_list, t) - 1, self.segments - 1)
        ref = self._set.at(max(i, 0), t)
        if laps:
            return Reference(t=t + laps * self.duration, position=ref.position,
                             velocity=ref.velocity, acceleration=ref.acceleration,
                             yaw=ref.yaw + laps * self._lap_yaw, jerk=ref.jerk,
                             yaw_rate=ref.yaw_rate)
        return ref

    def sample_many(self, t: FloatArray) -> Samples:
        """:meth:`sample` at many times ``t`` (n,) [s] at once."""
        t = np.asarray(t, dtype=float)
        span = t[-1] if t.size else 0.0
        sets = self.pieces(min(0.0, float(np.min(t, initial=0.0))), max(span, self.duration))
        assert sets is not None
        return sample_pieces(sets, t)

    def pieces(self, t0: float, t1: float) -> list[PieceSet] | None:
        """The segments over ``[t0, t1]`` (laps unrolled if periodic; at rest before 0
        and after the end if open)."""
        out: list[PieceSet] = []
        if not self.periodic:
            if t0 < 0.0:
                out.append(HoldSet(t0, 0.0, self._first.position, self._first.yaw))
            out.append(self._set)
            if t1 > self.duration:
                out.append(HoldSet(self.duration, t1, self._last.position, self._last.yaw))
            return out
        period = self.duration
        for lap in range(math.floor(t0 / period), math.ceil(t1 / period)):
            if lap == 0:
                out.append(self._set)
                continue
            coef = self.coefficients.copy()
            coef[:, 0, 3] += lap * self._lap_yaw
            out.append(PolySet(self.breaks[:-1] + lap * period, self.breaks[1:] + lap * period,
                               coef))
        return out
