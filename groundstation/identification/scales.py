"""IMU scale identification from a flight log, against Vicon in the same log (Table 6.2).

The ground station turns raw counts into SI with ``SI = K (count - zero)`` per axis
(``vehicle.gyro_scale``/``acc_scale``, ``gyro_zero``/``acc_zero``; Table 6.2). This
module fits ``K`` per axis by regressing a reference that Vicon's poses imply on the
raw counts the same flight logged:

* body rates ``omega = 2 Im(q* ⊗ dq/dt)`` from the Vicon quaternion (scalar first,
  body to earth), divided by ``|q|^2``;
* specific force ``f = R(q)^T (d^2 P/dt^2 - [0, 0, g])`` from the Vicon position (NED)
  and attitude, with ``g = vehicle.gravity``.

Processing: the Vicon poses (``vicon_valid`` rows, stamped ``vicon_t``) are put on a
uniform grid at their own median interval, within runs without gaps; every signal,
reference and counts alike, passes through the *same* Gaussian smoothing (standard
deviation ``smoothing_s``) before the regression, and the derivatives are central
differences of the smoothed signals, so smoothing attenuates both sides equally and
does not bias the slope. The counts are interpolated at the grid times plus a lag
that the fit finds itself (the IMU's ``imu_t`` is a receive time, a frame's time on
the wire after the sample; Vicon's ``vicon_t`` is a measurement time): the lag that
maximises the summed R^2 of the axes asked for, refined to a fraction of a sample.
Only grid points whose whole smoothing window lies airborne (off the floor: a
touchdown stops the body at once but the accelerometer feels it over 50 ms) and
within continuous IMU data are used.

Per axis ``reference = K (count - zero) + c`` by least squares with an intercept, so
an error in the configured zero (or a sensor bias) lands in ``c``, not in ``K``. 95 %
confidence intervals of ``K`` by a moving-block bootstrap (blocks of about a second,
longer than the smoothing's correlation; fixed seed, so a log gives one answer).

A quadrotor's rotors push only along body z, so in flight the accelerometer's x and y
read (nearly) zero whatever the vehicle does: those two axes have no excitation in
flight, and the virtual lab's model has none at all. Identify them on the bench
(e.g. the vehicle resting on each side) and leave them out here with ``axes``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import numpy as np

from groundstation.errors import IdentificationError
from groundstation.identification.rates import SYSID_HINT, BoolArray, FlightLog, load_flight_log
from groundstation.types import FloatArray

__all__ = [
    "SCALE_AXES",
    "AxisScaleFit",
    "ScaleFit",
    "identify_scales",
]

ScaleAxis = Literal["gyro_x", "gyro_y", "gyro_z", "acc_x", "acc_y", "acc_z"]
SCALE_AXES: tuple[ScaleAxis, ...] = ("gyro_x", "gyro_y", "gyro_z", "acc_x", "acc_y", "acc_z")
"""The sensor axes, FRD body axes of the gyro and the accelerometer."""

_UNIT = {"gyro": "rad/s", "acc": "m/s^2"}


@dataclass(frozen=True)
class AxisScaleFit:
    """One sensor axis's scale (Table 6.2 K).

    axis : e.g. "gyro_x"; sensor : "gyro" or "acc"; unit : "rad/s" or "m/s^2"
    scale : K [unit per count]; scale_ci : 95 % interval; configured : the flight
        configuration's value
    offset : intercept c [unit]: the reference at the configured zero count (zero error
        and sensor bias together)
    zero_estimate : the count at which the reference is zero [counts], ``zero - c / K``
    r2 : coefficient of determination; rms_residual : [unit]
    reference_std : standard deviation of the reference [unit] (the excitation)
    samples : grid points fitted
    counts, reference : (n,) the fitted points, ``count - zero`` [counts] and the
        reference [unit] (for :meth:`ScaleFit.figure`)
    """

    axis: ScaleAxis
    sensor: str
    unit: str
    scale: float
    scale_ci: tuple[float, float]
    configured: float
    offset: float
    zero_estimate: float
    r2: float
    rms_residual: float
    reference_std: float
    samples: int
    counts: FloatArray = field(repr=False, compare=False)
    reference: FloatArray = field(repr=False, compare=False)

    def summary(self) -> str:
        """One line: the scale with its 95 % interval, against the configured one."""
        lo, hi = self.scale_ci
        change = 100.0 * (self.scale / self.configured - 1.0)
        return (f"{self.axis:6s} K = {self.scale:.5e} {self.unit}/count "
                f"[{lo:.5e}, {hi:.5e}]  ({change:+.1f} % from {self.configured:.5e})  "
                f"R^2 {self.r2:.3f}, RMS {self.rms_residual:.4f} {self.unit}, "
                f"excitation {self.reference_std:.3f} {self.unit}, {self.samples} points")


@dataclass(frozen=True)
class ScaleFit:
    """IMU scales identified from one flight (see the module docstring).

    fits : the fitted axes, in :data:`SCALE_AXES` order
    gyro_scale, acc_scale : (3,) [rad/s per count], [m/s^2 per count]; an axis not
        fitted keeps the flight configuration's value
    lag_s : IMU receive time minus Vicon measurement time of the same instant [s]
    smoothing_s : the Gaussian smoothing's standard deviation [s]
    vicon_rate_hz : the Vicon poses' rate in the log [Hz]
    source : the flight directory
    """

    fits: tuple[AxisScaleFit, ...]
    gyro_scale: tuple[float, float, float]
    acc_scale: tuple[float, float, float]
    lag_s: float
    smoothing_s: float
    vicon_rate_hz: float
    source: Path

    def axis(self, name: ScaleAxis) -> AxisScaleFit | None:
        """The fit of axis ``name`` ("gyro_x" ... "acc_z"), None if it was not fitted."""
        return next((f for f in self.fits if f.axis == name), None)

    def config_fields(self) -> dict[str, list[float]]:
        """``{"vehicle.gyro_scale": [3], "vehicle.acc_scale": [3]}`` (configuration
        field paths, ready for ``apply_overrides``)."""
        return {"vehicle.gyro_scale": [float(v) for v in self.gyro_scale],
                "vehicle.acc_scale": [float(v) for v in self.acc_scale]}

    def summary(self) -> str:
        """Several lines: each fitted axis with its 95 % interval, then the values."""
        fitted = {f.axis for f in self.fits}
        kept = [a for a in SCALE_AXES if a not in fitted]
        lines = [f"IMU scales identified from {self.source} against Vicon "
                 f"({self.vicon_rate_hz:.0f} Hz, smoothing {1e3 * self.smoothing_s:.0f} ms, "
                 f"IMU lag {1e3 * self.lag_s:.1f} ms)"]
        lines += ["  " + f.summary() for f in self.fits]
        if kept:
            lines.append(f"  not fitted (configured value kept): {', '.join(kept)}")
        g = ", ".join(f"{v:.5e}" for v in self.gyro_scale)
        a = ", ".join(f"{v:.5e}" for v in self.acc_scale)
        lines += [f"  vehicle.gyro_scale: [{g}]  # rad/s per count",
                  f"  vehicle.acc_scale: [{a}]  # m/s^2 per count"]
        return "\n".join(lines)

    def figure(self, path: str | Path) -> Path:
        """Write a PNG: per fitted axis the reference against ``count - zero`` with the
        fitted line and, through the data's mean, the configured scale's slope. Needs
        matplotlib (GroundStationError naming ``pip install 'groundstation[plot]'``
        without it)."""
        from groundstation.evaluation.plotting import pyplot, save

        plt = pyplot()
        n = len(self.fits)
        cols = min(3, n)
        nrows = -(-n // cols)
        fig, axes = plt.subplots(nrows, cols, figsize=(4.2 * cols, 3.6 * nrows), squeeze=False)
        for ax, fit in zip(axes.flat, self.fits, strict=False):
            x, y = fit.counts, fit.reference
            step = max(1, len(x) // 4000)
            ax.plot(x[::step], y[::step], ".", ms=1.5, color="C0", alpha=0.4,
                    label="Vicon reference")
            xs = np.array([x.min(), x.max()])
            ax.plot(xs, fit.scale * xs + fit.offset, color="C1", lw=1.2,
                    label=f"K = {fit.scale:.4e}")
            xm, ym = float(np.mean(x)), float(np.mean(y))
            ax.plot(xs, ym + fit.configured * (xs - xm), color="k", lw=0.8, ls=":",
                    label=f"configured {fit.configured:.4e}")
            ax.set_xlabel(f"{fit.axis} count - zero")
            ax.set_ylabel(f"reference [{fit.unit}]")
            ax.set_title(f"{fit.axis}: R^2 {fit.r2:.3f}", fontsize=9)
            ax.grid(alpha=0.3)
            ax.legend(fontsize=7, loc="upper left")
        for ax in list(axes.flat)[n:]:
            ax.set_visible(False)
        return save(fig, Path(path))


# --------------------------------------------------------------------------- references
def _body_increment(q0: FloatArray, q1: FloatArray) -> FloatArray:
    """Rotation vector of ``conj(q0) ⊗ q1`` for unit quaternions (n, 4) -> (n, 3): the
    rotation from attitude ``q0`` to ``q1`` in ``q0``'s body axes [rad]."""
    a0, a1, a2, a3 = q0[:, 0], -q0[:, 1], -q0[:, 2], -q0[:, 3]
    b0, b1, b2, b3 = q1[:, 0], q1[:, 1], q1[:, 2], q1[:, 3]
    w = a0 * b0 - a1 * b1 - a2 * b2 - a3 * b3
    v = np.column_stack([
        a0 * b1 + a1 * b0 + a2 * b3 - a3 * b2,
        a0 * b2 - a1 * b3 + a2 * b0 + a3 * b1,
        a0 * b3 + a1 * b2 - a2 * b1 + a3 * b0,
    ])
    sign = np.where(w < 0, -1.0, 1.0)
    w, v = w * sign, v * sign[:, None]
    s = np.linalg.norm(v, axis=1)
    angle = 2.0 * np.arctan2(s, w)
    factor = np.where(s > 1e-12, angle / np.maximum(s, 1e-300), 2.0)
    out: FloatArray = v * factor[:, None]
    return out


