"""Tracking metrics for flown trajectories: RMS error, time lag, step-response figures.

Pure functions of sampled time histories (uniform sample time ``dt``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from groundstation.errors import ControlError
from groundstation.types import FloatArray


def rms_error(flown: FloatArray, reference: FloatArray) -> float:
    """Root-mean-square Euclidean distance between (N, d) histories [same unit]."""
    diff = np.asarray(flown, dtype=float) - np.asarray(reference, dtype=float)
    return float(np.sqrt(np.mean(np.sum(diff.reshape(len(diff), -1) ** 2, axis=1))))


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
