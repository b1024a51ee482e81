"""The flown curve as pieces with bounds: what the feasibility check reads instead of samples.

A trajectory that knows its own form describes the time span ``[t0, t1]`` as a list of
:class:`PieceSet` objects (``pieces(t0, t1)``, the :class:`Piecewise` protocol). A piece
is a time interval on which the reference is one smooth formula: a polynomial segment
(:class:`PolySet`), a constant (:class:`HoldSet`), a closed form (the figure-eight), or
one of those on an eased clock (:class:`~groundstation.control.shaping.TimeWarp`). Each
set evaluates its pieces at many times at once (:meth:`PieceSet.evaluate`, one-sided: a
piece uses its own formula up to its end, so a jump between two pieces shows) and
bounds them (:meth:`PieceSet.bounds`: upper bounds of the norms of the derivatives up to
the fourth, and a box holding every position, per piece). The bounds are rigorous:
from the coefficients (a Taylor expansion about the piece's middle) or a closed form,
never from samples, so the check can bound what happens between any two of its
samples (:mod:`groundstation.control.feasibility`).

Positions NED [m], velocities [m/s], accelerations [m/s^2], jerks [m/s^3], snaps
[m/s^4], headings [rad] (unwrapped), heading rates [rad/s] and accelerations [rad/s^2].
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np
import numpy.typing as npt

from groundstation.types import FloatArray, Reference

IntArray = npt.NDArray[np.intp]


@dataclass(frozen=True, slots=True)
class Samples:
    """References at n times, as arrays.

    t : (n,) [s]; position, velocity, acceleration, jerk : (n, 3) NED;
    yaw : (n,) [rad]; yaw_rate : (n,) [rad/s].
    """

    t: FloatArray
    position: FloatArray
    velocity: FloatArray
    acceleration: FloatArray
    jerk: FloatArray
    yaw: FloatArray
    yaw_rate: FloatArray

    def __len__(self) -> int:
        return int(self.t.shape[0])

    def take(self, index: IntArray | npt.NDArray[np.bool_]) -> Samples:
        """The samples at ``index`` (an index or boolean array)."""
        return Samples(self.t[index], self.position[index], self.velocity[index],
                       self.acceleration[index], self.jerk[index], self.yaw[index],
                       self.yaw_rate[index])

    def reference(self, k: int) -> Reference:
        """Sample ``k`` as a :class:`~groundstation.types.Reference`."""
        return Reference(t=float(self.t[k]), position=self.position[k].copy(),
                         velocity=self.velocity[k].copy(),
                         acceleration=self.acceleration[k].copy(), yaw=float(self.yaw[k]),
                         jerk=self.jerk[k].copy(), yaw_rate=float(self.yaw_rate[k]))

    @classmethod
    def empty(cls, n: int) -> Samples:
        """``n`` samples of zeros (filled in place by :func:`concatenate` users)."""
        z3 = np.zeros((n, 3))
        return cls(np.zeros(n), z3, z3.copy(), z3.copy(), z3.copy(), np.zeros(n), np.zeros(n))

    @classmethod
    def of(cls, refs: list[Reference]) -> Samples:
        """The references ``refs`` as arrays."""
        return cls(np.array([r.t for r in refs], dtype=float),
                   np.array([r.position for r in refs], dtype=float).reshape(-1, 3),
                   np.array([r.velocity for r in refs], dtype=float).reshape(-1, 3),
                   np.array([r.acceleration for r in refs], dtype=float).reshape(-1, 3),
                   np.array([r.jerk for r in refs], dtype=float).reshape(-1, 3),
                   np.array([r.yaw for r in refs], dtype=float),
                   np.array([r.yaw_rate for r in refs], dtype=float))

    def put(self, index: IntArray, other: Samples) -> None:
        """Write ``other`` into rows ``index`` of these samples (in place)."""
        self.t[index] = other.t
        self.position[index] = other.position
        self.velocity[index] = other.velocity
        self.acceleration[index] = other.acceleration
        self.jerk[index] = other.jerk
        self.yaw[index] = other.yaw
        self.yaw_rate[index] = other.yaw_rate


@dataclass(frozen=True, slots=True)
class PieceBounds:
    """Rigorous upper bounds over each of m pieces.

    lo, hi : (m, 3) a box holding every position of the piece, NED [m];
    speed, accel, jerk, snap : (m,) largest norms of the first to fourth derivatives;
    yaw_rate, yaw_accel : (m,) largest |heading rate| [rad/s] and |its derivative| [rad/s^2].
    """

    lo: FloatArray
    hi: FloatArray
    speed: FloatArray
    accel: FloatArray
    jerk: FloatArray
    snap: FloatArray
    yaw_rate: FloatArray
    yaw_accel: FloatArray

    def take(self, index: IntArray) -> PieceBounds:
        """The bounds of pieces ``index``."""
        return PieceBounds(self.lo[index], self.hi[index], self.speed[index],
                           self.accel[index], self.jerk[index], self.snap[index],
                           self.yaw_rate[index], self.yaw_accel[index])

    @classmethod
    def concatenate(cls, parts: list[PieceBounds]) -> PieceBounds:
        """The bounds of several sets of pieces, in order."""
        return cls(*(np.concatenate([getattr(p, name) for p in parts])
                     for name in ("lo", "hi", "speed", "accel", "jerk", "snap", "yaw_rate",
                                  "yaw_accel")))


class PieceSet(Protocol):
    """m pieces of a trajectory: piece i spans ``[start[i], end[i]]`` (trajectory time [s]).

    kind : what the pieces are, for people ("polynomial segments", "closed form", ...).
    """

    start: FloatArray
    end: FloatArray
    kind: str

    def evaluate(self, index: IntArray, t: FloatArray) -> Samples:
        """Piece ``index[k]`` at time ``t[k]`` (within its span), by its own formula."""
        ...

    def bounds(self) -> PieceBounds:
        """Upper bounds per piece (see :class:`PieceBounds`)."""
        ...


@runtime_checkable
class Piecewise(Protocol):
    """A trajectory that can describe its flown curve exactly, piece by piece."""

    def pieces(self, t0: float, t1: float) -> list[PieceSet] | None:
        """Piece sets covering ``[t0, t1]`` in time order (the first may start before
        ``t0``, the last end after ``t1``), or None if it cannot."""
        ...


# ------------------------------------------------------------------ polynomial pieces
def derivative_coefficients(coef: FloatArray, order: int) -> FloatArray:
    """The coefficients (m, K + 1 - order, d) of the ``order``-th derivative of the
    polynomials ``coef`` (m, K + 1, d), lowest power first (zeros if ``order > K``)."""
    k1 = coef.shape[1]
    if order >= k1:
        return np.zeros((coef.shape[0], 1, coef.shape[2]))
    powers = np.arange(order, k1, dtype=float)
    factor = np.ones(k1 - order)
    for r in range(order):
        factor = factor * (powers - r)
    out: FloatArray = coef[:, order:, :] * factor[None, :, None]
    return out


def horner(coef: FloatArray, tau: FloatArray) -> FloatArray:
    """The polynomials ``coef`` (n, K + 1, d) at ``tau`` (n,): (n, d)."""
    out = coef[:, -1, :].copy()
    for k in range(coef.shape[1] - 2, -1, -1):
        out = out * tau[:, None] + coef[:, k, :]
    return out


class PolySet:
    """Polynomial segments: position (x, y, z) and heading as polynomials of the time
    since each segment's start.

    start, end : (m,) segment spans [s]; coef : (m, K + 1, 4) coefficients of x, y, z
    (NED [m]) and yaw [rad] in ``tau = t - start`` [s], lowest power first.
    """

    kind = "polynomial segments"

    def __init__(self, start: FloatArray, end: FloatArray, coef: FloatArray,
                 kind: str = "polynomial segments") -> None:
        self.start = np.asarray(start, dtype=float)
        self.end = np.asarray(end, dtype=float)
        self.coef = np.asarray(coef, dtype=float)
        self.kind = kind
        self._d = [derivative_coefficients(self.coef, r) for r in range(4)]
        # One sample is a product of the powers of tau with every derivative's
        # coefficients at once (:meth:`at`): (m, K + 1, 4 derivatives x 4 axes).
        k1 = self.coef.shape[1]
        table = np.zeros((self.coef.shape[0], k1, 4, 4))
        for r, d in enumerate(self._d):
            table[:, :d.shape[1], r, :] = d
        self._table = table.reshape(self.coef.shape[0], k1, 16)
        self._exponents = np.arange(k1, dtype=float)

    def evaluate(self, index: IntArray, t: FloatArray) -> Samples:
        """Segment ``index[k]`` at ``t[k]`` with its exact derivatives up to the jerk."""
        tau = t - self.start[index]
        p, v, a, j = (horner(d[index], tau) for d in self._d)
        return Samples(t.copy(), p[:, :3], v[:, :3], a[:, :3], j[:, :3], p[:, 3], v[:, 3])

    def at(self, index: int, t: float) -> Reference:
        """Segment ``index`` at one time ``t`` [s]: :meth:`evaluate` for a single sample,
        without its arrays of one (the flight's reference, every tick)."""
        tau = t - float(self.start[index])
        out = (tau ** self._exponents @ self._table[index]).reshape(4, 4)
        return Reference(t=t, position=out[0, :3], velocity=out[1, :3],
                         acceleration=out[2, :3], yaw=float(out[0, 3]), jerk=out[3, :3],
                         yaw_rate=float(out[1, 3]))

    def bounds(self) -> PieceBounds:
        """From the Taylor expansion about each segment's middle: on ``|tau - mid| <= h/2``
        the r-th derivative is at most ``sum_k |p^(r+k)(mid)| (h/2)^k / k!`` per axis."""
        with np.errstate(over="ignore", invalid="ignore"):  # huge: refused as not finite
            return self._bounds()

    def _bounds(self) -> PieceBounds:
        coef = self.coef
        m, k1, _ = coef.shape
        half = 0.5 * (self.end - self.start)
        mid = half.copy()
        at_mid = np.stack([horner(derivative_coefficients(coef, r), mid) for r in range(k1)],
                          axis=1)  # (m, K + 1, 4): p^(r)(mid)
        powers = np.stack([half ** k / math.factorial(k) for k in range(k1)], axis=1)  # (m, K+1)

        def bound(order: int) -> FloatArray:
            """(m, 4) bounds of |p^(order)| per axis."""
            if order >= k1:
                return np.zeros((m, 4))
            terms = np.abs(at_mid[:, order:, :]) * powers[:, : k1 - order, None]
            out: FloatArray = np.sum(terms, axis=1)
            return out

        spread = bound(0) - np.abs(at_mid[:, 0, :])  # the reach beyond the middle value
        norms = [np.linalg.norm(bound(r)[:, :3], axis=1) for r in (1, 2, 3, 4)]
        return PieceBounds(lo=at_mid[:, 0, :3] - spread[:, :3], hi=at_mid[:, 0, :3] + spread[:, :3],
                           speed=norms[0], accel=norms[1], jerk=norms[2], snap=norms[3],
                           yaw_rate=bound(1)[:, 3], yaw_accel=bound(2)[:, 3])


class HoldSet:
    """The reference at rest at ``point`` (NED [m]) with heading ``yaw`` [rad] over each
    span ``[start[i], end[i]]``."""

    kind = "at rest"

    def __init__(self, start: float, end: float, point: FloatArray, yaw: float) -> None:
        self.start = np.array([float(start)])
        self.end = np.array([float(end)])
        self.point = np.asarray(point, dtype=float).reshape(3)
        self.yaw = float(yaw)

    def evaluate(self, index: IntArray, t: FloatArray) -> Samples:
        """The point, at rest."""
        n = len(t)
        zeros = np.zeros((n, 3))
        return Samples(t.copy(), np.tile(self.point, (n, 1)), zeros, zeros.copy(), zeros.copy(),
                       np.full(n, self.yaw), np.zeros(n))

    def bounds(self) -> PieceBounds:
        """Zero derivatives; the box is the point."""
        z = np.zeros(1)
        return PieceBounds(self.point[None, :].copy(), self.point[None, :].copy(), z, z.copy(),
                           z.copy(), z.copy(), z.copy(), z.copy())


def sample_pieces(sets: list[PieceSet], t: FloatArray) -> Samples:
    """The curve ``sets`` at times ``t`` (n,): each time in the first piece that holds it
    (times outside every piece take the nearest end)."""
    starts = np.concatenate([s.start for s in sets])
    ends = np.concatenate([s.end for s in sets])
    owner = np.concatenate([np.full(len(s.start), k) for k, s in enumerate(sets)])
    local = np.concatenate([np.arange(len(s.start)) for s in sets])
    t = np.asarray(t, dtype=float)
    piece = np.clip(np.searchsorted(ends, t, side="left"), 0, len(ends) - 1)
    tt = np.clip(t, starts[piece], ends[piece])
    out = Samples.empty(len(t))
    for k, s in enumerate(sets):
        rows = np.flatnonzero(owner[piece] == k)
        if rows.size:
            out.put(rows, s.evaluate(local[piece[rows]], tt[rows]))
    out.t[:] = t
    return out
