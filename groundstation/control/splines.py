"""Dense sampled paths: a smooth curve through the samples, continuous to the jerk.

A waypoint file is either a list of *corners* (the thesis's square, a few waypoints
seconds apart: each flown from rest to rest, :class:`~groundstation.control.shaping.MinJerkPath`)
or *samples of a curve* (a spline exported every 10 or 20 ms). :func:`dense_rule` tells
them apart: the samples are closer than the vehicle can stop between when flying each
hop from rest to rest (a min-jerk hop of ``d`` metres in ``h`` seconds peaks at
``15/8 d/h`` and ``10/sqrt(3) d/h^2``; a heading hop at ``15/8 dpsi/h``) would break the
speed, acceleration (``g tan(tilt limit)``) or heading-rate limit for at least half of
the hops that move, and there are at least :data:`MIN_DENSE_SAMPLES` of them.

:func:`fit_samples` fits each of x, y, z and the (unwrapped) heading with a quintic
least-squares spline on uniformly spaced knots (``scipy.interpolate.make_lsq_spline``,
k = 5: continuous to the fourth derivative, so the feed-forward's acceleration and jerk
are smooth). The number of knot intervals is the one minimising the Bayesian
information criterion ``RSS / sigma^2 + ln(n) p`` (``p`` coefficients, at most half the
number of samples), with ``sigma`` the data's own noise: the robust spread of the
sixth differences of the samples (:func:`noise_estimate`; a smooth curve's sixth
difference is ``h^6 f^(6)``, negligible at these rates, while white noise's is
``sqrt(924) sigma``), at least :data:`NOISE_FLOOR_M`. Noise-free samples are then met
within micrometres; noisy ones are smoothed to a residual about their noise.

Why not FITPACK's smoothing spline (``UnivariateSpline(k=5, s=n sigma^2)``): its knot
insertion chases the noise wherever ``sigma`` comes out a little low, and on a
lemniscate sampled at 100 Hz with 0.5 mm of noise it put 114 knots into one axis and
asked 84 m/s^3 of jerk (861 m/s^3 at 50 Hz); uniform knots chosen by the criterion
stayed below 25 m/s^3 on 20 noise draws at 10, 50 and 100 Hz.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from groundstation.control.minjerk import PEAK_ACCEL, PEAK_RATE
from groundstation.control.polynomial import PiecewisePolynomial
from groundstation.errors import TrajectoryError
from groundstation.types import FloatArray

MIN_DENSE_SAMPLES = 12
"""Fewest samples taken for a curve (a quintic spline needs 6 coefficients, at most half
the samples)."""
NOISE_FLOOR_M = 1e-5
"""Smallest noise assumed [m] (and [rad] for headings): files are written to about a
micrometre, and the criterion needs a noise to weigh the residual against."""
DIFF_ORDER = 6
"""Order of the differences the noise is estimated from."""
DEGREE = 5
"""Quintic: continuous to the fourth derivative."""


@dataclass(frozen=True, slots=True)
class HopRule:
    """The verdict of :func:`dense_rule`: ``dense``; ``moving`` hops; how many would
    break a limit flown rest-to-rest; the worst such hop's need (text)."""

    dense: bool
    samples: int
    moving: int
    breaking: int
    worst: str

    def describe(self) -> str:
        """One line for people."""
        return (f"{self.breaking} of {self.moving} moving hops flown rest-to-rest would break "
                f"the limits ({self.worst})")