def _earth_to_body(q: FloatArray, v: FloatArray) -> FloatArray:
    """``R(q)^T v`` for unit quaternions (n, 4) and vectors (n, 3) -> (n, 3)."""
    q0, q1, q2, q3 = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    s0, s1, s2, s3 = q0 * q0, q1 * q1, q2 * q2, q3 * q3
    r = np.empty((len(q), 3, 3))
    r[:, 0, 0] = s0 + s1 - s2 - s3
    r[:, 0, 1] = 2 * (q1 * q2 - q0 * q3)
    r[:, 0, 2] = 2 * (q1 * q3 + q0 * q2)
    r[:, 1, 0] = 2 * (q1 * q2 + q0 * q3)
    r[:, 1, 1] = s0 - s1 + s2 - s3
    r[:, 1, 2] = 2 * (q2 * q3 - q0 * q1)
    r[:, 2, 0] = 2 * (q1 * q3 - q0 * q2)
    r[:, 2, 1] = 2 * (q2 * q3 + q0 * q1)
    r[:, 2, 2] = s0 - s1 - s2 + s3
    out: FloatArray = np.einsum("nji,nj->ni", r, v)
    return out


def _kernel(sigma_samples: float) -> FloatArray:
    """Normalised Gaussian of standard deviation ``sigma_samples``, truncated at 4 sigma."""
    w = max(1, math.ceil(4.0 * sigma_samples))
    i = np.arange(-w, w + 1, dtype=float)
    g = np.exp(-0.5 * (i / sigma_samples) ** 2)
    out: FloatArray = g / g.sum()
    return out


