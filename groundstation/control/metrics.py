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
    """Delay [s] of ``flown`` behind ``reference`` by cross-correlation.

    flown, reference : (N,) or (N, d) histories sampled every ``dt`` [s]; the
    channels are mean-removed and their correlations summed, so the x and y of
    a square give one lag. The lag maximising the normalised cross-correlation
    ``c(l) = mean_i ref[i] . flown[i + l]`` over ``|l| <= max_lag_s`` is refined
    to below one sample by a parabola through the peak and its neighbours.
    Positive: the vehicle is behind the reference.
    """
    a = np.asarray(reference, dtype=float).reshape(len(reference), -1)
    b = np.asarray(flown, dtype=float).reshape(len(flown), -1)
    if a.shape != b.shape or len(a) < 3:
        raise ControlError(f"histories must have the same shape (N >= 3), found {a.shape}, "
                           f"{b.shape}")
    a = a - a.mean(axis=0)
    b = b - b.mean(axis=0)
    n = len(a)
    max_l = min(round(max_lag_s / dt), n // 2)
    lags = range(-max_l, max_l + 1)
    c = np.array([np.sum(a[max(0, -lag): n - max(0, lag)] * b[max(0, lag): n - max(0, -lag)])
                  / (n - abs(lag)) for lag in lags])
    k = int(np.argmax(c))
    frac = 0.0
    if 0 < k < len(c) - 1:
        denom = c[k - 1] - 2.0 * c[k] + c[k + 1]
        frac = 0.5 * (c[k - 1] - c[k + 1]) / denom if denom != 0.0 else 0.0
    return float((k - max_l + frac) * dt)


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
