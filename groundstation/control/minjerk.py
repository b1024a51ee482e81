"""Minimum-jerk profiles: the quintic smoothstep, rest-to-rest segments, quintic blends.

The quintic smoothstep ``S(x) = 10 x^3 - 15 x^4 + 6 x^5`` rises from 0 to 1 on
``[0, 1]`` with zero first and second derivatives at both ends: it is the
minimum-jerk rest-to-rest profile (Flash and Hogan, 1985). Its peaks, used to
size a segment from speed and acceleration limits, are ``S'(1/2) = 15/8``,
``|S''| = 10 / sqrt(3)`` at ``x = 1/2 -+ sqrt(3)/6`` and ``|S'''| = 60`` at the ends.

:class:`MinJerkSegment` moves a point (or an angle) from rest to rest along a
straight line; :class:`Quintic` is the quintic in time with given end values,
end speeds and zero end accelerations that the shaped paths are built from.
All functions return exact derivatives up to the third (jerk).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from groundstation.types import FloatArray

PEAK_RATE = 1.875
"""max S'(x): the peak speed of a rest-to-rest segment is ``PEAK_RATE * distance / T``."""
PEAK_ACCEL = 10.0 / math.sqrt(3.0)
"""max |S''(x)|: the peak acceleration is ``PEAK_ACCEL * distance / T^2``."""
PEAK_JERK = 60.0
"""max |S'''(x)|: the peak jerk is ``PEAK_JERK * distance / T^3``."""


def smoothstep(x: float) -> tuple[float, float, float, float]:
    """``S(x)`` and its first three derivatives with respect to ``x``.

    Clamped: 0 before ``x = 0`` and 1 after ``x = 1``, with zero derivatives.
    """
    if x <= 0.0:
        return 0.0, 0.0, 0.0, 0.0
    if x >= 1.0:
        return 1.0, 0.0, 0.0, 0.0
    x2 = x * x
    return (x2 * x * (10.0 - 15.0 * x + 6.0 * x2), 30.0 * x2 * (1.0 - x) ** 2,
            60.0 * x * (1.0 - x) * (1.0 - 2.0 * x), 60.0 * (1.0 - 6.0 * x + 6.0 * x2))


def smoothstep_integral(x: float) -> float:
    """``∫_0^x S(u) du`` for ``x`` in ``[0, 1]`` (``1/2`` at ``x = 1``)."""
    x = min(max(x, 0.0), 1.0)
    x4 = x ** 4
    return x4 * (2.5 - 3.0 * x + x * x)


def min_jerk_duration(distance: float, max_speed: float, max_accel: float,
                      max_jerk: float = math.inf) -> float:
    """Shortest duration [s] of a rest-to-rest min-jerk move over ``distance`` whose peak
    speed stays within ``max_speed``, peak acceleration within ``max_accel`` and peak
    jerk within ``max_jerk``. Without the jerk limit a short move is fast: 3 mm within
    0.5 m/s^2 takes 0.19 s and asks for 26 m/s^3, a tilt rate of 2.7 rad/s."""
    d = abs(distance)
    if d == 0.0:
        return 0.0
    return max(PEAK_RATE * d / max_speed, math.sqrt(PEAK_ACCEL * d / max_accel),
               math.pow(PEAK_JERK * d / max_jerk, 1.0 / 3.0))


@dataclass(frozen=True, slots=True)
class MinJerkSegment:
    """From ``start`` at rest at ``t0`` to ``end`` at rest ``duration`` seconds later.

    start, end : (n,) arrays (a NED position [m], or a (1,) heading [rad]);
    before ``t0`` the segment is at ``start``, after its end at ``end``.
    """

    t0: float
    start: FloatArray
    end: FloatArray
    duration: float

    @property
    def end_time(self) -> float:
        """``t0 + duration`` [s]."""
        return self.t0 + self.duration

    def at(self, t: float) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """Position, velocity, acceleration and jerk at time ``t`` (exact)."""
        if self.duration <= 0.0:
            zero = np.zeros_like(self.end)
            return self.end.copy(), zero, zero.copy(), zero.copy()
        T = self.duration
        s, ds, dds, ddds = smoothstep((t - self.t0) / T)
        d = self.end - self.start
        return self.start + s * d, (ds / T) * d, (dds / T**2) * d, (ddds / T**3) * d


@dataclass(frozen=True, slots=True)
class Quintic:
    """``s(τ)`` on ``[0, h]``: ``s(0) = 0``, ``s(h) = length``, speeds ``v0`` and ``v1`` at
    the ends and zero acceleration at both (the Hermite quintic).

    With ``s = v0 τ + c3 τ^3 + c4 τ^4 + c5 τ^5`` and ``A = length - v0 h``,
    ``B h = (v1 - v0) h`` the end conditions give ``c3 h^3 = 10 A - 4 B h``,
    ``c4 h^4 = 7 B h - 15 A``, ``c5 h^5 = 6 A - 3 B h``; with ``v0 = v1 = 0`` this is
    ``length * S(τ / h)``, with ``v0 = v1 = length / h`` a constant speed.
    """

    h: float
    v0: float
    c3: float
    c4: float
    c5: float

    @classmethod
    def through(cls, length: float, h: float, v0: float, v1: float) -> Quintic:
        """The quintic covering ``length`` in ``h`` seconds from speed ``v0`` to ``v1``."""
        a, bh = length - v0 * h, (v1 - v0) * h
        return cls(h=h, v0=v0, c3=(10.0 * a - 4.0 * bh) / h**3, c4=(7.0 * bh - 15.0 * a) / h**4,
                   c5=(6.0 * a - 3.0 * bh) / h**5)

    def at(self, tau: float) -> tuple[float, float, float, float]:
        """``s``, ``s'``, ``s''``, ``s'''`` at ``tau`` seconds into the segment."""
        c3, c4, c5 = self.c3, self.c4, self.c5
        t = tau
        return (t * (self.v0 + t * t * (c3 + t * (c4 + t * c5))),
                self.v0 + t * t * (3.0 * c3 + t * (4.0 * c4 + t * 5.0 * c5)),
                t * (6.0 * c3 + t * (12.0 * c4 + t * 20.0 * c5)),
                6.0 * c3 + t * (24.0 * c4 + t * 60.0 * c5))