def _smooth(x: FloatArray, k: FloatArray) -> FloatArray:
    """Each column of (n, c) ``x`` convolved with ``k`` ('valid': n - len(k) + 1 rows)."""
    return np.column_stack([np.convolve(x[:, j], k, mode="valid") for j in range(x.shape[1])])


def _window_all(ok: BoolArray, length: int) -> BoolArray:
    """For each 'valid' window of ``length`` samples: all of ``ok`` true in it."""
    bad = np.convolve((~ok).astype(float), np.ones(length), mode="valid")
    out: BoolArray = bad < 0.5
    return out


@dataclass
class _Grid:
    """Vicon on a uniform grid, per segment; the references at the window centres."""

    t: list[FloatArray]  # per segment: grid times [s]
    omega: list[FloatArray]  # per segment: (n - 2w - 2, 3) reference body rates [rad/s]
    force: list[FloatArray]  # per segment: (n - 2w - 2, 3) reference specific force
    air: list[BoolArray]  # per segment: window wholly airborne


def _vicon(log: FlightLog) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Unique Vicon poses, sorted: times [s], positions (n, 3) NED [m], quaternions (n, 4)
    with a continuous sign."""
    rows = log.rows
    ok = rows["vicon_valid"] & np.isfinite(rows["vicon_t"])
    ok &= np.all(np.isfinite(rows["vicon_position"]), axis=1)
    ok &= np.all(np.isfinite(rows["vicon_quaternion"]), axis=1)
    t = rows["vicon_t"][ok].astype(float)
    p = rows["vicon_position"][ok].astype(float)
    q = rows["vicon_quaternion"][ok].astype(float)
    t, first = np.unique(t, return_index=True)
    p, q = p[first], q[first]
    norm = np.linalg.norm(q, axis=1)
    good = norm > 0.5
    t, p, q = t[good], p[good], q[good] / norm[good, None]
    if len(q) > 1:  # q and -q are one attitude: keep the sign continuous
        flips = np.concatenate([[False], np.sum(q[1:] * q[:-1], axis=1) < 0])
        sign = np.where(np.cumsum(flips) % 2 == 1, -1.0, 1.0)
        q = q * sign[:, None]
    return t, p, q


def _build_grid(log: FlightLog, h: float, g: FloatArray, gravity: float) -> _Grid:
    """Vicon on a uniform grid of step ``h`` [s] per run without gaps, and the references.

    Per grid sample ``k`` the body rate is the rotation from ``q[k-1]`` to ``q[k+1]`` over
    ``2 h`` and the specific force ``R(q[k])^T (P[k+1] - 2 P[k] + P[k-1]) / h^2 - g e3``:
    both before any smoothing, so the Gaussian ``g`` then smooths the references exactly
    as it smooths the counts (a linear filter on each, whatever the attitude does).
    """
    t, p, q = _vicon(log)
    length = len(g) + 2  # the references need one more sample on each side
    breaks = np.flatnonzero(np.diff(t) > 2.5 * h) + 1
    row_t = log.rows["t"].astype(float)
    grid = _Grid([], [], [], [])
    for lo, hi in zip(np.r_[0, breaks], np.r_[breaks, len(t)], strict=True):
        if hi - lo < 3 or t[hi - 1] - t[lo] < length * h:
            continue
        tg = t[lo] + h * np.arange(math.floor(float(t[hi - 1] - t[lo]) / h) + 1)
        pg = np.column_stack([np.interp(tg, t[lo:hi], p[lo:hi, j]) for j in range(3)])
        qg = np.column_stack([np.interp(tg, t[lo:hi], q[lo:hi, j]) for j in range(4)])
        qg /= np.linalg.norm(qg, axis=1)[:, None]
        omega = _body_increment(qg[:-2], qg[2:]) / (2.0 * h)
        acc = (pg[2:] - 2.0 * pg[1:-1] + pg[:-2]) / (h * h)
        acc[:, 2] -= gravity
        force = _earth_to_body(qg[1:-1], acc)
        j = np.clip(np.searchsorted(row_t, tg, side="right") - 1, 0, len(row_t) - 1)
        air = log.airborne[j] & (tg >= row_t[0])
        grid.t.append(tg)
        grid.omega.append(_smooth(omega, g))
        grid.force.append(_smooth(force, g))
        grid.air.append(_window_all(air, length))
    return grid


# --------------------------------------------------------------------------- the fit
@dataclass
class _Counts:
    """The IMU's unique samples: receive times and (n, 6) raw counts (gyro, acc)."""

    t: FloatArray
    counts: FloatArray
    max_gap: float

    def at(self, tg: FloatArray, lag: float, k0: FloatArray) -> tuple[FloatArray, BoolArray]:
        """Smoothed counts (n - len(k0) + 1, 6) at ``tg + lag`` and where the whole window
        lies within continuous IMU data."""
        x = tg + lag
        raw = np.column_stack([np.interp(x, self.t, self.counts[:, j]) for j in range(6)])
        i = np.searchsorted(self.t, x, side="right")
        inside = (i > 0) & (i < len(self.t))
        ic = np.clip(i, 1, len(self.t) - 1)
        ok = inside & (self.t[ic] - self.t[ic - 1] <= self.max_gap)
        return _smooth(raw, k0), _window_all(ok, len(k0))


