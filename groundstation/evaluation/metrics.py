"""Flight metrics: pure functions of aligned time histories.

Every function takes numpy arrays and returns numbers; nothing here knows how a
flight was flown. Positions are NED [m], times [s], quaternions scalar-first.

* tracking error: RMS and maximum Euclidean distance between two paths;
* time lag: the delay of the flown path behind the reference that maximises
  their normalised cross-correlation (:func:`time_lag`),
  refined to below one sample by a parabola through the peak, after resampling onto a
  uniform grid,
  over the axes on which the reference moves;
* step figures: overshoot and the 2 % settling time
  (:func:`step_metrics` with ``band = 0.02``);
* tilt from a quaternion, percentiles of per-tick timings, and the lap mean
  of a periodic path (thesis Fig. 11.5 shows the mean of five laps);
* distance off a path: each point's distance to a polyline (the densely sampled
  reference), exact, found through a k-d tree of the polyline's vertices;
* heading (3-2-1 Euler yaw) from a quaternion and wrapped heading errors.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy.spatial import cKDTree

from groundstation.errors import ControlError
from groundstation.types import FloatArray

SETTLING_BAND = 0.02
"""Settling band as a fraction of the step size (2 %)."""

MOVING_STD_M = 0.01
"""An axis whose reference varies by less than this (standard deviation) [m] does not move."""


def error_norms(path: FloatArray, reference: FloatArray) -> FloatArray:
    """Euclidean distance per row between (N, d) ``path`` and ``reference`` [m]."""
    return np.asarray(np.linalg.norm(np.asarray(path) - np.asarray(reference), axis=1))


def rms(values: FloatArray) -> float:
    """Root mean square of ``values`` (NaN for an empty array)."""
    v = np.asarray(values, dtype=float)
    return float(np.sqrt(np.mean(v * v))) if v.size else math.nan


def tracking_errors(path: FloatArray, reference: FloatArray) -> dict[str, float]:
    """RMS (3-D and per axis) and maximum 3-D error of (N, 3) ``path`` against ``reference``.

    Keys ``rms_m``, ``rms_x_m``, ``rms_y_m``, ``rms_z_m``, ``max_m`` [m]; NaN when N = 0.
    """
    p, r = np.asarray(path, dtype=float), np.asarray(reference, dtype=float)
    if len(p) == 0:
        return dict.fromkeys(("rms_m", "rms_x_m", "rms_y_m", "rms_z_m", "max_m"), math.nan)
    d = error_norms(p, r)
    per_axis = np.sqrt(np.mean((p - r) ** 2, axis=0))
    return {"rms_m": rms(d), "rms_x_m": float(per_axis[0]), "rms_y_m": float(per_axis[1]),
            "rms_z_m": float(per_axis[2]), "max_m": float(np.max(d))}


def time_lag(flown: FloatArray, reference: FloatArray, dt: float, max_lag_s: float = 5.0) -> float:
    """Delay [s] of (N,) or (N, d) ``flown`` behind ``reference``, both sampled every ``dt``.

    For each lag ``l`` (|l| <= ``max_lag_s``, at most a quarter of the window) the
    reference's central samples ``a = reference[L:N-L]`` are compared with the
    flown samples ``l`` later, ``b = flown[L+l:N-L+l]``, by the correlation
    coefficient ``sum(a.b) / (|a| |b|)`` (means removed per channel, channels
    summed, so the x and y of a square give one lag). The reference window is the
    same for every lag, so by Cauchy-Schwarz a pure delay
    ``flown(t) = reference(t - d)`` peaks at exactly ``l = d``; the
    overlap-normalised estimator ``sum over the overlap / (N - |l|)`` is biased by
    the window's edges (35 ms for a 10 s sine over 60 s). The peak is refined by a
    parabola through it and its neighbours. Positive: the vehicle is behind.
    """
    a = np.asarray(reference, dtype=float).reshape(len(reference), -1)
    b = np.asarray(flown, dtype=float).reshape(len(flown), -1)
    if a.shape != b.shape or len(a) < 5:
        raise ControlError(f"histories must have the same shape (N >= 5), found {a.shape}, "
                           f"{b.shape}")
    n = len(a)
    big_l = min(round(max_lag_s / dt), (n - 1) // 4)
    core = a[big_l:n - big_l] - a[big_l:n - big_l].mean(axis=0)
    norm_a = float(np.linalg.norm(core))
    c = np.zeros(2 * big_l + 1)
    for k, lag in enumerate(range(-big_l, big_l + 1)):
        seg = b[big_l + lag:n - big_l + lag]
        seg = seg - seg.mean(axis=0)
        denom = norm_a * float(np.linalg.norm(seg))
        c[k] = float(np.sum(core * seg)) / denom if denom > 0.0 else 0.0
    k = int(np.argmax(c))
    frac = 0.0
    if 0 < k < len(c) - 1:
        curv = c[k - 1] - 2.0 * c[k] + c[k + 1]
        frac = 0.5 * (c[k - 1] - c[k + 1]) / curv if curv != 0.0 else 0.0
    return float((k - big_l + frac) * dt)


@dataclass(frozen=True, slots=True)
class StepMetrics:
    """Figures of a step response: rise_time (10-90 %) [s], settling_time [s]
    after the step (last exit from the ``band`` around the final value),
    overshoot [fraction of the step], steady_state_error [unit of the signal]."""

    rise_time: float
    settling_time: float
    overshoot: float
    steady_state_error: float


def step_metrics(t: FloatArray, y: FloatArray, *, t_step: float, initial: float, final: float,
                 band: float = 0.05, tail_s: float = 1.0) -> StepMetrics:
    """Step-response figures of ``y(t)`` for a set-point step ``initial -> final`` at ``t_step``.

    band : settling band as a fraction of the step size (5 % default);
    tail_s : the steady-state error is the mean error over the last ``tail_s``.
    """
    t = np.asarray(t, dtype=float)
    y = np.asarray(y, dtype=float)
    size = final - initial
    if size == 0.0:
        raise ControlError("a step must change the set point")
    after = t >= t_step
    s = (y[after] - initial) / size  # normalised: 0 -> 1
    ta = t[after] - t_step
    outside = np.flatnonzero(np.abs(s - 1.0) > band)
    settling = float(ta[outside[-1] + 1]) if outside.size and outside[-1] + 1 < len(ta) else (
        float("inf") if outside.size else 0.0)
    above10 = np.flatnonzero(s >= 0.1)
    above90 = np.flatnonzero(s >= 0.9)
    rise = (float(ta[above90[0]] - ta[above10[0]]) if above10.size and above90.size
            else float("inf"))
    tail = ta >= ta[-1] - tail_s
    return StepMetrics(
        rise_time=rise, settling_time=settling, overshoot=float(max(0.0, np.max(s) - 1.0)),
        steady_state_error=float(np.mean(y[after][tail]) - final),
    )


def resample(t: FloatArray, values: FloatArray, dt: float) -> tuple[FloatArray, FloatArray]:
    """Linear interpolation of (N,) or (N, d) ``values`` at ``t`` onto a grid of step ``dt``."""
    t = np.asarray(t, dtype=float)
    grid = np.arange(t[0], t[-1] + 0.5 * dt, dt)
    grid = grid[grid <= t[-1]]
    v = np.asarray(values, dtype=float).reshape(len(t), -1)
    out = np.column_stack([np.interp(grid, t, v[:, k]) for k in range(v.shape[1])])
    return grid, out


def moving_axes(reference: FloatArray, threshold_m: float = MOVING_STD_M) -> list[int]:
    """Indices of the columns of (N, d) ``reference`` whose standard deviation exceeds
    ``threshold_m``: the axes a lag can be measured on."""
    std = np.std(np.asarray(reference, dtype=float), axis=0)
    return [k for k in range(std.shape[0]) if std[k] > threshold_m]


def lag_s(t: FloatArray, path: FloatArray, reference: FloatArray, *, dt: float = 0.01,
          max_lag_s: float = 3.0) -> float:
    """Delay [s] of ``path`` behind ``reference`` (N, 3) sampled at times ``t`` (N,).

    Resampled to a uniform ``dt`` grid; the correlations of the axes on which the
    reference moves are summed (so the x and y of a square give one lag).
    Positive: the vehicle is behind. NaN if the reference does not move (hover,
    steps) or the window is shorter than three samples.
    """
    axes = moving_axes(reference)
    if not axes or len(t) < 3 or t[-1] - t[0] < 8 * dt:
        return math.nan
    _, ref = resample(t, np.asarray(reference)[:, axes], dt)
    _, flown = resample(t, np.asarray(path)[:, axes], dt)
    return time_lag(flown, ref, dt, max_lag_s)


def step_figures(t: FloatArray, y: FloatArray, *, t_step: float, initial: float,
                 final: float) -> dict[str, float]:
    """Overshoot [%], 2 % settling time [s], 10-90 % rise time [s] and steady-state error [m]
    of ``y(t)`` for a set-point step ``initial -> final`` at ``t_step``.

    ``t`` and ``y`` should cover the step and enough time after it to settle (the
    steady-state error is the mean error over the last second).
    """
    m: StepMetrics = step_metrics(np.asarray(t), np.asarray(y), t_step=t_step,
                                  initial=initial, final=final, band=SETTLING_BAND)
    return {"overshoot_pct": 100.0 * m.overshoot, "settling_s": m.settling_time,
            "rise_s": m.rise_time, "steady_state_m": m.steady_state_error}


def tilt_deg(q: FloatArray) -> FloatArray:
    """Angle between body z and earth z [deg] for (N, 4) scalar-first unit quaternions.

    ``cos(tilt) = R(q)[2, 2] = q0^2 - q1^2 - q2^2 + q3^2`` (``R(q) = eCb``).
    """
    q = np.asarray(q, dtype=float)
    c = q[:, 0] ** 2 - q[:, 1] ** 2 - q[:, 2] ** 2 + q[:, 3] ** 2
    return np.asarray(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))))


def percentiles(values: FloatArray, scale: float = 1.0,
                qs: tuple[float, ...] = (50.0, 99.0)) -> list[float]:
    """Percentiles ``qs`` of the finite ``values`` times ``scale``, then their maximum
    (all NaN if there are none)."""
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    if v.size == 0:
        return [math.nan] * (len(qs) + 1)
    return [float(x) * scale for x in (*np.percentile(v, qs), np.max(v))]


def track_clock(t: FloatArray, active: npt.NDArray[np.bool_]) -> FloatArray:
    """Time spent in the ``active`` rows so far [s]: the trajectory's own clock.

    t : (N,) row times; active : (N,) rows in which the trajectory runs (TRACK).
    A row adds its spacing to the previous row only if both rows are active,
    so the clock starts at 0 on the first active row and pauses outside them,
    as :class:`groundstation.flight.mission.Mission` pauses it in HOLD.
    """
    t = np.asarray(t, dtype=float)
    a = np.asarray(active, dtype=bool)
    inc = np.zeros_like(t)
    inc[1:] = np.diff(t) * (a[1:] & a[:-1])
    return np.cumsum(inc)


def lap_mean(clock: FloatArray, path: FloatArray, period_s: float, laps: int,
             first: int = 0, dt: float = 0.01) -> tuple[FloatArray, FloatArray]:
    """Mean over ``laps`` whole laps, from lap ``first`` on, of a periodic (N, d) ``path``
    sampled at trajectory time ``clock`` (N,): the phase grid (M,) [s] and mean path (M, d).

    Lap ``k`` covers ``k * period_s <= clock < (k + 1) * period_s``; each lap is
    interpolated onto the same phase grid before averaging.
    """
    phase = np.arange(0.0, period_s, dt)
    p = np.asarray(path, dtype=float).reshape(len(clock), -1)
    c = np.asarray(clock, dtype=float)
    acc = np.zeros((len(phase), p.shape[1]))
    for k in range(first, first + laps):
        inside = (c >= k * period_s - dt) & (c <= (k + 1) * period_s + dt)
        ck, pk = c[inside], p[inside]
        for j in range(p.shape[1]):
            acc[:, j] += np.interp(phase + k * period_s, ck, pk[:, j])
    return phase, acc / laps


PATH_SEGMENT_M = 0.005
"""Polyline segments longer than this are split before the k-d tree is built [m]
(collinear vertices: the path is unchanged; the candidate search needs short segments)."""


def _densify(vertices: FloatArray, max_len: float) -> FloatArray:
    """``vertices`` (M, d) without repeated consecutive vertices, every segment split into
    equal parts no longer than ``max_len``: the same polyline."""
    v = np.asarray(vertices, dtype=float)
    v = v[np.r_[True, np.any(np.diff(v, axis=0) != 0.0, axis=1)]]
    if len(v) < 2:
        return v
    seg = np.diff(v, axis=0)
    parts = np.maximum(1, np.ceil(np.linalg.norm(seg, axis=1) / max_len)).astype(int)
    if np.all(parts == 1):
        return v
    k = np.repeat(np.arange(len(seg)), parts)
    frac = np.concatenate([np.arange(n) / n for n in parts])
    return np.vstack([v[k] + frac[:, None] * seg[k], v[-1:]])


def _segment_distances(p: FloatArray, a: FloatArray, b: FloatArray) -> FloatArray:
    """Row-wise distance from points ``p`` to segments ``a``-``b`` (all (K, d))."""
    ab, ap = b - a, p - a
    ab2 = np.einsum("ij,ij->i", ab, ab)
    u = np.clip(np.einsum("ij,ij->i", ap, ab) / np.where(ab2 > 0.0, ab2, 1.0), 0.0, 1.0)
    d = ap - u[:, None] * ab
    return np.asarray(np.sqrt(np.einsum("ij,ij->i", d, d)))


def path_distances(points: FloatArray, polyline: FloatArray) -> FloatArray:
    """Distance [m] from each of (N, d) ``points`` to the polyline through (M, d) vertices.

    Exact: after splitting segments to at most :data:`PATH_SEGMENT_M` (``L``), a segment
    whose closest point lies within ``e`` of a point has a vertex within ``e + L / 2``;
    with ``e`` the distance to the nearest vertex, the segments next to the vertices in
    that ball hold the answer. One vertex: distances to it; no vertex: NaN.
    """
    p = np.asarray(points, dtype=float).reshape(-1, np.shape(polyline)[-1])
    v = _densify(np.asarray(polyline, dtype=float), PATH_SEGMENT_M)
    if len(v) == 0 or len(p) == 0:
        return np.full(len(p), math.nan)
    if len(v) == 1:
        return np.asarray(np.linalg.norm(p - v[0], axis=1))
    tree = cKDTree(v)
    nearest, _ = tree.query(p)
    longest = float(np.max(np.linalg.norm(np.diff(v, axis=0), axis=1)))
    balls = tree.query_ball_point(p, nearest + 0.5 * longest + 1e-12)
    counts = np.fromiter((len(b) for b in balls), dtype=int, count=len(p))
    vertex = np.concatenate([np.asarray(b, dtype=int) for b in balls])
    who = np.repeat(np.arange(len(p)), counts)
    before = np.clip(vertex - 1, 0, len(v) - 2)  # the segments ending and starting there
    after = np.minimum(vertex, len(v) - 2)
    d = np.minimum(_segment_distances(p[who], v[before], v[before + 1]),
                   _segment_distances(p[who], v[after], v[after + 1]))
    out = np.full(len(p), np.inf)
    np.minimum.at(out, who, d)
    return out


def heading_deg(q: FloatArray) -> FloatArray:
    """Heading (3-2-1 Euler yaw, from north towards east) [deg] in (-180, 180] of (N, 4)
    scalar-first quaternions: ``atan2(2 (q1 q2 + q0 q3), q0^2 + q1^2 - q2^2 - q3^2)``."""
    q = np.asarray(q, dtype=float)
    return np.asarray(np.degrees(np.arctan2(
        2.0 * (q[:, 1] * q[:, 2] + q[:, 0] * q[:, 3]),
        q[:, 0] ** 2 + q[:, 1] ** 2 - q[:, 2] ** 2 - q[:, 3] ** 2)))


def wrap_deg(angle: FloatArray) -> FloatArray:
    """Angles [deg] wrapped into [-180, 180)."""
    return np.asarray((np.asarray(angle, dtype=float) + 180.0) % 360.0 - 180.0)