def dense_rule(times: FloatArray, points: FloatArray, yaws: FloatArray, *, max_speed: float,
               max_accel: float, max_yaw_rate: float) -> HopRule:
    """Are ``points`` (N, 3) [m] at ``times`` (N,) [s] with headings ``yaws`` (N,) [rad]
    samples of a curve (see the module doc)? Limits in m/s, m/s^2 and rad/s."""
    h = np.diff(times)
    d = np.linalg.norm(np.diff(points, axis=0), axis=1)
    turn = np.abs(np.diff(yaws))
    speed, accel, rate = PEAK_RATE * d / h, PEAK_ACCEL * d / h ** 2, PEAK_RATE * turn / h
    moving = (d > 0.0) | (turn > 0.0)
    excess = np.maximum.reduce([speed / max_speed, accel / max_accel, rate / max_yaw_rate])
    breaking = moving & (excess > 1.0)
    n_moving, n_breaking = int(np.count_nonzero(moving)), int(np.count_nonzero(breaking))
    worst = ""
    if n_breaking:
        k = int(np.argmax(np.where(breaking, excess, 0.0)))
        worst = (f"the worst: {d[k] * 1000:.1f} mm in {h[k] * 1000:.0f} ms needs "
                 f"{accel[k]:.3g} m/s^2, {speed[k]:.3g} m/s")
    dense = len(times) >= MIN_DENSE_SAMPLES and n_moving > 0 and 2 * n_breaking >= n_moving
    return HopRule(dense, len(times), n_moving, n_breaking, worst)


def noise_estimate(y: FloatArray) -> float:
    """White-noise standard deviation of the samples ``y`` (n,): the median absolute
    deviation of their sixth differences, scaled to a standard deviation (x 1.4826) and
    by ``sqrt(C(12, 6)) = sqrt(924)``, the spread of a sixth difference of unit noise."""
    if len(y) <= DIFF_ORDER:
        return 0.0
    d = np.diff(y, n=DIFF_ORDER)
    mad = float(np.median(np.abs(d - np.median(d))))
    return 1.4826 * mad / math.sqrt(math.comb(2 * DIFF_ORDER, DIFF_ORDER))


def _lsq_spline(t: FloatArray, y: FloatArray, intervals: int):  # type: ignore[no-untyped-def]
    """The quintic least-squares spline of ``y`` on ``intervals`` uniform knot intervals."""
    from scipy.interpolate import make_lsq_spline

    inner = np.linspace(t[0], t[-1], intervals + 1)[1:-1]
    knots = np.concatenate([np.full(DEGREE + 1, t[0]), inner, np.full(DEGREE + 1, t[-1])])
    return make_lsq_spline(t, y, knots, k=DEGREE)