def _ols(x: FloatArray, y: FloatArray) -> tuple[float, float, float, float]:
    """``y = k x + c``: (k, c, R^2, RMS residual)."""
    xm, ym = float(np.mean(x)), float(np.mean(y))
    dx, dy = x - xm, y - ym
    sxx = float(dx @ dx)
    k = float(dx @ dy) / sxx if sxx > 0 else math.nan
    c = ym - k * xm
    r = dy - k * dx
    syy = float(dy @ dy)
    rss = float(r @ r)
    return k, c, (1.0 - rss / syy) if syy > 0 else 0.0, math.sqrt(rss / len(x))


def _block_bootstrap_ci(x: FloatArray, y: FloatArray, block: int, draws: int,
                        seed: int = 0) -> tuple[float, float]:
    """95 % percentile interval of the OLS slope under a moving-block bootstrap."""
    n = len(x)
    block = max(1, min(block, n // 2))
    starts = np.arange(0, n - block + 1)
    nb = max(1, n // block)
    rng = np.random.default_rng(seed)
    cx = np.concatenate([[0.0], np.cumsum(x)])
    cy = np.concatenate([[0.0], np.cumsum(y)])
    cxx = np.concatenate([[0.0], np.cumsum(x * x)])
    cxy = np.concatenate([[0.0], np.cumsum(x * y)])
    pick = rng.choice(starts, size=(draws, nb))

    def total(c: FloatArray) -> FloatArray:
        out: FloatArray = np.sum(c[pick + block] - c[pick], axis=1)
        return out

    m = nb * block
    sx, sy, sxx, sxy = total(cx), total(cy), total(cxx), total(cxy)
    slope = (sxy - sx * sy / m) / (sxx - sx * sx / m)
    lo, hi = np.percentile(slope, [2.5, 97.5])
    return float(lo), float(hi)


def identify_scales(
    log_dir: str | Path,
    *,
    axes: Sequence[ScaleAxis] = SCALE_AXES,
    smoothing_s: float = 0.05,
    max_lag_s: float = 0.15,
    min_samples: int = 500,
    min_rate_std: float = 0.03,
    min_force_std: float = 0.1,
    max_rel_ci: float = 0.05,
    min_vicon_rate_hz: float = 40.0,
    min_height_m: float = 0.05,
    bootstrap: int = 2000,
) -> ScaleFit:
    """Identify gyro and accelerometer scales against Vicon (see the module docstring).

    log_dir : the flight directory
    axes : which of :data:`SCALE_AXES` to fit (each must be excited); the others keep the
        configured scale. The accelerometer's x and y are not excited in flight: leave
        them out unless the log has them (a bench test)
    smoothing_s : standard deviation of the Gaussian smoothing [s]
    max_lag_s : largest IMU-to-Vicon lag searched [s], both signs
    min_samples : fewest grid points per axis; min_rate_std [rad/s], min_force_std
        [m/s^2] : least standard deviation of the reference (the excitation)
    max_rel_ci : widest 95 % interval of a scale accepted, half-width as a fraction of it
    min_vicon_rate_hz : slowest Vicon rate accepted [Hz] (differentiating needs a rate)
    min_height_m : height above the floor [m] from which the vehicle counts as airborne
    bootstrap : bootstrap resamples for the intervals

    Raises IdentificationError (a GroundStationError) naming the axis when the log has
    too little Vicon or excitation for it, or when it is not a flight log.
    """
    unknown = [a for a in axes if a not in SCALE_AXES]
    if unknown or not axes:
        raise IdentificationError(f"axes must be some of {', '.join(SCALE_AXES)}; "
                                  f"got {list(axes)}")
    log = load_flight_log(log_dir, min_height_m=min_height_m)
    where = str(log.path)
    tv, _, _ = _vicon(log)
    if len(tv) < 50:
        raise IdentificationError(f"{where}: only {len(tv)} Vicon poses in the log: the "
                                  f"scales are identified against Vicon")
    h = float(np.median(np.diff(tv)))
    rate = 1.0 / h if h > 0 else math.inf
    if not rate >= min_vicon_rate_hz:
        raise IdentificationError(f"{where}: Vicon poses at {rate:.1f} Hz, at least "
                                  f"{min_vicon_rate_hz:g} Hz needed to differentiate them")
    g = _kernel(smoothing_s / h)
    k0 = np.concatenate([[0.0], g, [0.0]])  # the counts' smoothing, aligned with the grid's
    vehicle = log.config.vehicle
    grid = _build_grid(log, h, g, vehicle.gravity)
    imu_t = log.rows["imu_t"][log.imu].astype(float)
    counts = np.column_stack([log.rows["gyro_counts"][log.imu],
                              log.rows["acc_counts"][log.imu]]).astype(float)
    source = _Counts(imu_t, counts, 1.5 * log.data_period_s)
    zero = np.array(list(vehicle.gyro_zero) + list(vehicle.acc_zero), dtype=float)
    wanted = [SCALE_AXES.index(a) for a in axes]

    def gather(lag: float) -> tuple[FloatArray, FloatArray]:
        xs, ys = [], []
        for tg, om, fo, air in zip(grid.t, grid.omega, grid.force, grid.air, strict=True):
            sm, ok = source.at(tg, lag, k0)
            use = ok & air
            xs.append(sm[use] - zero)
            ys.append(np.column_stack([om, fo])[use])
        if not xs:
            return np.empty((0, 6)), np.empty((0, 6))
        return np.concatenate(xs), np.concatenate(ys)

    def score(lag: float) -> float:
        x, y = gather(lag)
        if len(x) < 10:
            return -math.inf
        return sum(_ols(x[:, j], y[:, j])[2] for j in wanted)

    lags = np.arange(-max_lag_s, max_lag_s + 1e-12, h / 2.0)
    scores = np.array([score(float(lag)) for lag in lags])
    if not np.any(np.isfinite(scores)):
        raise IdentificationError(f"{where}: no airborne stretch with Vicon and IMU data "
                                  f"of at least {len(k0) * h:.2f} s")
    b = int(np.argmax(scores))
    lag = float(lags[b])
    if 0 < b < len(lags) - 1 and np.all(np.isfinite(scores[b - 1:b + 2])):
        s0, s1, s2 = scores[b - 1:b + 2]
        den = s0 - 2.0 * s1 + s2
        if den < 0:
            lag += float(0.5 * (s0 - s2) / den) * (h / 2.0)
    x, y = gather(lag)
    block = max(len(k0), round(1.0 / h))
    fits: list[AxisScaleFit] = []
    for j in wanted:
        fits.append(_fit_axis(where, SCALE_AXES[j], x[:, j], y[:, j], zero[j],
                              _configured(log, j), min_samples,
                              min_rate_std if j < 3 else min_force_std, max_rel_ci,
                              block, bootstrap))
    by_axis = {f.axis: f.scale for f in fits}
    scale = [by_axis.get(a, _configured(log, i)) for i, a in enumerate(SCALE_AXES)]
    return ScaleFit(fits=tuple(fits), gyro_scale=(scale[0], scale[1], scale[2]),
                    acc_scale=(scale[3], scale[4], scale[5]), lag_s=lag,
                    smoothing_s=smoothing_s, vicon_rate_hz=rate, source=log.path)


def _configured(log: FlightLog, j: int) -> float:
    v = log.config.vehicle
    return float((list(v.gyro_scale) + list(v.acc_scale))[j])


def _fit_axis(where: str, axis: ScaleAxis, x: FloatArray, y: FloatArray, zero: float,
              configured: float, min_samples: int, min_std: float, max_rel_ci: float,
              block: int, draws: int) -> AxisScaleFit:
    sensor = axis.split("_")[0]
    unit = _UNIT[sensor]
    n = len(x)
    if n < min_samples:
        raise IdentificationError(
            f"{where}: {axis}: only {n} points with Vicon and IMU while airborne (at least "
            f"{min_samples} needed): fly longer with Vicon tracking: {SYSID_HINT}")
    ref_std = float(np.std(y))
    if ref_std < min_std:
        hint = (" (a quadrotor's rotors push only along body z: the accelerometer's x and y "
                "are not excited in flight; calibrate them on the bench and leave them out "
                "with axes=...)" if axis in ("acc_x", "acc_y") else
                f": {SYSID_HINT}")
        raise IdentificationError(
            f"{where}: {axis}: too little excitation: the Vicon reference varies by "
            f"{ref_std:.3f} {unit} (standard deviation; at least {min_std:g} needed){hint}")
    k, c, r2, rms = _ols(x, y)
    lo, hi = _block_bootstrap_ci(x, y, block, draws)
    if not (k != 0 and max(hi - k, k - lo) <= max_rel_ci * abs(k)):
        raise IdentificationError(
            f"{where}: {axis}: too little excitation to determine the scale: K = {k:.4e} "
            f"{unit}/count with a 95 % interval [{lo:.4e}, {hi:.4e}], wider than "
            f"+-{100 * max_rel_ci:g} %")
    return AxisScaleFit(axis=axis, sensor=sensor, unit=unit, scale=k, scale_ci=(lo, hi),
                        configured=configured, offset=c, zero_estimate=zero - c / k,
                        r2=r2, rms_residual=rms, reference_std=ref_std, samples=n,
                        counts=x, reference=y)