def _fit_channel(t: FloatArray, y: FloatArray, sigma: float):  # type: ignore[no-untyped-def]
    """(spline, knot intervals) minimising ``RSS / sigma^2 + ln(n) p`` for ``y`` (n,)."""
    n = len(t)
    most = max(1, n // 2 - DEGREE)
    candidates = np.unique(np.round(np.geomspace(1, most, 40)).astype(int))
    best = None
    since_best = 0
    for intervals in candidates:
        try:
            spline = _lsq_spline(t, y, int(intervals))
        except (ValueError, np.linalg.LinAlgError):  # knots without data between them
            continue
        rss = float(np.sum((spline(t) - y) ** 2))
        criterion = rss / sigma ** 2 + math.log(n) * (intervals + DEGREE)
        if best is None or criterion < best[0]:
            best, since_best = (criterion, spline, int(intervals)), 0
        else:
            since_best += 1
            if since_best >= 8:  # the criterion rises for good once the noise is fitted
                break
    if best is None:
        raise TrajectoryError("the samples cannot be fitted (too few distinct times)")
    return best[1], best[2]


@dataclass(frozen=True, slots=True)
class SampleFit:
    """How a dense path was fitted.

    samples : rows; rate_hz : median sample rate; noise_m : (3,) noise estimate per axis
    [m]; noise_yaw_rad; residual_rms_m, residual_max_m : distance of the samples from
    the fitted curve [m]; residual_yaw_max_rad; intervals : knot intervals per channel
    (x, y, z, yaw); rule : the :class:`HopRule` that called it dense.
    """

    samples: int
    rate_hz: float
    noise_m: tuple[float, float, float]
    noise_yaw_rad: float
    residual_rms_m: float
    residual_max_m: float
    residual_yaw_max_rad: float
    intervals: tuple[int, int, int, int]
    rule: HopRule

    def describe(self) -> str:
        """One line for people (millimetres, degrees)."""
        noise = "/".join(f"{1000 * s:.2f}" for s in self.noise_m)
        return (f"dense samples: {self.samples} rows at {self.rate_hz:.0f} Hz, "
                f"{self.rule.describe()}; fitted with a quintic least-squares spline (knot "
                f"intervals x/y/z/yaw {'/'.join(str(k) for k in self.intervals)}, chosen "
                f"from the noise); noise "
                f"estimate x/y/z {noise} mm, yaw {math.degrees(self.noise_yaw_rad):.3f} deg; "
                f"samples off the curve: {1000 * self.residual_rms_m:.3f} mm RMS, "
                f"{1000 * self.residual_max_m:.3f} mm max, yaw "
                f"{math.degrees(self.residual_yaw_max_rad):.3f} deg max")


class FittedPath(PiecewisePolynomial):
    """A :class:`PiecewisePolynomial` fitted to dense samples; ``fit`` says how."""

    def __init__(self, breaks: FloatArray, coefficients: FloatArray, fit: SampleFit, *,
                 free_heading: bool, name: str) -> None:
        super().__init__(breaks, coefficients, free_heading=free_heading, name=name,
                         description=fit.describe())
        self.fit = fit
        self.sample_times: FloatArray = np.zeros(0)
        """The samples' times (N,) [s] (for figures)."""
        self.sample_points: FloatArray = np.zeros((0, 3))
        """The samples (N, 3), NED [m]."""


def fit_samples(times: FloatArray, points: FloatArray, yaws: FloatArray, *, rule: HopRule,
                free_heading: bool, name: str = "waypoints") -> FittedPath:
    """The smooth curve through dense samples (see the module doc).

    times : (N,) [s] strictly increasing from 0; points : (N, 3) NED [m]; yaws : (N,)
    unwrapped headings [rad] (zeros for a free heading); rule : why they are dense.
    """
    from scipy.interpolate import PPoly

    t = np.asarray(times, dtype=float)
    data = np.column_stack([np.asarray(points, dtype=float), np.asarray(yaws, dtype=float)])
    polys, intervals, noise = [], [], []
    for c in range(4):
        sigma = noise_estimate(data[:, c])
        noise.append(sigma)
        spline, k = _fit_channel(t, data[:, c], max(sigma, NOISE_FLOOR_M))
        polys.append(PPoly.from_spline(spline))
        intervals.append(k)
    breaks = np.unique(np.concatenate([p.x for p in polys]))
    starts = breaks[:-1]
    coef = np.zeros((len(starts), DEGREE + 1, 4))
    for c, poly in enumerate(polys):  # re-expand each channel about the common breaks
        for k in range(DEGREE + 1):
            coef[:, k, c] = poly(starts, nu=k) / math.factorial(k)
    off = np.column_stack([p(t) for p in polys]) - data
    dist = np.linalg.norm(off[:, :3], axis=1)
    fit = SampleFit(samples=len(t), rate_hz=1.0 / float(np.median(np.diff(t))),
                    noise_m=(noise[0], noise[1], noise[2]), noise_yaw_rad=noise[3],
                    residual_rms_m=float(np.sqrt(np.mean(dist ** 2))),
                    residual_max_m=float(np.max(dist)),
                    residual_yaw_max_rad=float(np.max(np.abs(off[:, 3]))),
                    intervals=(intervals[0], intervals[1], intervals[2], intervals[3]),
                    rule=rule)
    path = FittedPath(breaks - breaks[0], coef, fit, free_heading=free_heading, name=name)
    path.sample_times, path.sample_points = t.copy(), data[:, :3].copy()
    return path
