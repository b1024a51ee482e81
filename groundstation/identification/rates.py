"""Rate-loop identification from a flight log: gain, transport delay and time constant.

The thesis identified the stick-to-rate gains "with a time delay" (Ch. 3.3.1, eq.
3.22: ``omega = K u``) and showed the on-board rate loop's step response (Fig. 3.8);
the model flies it as a first-order lag behind a delayed set point::

    d omega / dt = (K u(t - D) - omega) / tau          (per body axis)

with ``u`` the stick the vehicle applies [RC units], ``omega`` the body rate [rad/s],
``K`` [rad/s per RC unit], ``tau`` [s] and ``D`` [s] the delay from the ground station
writing a COMMAND to the gyro sample showing its effect arriving back. Roll stick ->
omega_x, pitch stick -> omega_y, yaw stick -> omega_z (FRD body axes).

Method (an output-error fit, exact for the model above):

* The stick in force at the vehicle is the last COMMAND sent (``cmd_sent`` rows at their
  tick time ``t``, the value held until the next send: zero-order hold), delayed by
  ``D``. Only IMU samples while the vehicle is airborne (states TAKEOFF/TRACK/HOLD/LAND
  and above the floor) and while every COMMAND that can be in force has the axis's
  ``cmd_mask`` bit set (and comes within the vehicle's watchdog of the previous one) are
  used, and, when the log has the vehicle's STATUS, only samples whose DATA frame says
  the vehicle applies our command on that axis (``vehicle_mask``); they form segments of
  consecutive samples (a dropped DATA frame or a gap ends a segment). Sample times are
  the receive times ``imu_t``, regularised per segment by a straight line through them
  (the vehicle samples on its own regular clock; the line removes receive jitter).
* For a trial ``(D, tau)`` the lag is integrated exactly over each sample interval
  with the piecewise-constant delayed stick (``x_k``), so a fractional delay needs no
  interpolation; per segment ``s[k+1] = a s[k] + x_k`` with ``a = exp(-dt/tau)`` from
  ``s = 0``. The gyro then is ``K s[k] + c + z a^k``: linear in the gain ``K``, the
  gyro bias ``c`` and each segment's initial rate ``z``, which least squares solves.
  ``(D, tau)`` minimise the residual: a grid, then Nelder-Mead. (The discrete form
  ``omega[k+1] = a omega[k] + b u[k - n] + c`` with ``K = b / (1 - a)``,
  ``tau = -dt / ln a`` is the special case of a delay of whole samples; an equation-error
  fit of it would weigh the gyro noise into ``a``, the output-error fit does not.)
* 95 % confidence intervals from the Gauss-Newton covariance of all parameters
  (``s^2 (J^T J)^-1``), inflated by ``(1 + rho) / (1 - rho)`` for the lag-1
  autocorrelation ``rho`` of the residuals (fewer independent samples than rows);
  ``tau``'s interval is taken on ``ln tau`` so it stays positive.
* The delay reported as ``delay_s`` is the configuration's
  ``vehicle.command_delay_s``: ``D`` less the frames' time on the serial wire
  (:func:`groundstation.asctec.dialect.wire_time_s`), which the model adds back
  (:func:`groundstation.flight.assembly.vehicle_model`). It still holds the ground
  station's compute time (a tick's COMMAND is written after its ``t``) and the
  vehicle's loop period (the virtual lab applies a command at its next 2 ms step).

The gain is relative to the gyro as the log's configuration scales it
(``vehicle.gyro_scale``): a gyro scale error is a gain error of the same size. Pass
``gyro_scale`` (e.g. from :func:`groundstation.identification.identify_scales`) to
rescale the raw counts first.

This module also holds the flight-log reading shared with
:mod:`groundstation.identification.scales` (:func:`load_flight_log`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np
import numpy.typing as npt
import yaml

from groundstation.app.recorder import read_flight
from groundstation.asctec.dialect import wire_time_s
from groundstation.config import GroundStationConfig, validate_config
from groundstation.errors import ConfigError, IdentificationError, RecorderError
from groundstation.flight.assembly import link_params
from groundstation.flight.supervisor import AIRBORNE, State
from groundstation.types import FloatArray

__all__ = [
    "AXES",
    "AxisRateFit",
    "FlightLog",
    "RateFit",
    "RateSeries",
    "identify_rates",
    "load_flight_log",
]

BoolArray = npt.NDArray[np.bool_]
IntArray = npt.NDArray[np.intp]

Axis = Literal["roll", "pitch", "yaw"]
AXES: tuple[Axis, ...] = ("roll", "pitch", "yaw")
"""The rate axes, in body-axis order: roll -> omega_x, pitch -> omega_y, yaw -> omega_z."""

_STICK_COLUMN = {"roll": "cmd_roll", "pitch": "cmd_pitch", "yaw": "cmd_yaw"}
_MASK_BIT = {"pitch": 0, "roll": 1, "yaw": 2}  # the spec's ctrl mask (bit0 pitch ... bit3 thrust)
_BODY_INDEX = {"roll": 0, "pitch": 1, "yaw": 2}
_Z95 = 1.959963984540054  # two-sided 95 % normal quantile
SYSID_HINT = ("fly the identification flight, gs fly --trajectory sysid (doublets on every "
              "rate stick, climbs and descents: its log passes every gs identify)")
"""What a refusal for want of excitation recommends: the one flight that is known to
excite every axis (square and figure-eight flown by lqr-ff move the sticks by a few tens
of RC units; tests/test_identification_flight.py identifies from the sysid log)."""


# --------------------------------------------------------------------------- the log
@dataclass(frozen=True, eq=False)
class FlightLog:
    """A flight log read for identification.

    path : the flight directory
    rows : (N,) the recorder's rows (:data:`groundstation.app.recorder.RECORD_DTYPE`)
    meta : meta.json; config : the configuration the flight flew with (config.yaml)
    airborne : (N,) the row's supervisor state is TAKEOFF/TRACK/HOLD/LAND *and* the
        estimated height above the floor (the estimate's z before take-off) is at least
        the ``min_height_m`` it was read with: off the floor, not merely commanded to be
    imu : (M,) indices of the rows where a new IMU sample first appears (a stalled stream
        repeats the last sample; those repeats are left out)
    """

    path: Path
    rows: npt.NDArray[np.void]
    meta: dict[str, Any]
    config: GroundStationConfig
    airborne: BoolArray
    imu: IntArray

    @property
    def data_period_s(self) -> float:
        """The configured DATA (IMU) period [s]."""
        return self.config.serial.data_period_ms / 1000.0


def _airborne_states(meta: dict[str, Any]) -> set[int]:
    """Row ``state`` values of the airborne states, by name when meta.json lists them."""
    names = meta.get("supervisor_states")
    airborne = {s.name for s in AIRBORNE}
    if isinstance(names, list) and all(isinstance(n, str) for n in names):
        return {i for i, n in enumerate(names) if n in airborne}
    return {int(s) for s in AIRBORNE}


def load_flight_log(log_dir: str | Path, *, min_height_m: float = 0.05) -> FlightLog:
    """Read a flight log and its configuration for identification.

    log_dir : the flight directory (or its flight.npy)
    min_height_m : height above the floor [m] from which a row counts as airborne
    Raises IdentificationError if it is not a readable flight log, its configuration
    does not validate, or it holds no IMU sample.
    """
    path = Path(log_dir)
    try:
        rows, meta, config_text = read_flight(path)
    except RecorderError as exc:
        raise IdentificationError(f"{path}: not a flight log: {exc}") from exc
    if meta.get("format") != "groundstation flight log":
        raise IdentificationError(f"{path}: not a flight log (meta.json format "
                                  f"{meta.get('format')!r})")
    try:
        config = validate_config(yaml.safe_load(config_text), f"{path}/config.yaml")
    except (ConfigError, yaml.YAMLError) as exc:
        raise IdentificationError(f"{path}: the flight's configuration does not "
                                  f"validate: {exc}") from exc
    if len(rows) == 0:
        raise IdentificationError(f"{path}: the flight log has no rows")
    state = rows["state"].astype(int)
    est_z = rows["est_position"][:, 2]
    pre = (state == int(State.PREFLIGHT)) & np.isfinite(est_z)
    floor_z = float(np.median(est_z[pre])) if np.any(pre) else 0.0
    with np.errstate(invalid="ignore"):
        high = (floor_z - est_z) >= min_height_m  # NED: z up is negative; NaN -> False
    airborne = np.isin(state, sorted(_airborne_states(meta))) & high
    imu_t = rows["imu_t"]
    new = np.isfinite(imu_t)
    new[1:] &= imu_t[1:] != imu_t[:-1]
    imu = np.flatnonzero(new)
    if len(imu) < 2:
        raise IdentificationError(f"{path}: the flight log holds no IMU samples")
    return FlightLog(path, rows, meta, config, airborne, imu)


# --------------------------------------------------------------------------- results
@dataclass(frozen=True)
class RateSeries:
    """The samples one axis was fitted on, for plots: per segment, concatenated.

    t : (n,) sample times [s] (the log's clock; NaN rows separate segments)
    measured : (n,) gyro [rad/s]; model : (n,) the fitted model's simulated rate [rad/s]
    (bias included); stick : (n,) the stick in force at the vehicle [RC units]
    """

    t: FloatArray
    measured: FloatArray
    model: FloatArray
    stick: FloatArray


@dataclass(frozen=True)
class AxisRateFit:
    """One body axis's rate loop (thesis eq. 3.22, Fig. 3.8).

    axis : "roll", "pitch" or "yaw" (body x, y, z)
    k_rate : stick-to-rate gain K [rad/s per RC unit]; k_rate_ci : 95 % interval
    delay_s : the configuration's ``vehicle.command_delay_s`` [s] (total delay less the
        frames' wire time); delay_ci : 95 % interval
    total_delay_s : COMMAND written -> gyro sample received [s]
    tau_s : first-order time constant [s]; tau_ci : 95 % interval
    gyro_bias : the gyro's constant offset on this axis [rad/s]
    rms_residual : RMS of measured minus model [rad/s]; r2 : coefficient of determination
    samples : IMU samples fitted; segments : how many runs of consecutive samples
    stick_std : standard deviation of the stick in force [RC units]
    series : the fitted data and the model's rate (for :meth:`RateFit.figure`)
    """

    axis: Axis
    k_rate: float
    k_rate_ci: tuple[float, float]
    delay_s: float
    delay_ci: tuple[float, float]
    total_delay_s: float
    tau_s: float
    tau_ci: tuple[float, float]
    gyro_bias: float
    rms_residual: float
    r2: float
    samples: int
    segments: int
    stick_std: float
    series: RateSeries = field(repr=False, compare=False)

    def summary(self) -> str:
        """One line: gain, delay and time constant with their 95 % intervals, fit quality."""
        k, (k0, k1) = self.k_rate, self.k_rate_ci
        d, (d0, d1) = self.delay_s, self.delay_ci
        t, (t0, t1) = self.tau_s, self.tau_ci
        return (f"{self.axis:5s} K = {k:.4e} rad/s/unit [{k0:.4e}, {k1:.4e}]  "
                f"delay = {1e3 * d:5.1f} ms [{1e3 * d0:.1f}, {1e3 * d1:.1f}]  "
                f"tau = {1e3 * t:5.1f} ms [{1e3 * t0:.1f}, {1e3 * t1:.1f}]  "
                f"RMS {self.rms_residual:.4f} rad/s, R^2 {self.r2:.3f}, "
                f"{self.samples} samples")


@dataclass(frozen=True)
class RateFit:
    """Rate-loop identification of one flight (see the module docstring).

    roll, pitch, yaw : each axis's fit, None for an axis not asked for
    k_rate : (K_phi, K_theta, K_psi) [rad/s per RC unit]; an axis not fitted keeps the
        flight configuration's ``vehicle.k_rate`` value
    command_delay_s : mean of the fitted roll and pitch delays [s] (the yaw delay if
        neither was fitted)
    rate_loop_tau_s : mean of the fitted roll and pitch time constants [s] (likewise)
    wire_time_s : the frames' time on the serial wire taken off the total delay [s]
    source : the flight directory
    """

    roll: AxisRateFit | None
    pitch: AxisRateFit | None
    yaw: AxisRateFit | None
    k_rate: tuple[float, float, float]
    command_delay_s: float
    rate_loop_tau_s: float
    wire_time_s: float
    source: Path

    def axes(self) -> list[AxisRateFit]:
        """The fitted axes, in roll, pitch, yaw order."""
        return [a for a in (self.roll, self.pitch, self.yaw) if a is not None]

    def config_fields(self) -> dict[str, float | list[float]]:
        """The identified values keyed by configuration field path:
        ``{"vehicle.k_rate": [3 floats], "vehicle.command_delay_s": float,
        "vehicle.rate_loop_tau_s": float}`` (ready for ``apply_overrides``; a delay below
        the wire time, which the configuration cannot hold, is given as 0)."""
        return {"vehicle.k_rate": [float(k) for k in self.k_rate],
                "vehicle.command_delay_s": max(0.0, float(self.command_delay_s)),
                "vehicle.rate_loop_tau_s": float(self.rate_loop_tau_s)}

    def summary(self) -> str:
        """Several lines: each axis with 95 % intervals, then the configuration values."""
        lines = [f"rate loop identified from {self.source}",
                 "  (delay: COMMAND to vehicle, less "
                 f"{1e3 * self.wire_time_s:.1f} ms of frames on the serial wire)"]
        lines += ["  " + a.summary() for a in self.axes()]
        k = ", ".join(f"{v:.4e}" for v in self.k_rate)
        lines += [f"  vehicle.k_rate: [{k}]  # rad/s per RC unit",
                  f"  vehicle.command_delay_s: {self.command_delay_s:.4f}  # s",
                  f"  vehicle.rate_loop_tau_s: {self.rate_loop_tau_s:.4f}  # s"]
        return "\n".join(lines)

    def figure(self, path: str | Path) -> Path:
        """Write a PNG: per fitted axis the measured gyro and the fitted model's simulated
        rate against time, and the residual. Needs matplotlib (GroundStationError naming
        ``pip install 'groundstation[plot]'`` without it)."""
        from groundstation.evaluation.plotting import pyplot, save

        plt = pyplot()
        fits = self.axes()
        fig, axes = plt.subplots(len(fits), 1, figsize=(11, 3.2 * len(fits)), squeeze=False)
        for ax, fit in zip(axes[:, 0], fits, strict=True):
            s = fit.series
            t0 = float(np.nanmin(s.t))
            ax.plot(s.t - t0, s.measured, color="C0", lw=0.7, label="gyro")
            ax.plot(s.t - t0, s.model, color="C1", lw=1.0, label="model (simulated)")
            ax.plot(s.t - t0, s.measured - s.model, color="0.5", lw=0.5, label="residual")
            ax.set_ylabel(f"{fit.axis} rate [rad/s]")
            ax.set_title(f"{fit.axis}: K = {fit.k_rate:.3e} rad/s/unit, "
                         f"delay {1e3 * fit.delay_s:.1f} ms, tau {1e3 * fit.tau_s:.1f} ms, "
                         f"R^2 {fit.r2:.3f}", fontsize=9)
            ax.grid(alpha=0.3)
            ax.legend(loc="upper right", fontsize=8)
        axes[-1, 0].set_xlabel("time from the first fitted sample [s]")
        out = Path(path)
        return save(fig, out)


# --------------------------------------------------------------------------- the fit
@dataclass(frozen=True)
class _Segment:
    """Samples ``lo..hi-1`` of the axis's arrays; ``dt`` their regularised interval [s]."""

    lo: int
    hi: int
    dt: float


@dataclass
class _Problem:
    """The data of one axis: sample times, gyro, segments, and the commands."""

    t: FloatArray  # (n,) regularised sample times [s]
    y: FloatArray  # (n,) gyro [rad/s]
    segments: list[_Segment]
    send_t: FloatArray  # (m,) COMMAND write times [s]
    send_u: FloatArray  # (m,) the axis's stick in those COMMANDs [RC units]
    t0: FloatArray  # (n - S,) interval starts (all segments, concatenated)
    t1: FloatArray  # interval ends

    def model(self, delay: float, tau: float) -> tuple[FloatArray, FloatArray]:
        """Unit-gain lag response ``s`` (n,) and the free responses (n, S) for (D, tau)."""
        x = _lag_inputs(self.t0, self.t1, self.send_t + delay, self.send_u, tau)
        s = np.empty_like(self.y)
        free = np.zeros((len(self.y), len(self.segments)))
        start = 0
        for j, seg in enumerate(self.segments):
            n = seg.hi - seg.lo
            a = math.exp(-seg.dt / tau)
            xs = x[start:start + n - 1]
            start += n - 1
            s[seg.lo] = 0.0
            s[seg.lo + 1:seg.hi] = _first_order(a, xs)
            free[seg.lo:seg.hi, j] = a ** np.arange(n, dtype=float)
        return s, free

    def solve(self, delay: float, tau: float) -> tuple[float, FloatArray, FloatArray, FloatArray]:
        """Least squares at (D, tau): (RSS, theta = [K, c, z...], design, prediction)."""
        s, free = self.model(delay, tau)
        design: FloatArray = np.column_stack([s, np.ones_like(s), free])
        theta: FloatArray = np.asarray(np.linalg.lstsq(design, self.y, rcond=None)[0], dtype=float)
        pred: FloatArray = design @ theta
        r = self.y - pred
        return float(r @ r), theta, design, pred


def _first_order(a: float, x: FloatArray) -> FloatArray:
    """``s[k] = a s[k-1] + x[k-1]`` from ``s = 0`` before the first: the (len(x),) values
    ``s[1..]`` (scipy's lfilter: a C loop)."""
    from scipy.signal import lfilter

    return np.asarray(lfilter([1.0], [1.0, -a], x), dtype=float)


def _lag_inputs(t0: FloatArray, t1: FloatArray, breaks: FloatArray, values: FloatArray,
                tau: float) -> FloatArray:
    """Exact input of a unit-gain first-order lag over each interval ``[t0, t1]``.

    The input is ``values[j]`` on ``[breaks[j], breaks[j+1])`` (zero-order hold); returns
    ``x = int_t0^t1 exp(-(t1 - s)/tau) / tau * u(s) ds`` so that a lag at ``w(t0)`` is at
    ``exp(-(t1 - t0)/tau) w(t0) + x`` at ``t1``. Every ``t0`` must be at or after
    ``breaks[0]``.
    """
    j0 = np.searchsorted(breaks, t0, side="right") - 1
    j1 = np.searchsorted(breaks, t1, side="right") - 1
    x = np.zeros_like(t0)
    last = len(breaks) - 1
    for r in range(int(np.max(j1 - j0)) + 1):
        j = j0 + r
        active = j <= j1
        jc = np.minimum(j, last)
        lo = np.where(r == 0, t0, breaks[jc])
        nxt = np.minimum(jc + 1, last)
        hi = np.where(j + 1 <= j1, breaks[nxt], t1)
        w = np.exp(-(t1 - hi) / tau) - np.exp(-(t1 - lo) / tau)
        x += np.where(active, values[jc] * w, 0.0)
    return x


def _command_ok(log: FlightLog, axis: Axis) -> tuple[FloatArray, FloatArray, FloatArray]:
    """The COMMANDs sent: (write times [s], the axis's stick, cumulative count of sends
    that cannot be trusted: axis bit clear, or the next send later than the watchdog)."""
    rows = log.rows
    sent = np.flatnonzero(rows["cmd_sent"])
    t = rows["t"][sent].astype(float)
    u = rows[_STICK_COLUMN[axis]][sent].astype(float)
    bit = (rows["cmd_mask"][sent].astype(int) >> _MASK_BIT[axis]) & 1 == 1
    serial = log.config.serial  # the X-3D's watchdog is the spec's 100 ms
    watchdog = serial.ll.fallback_ms / 1000.0 if serial.protocol == "asctec-ll" else 0.1
    gap_ok = np.ones(len(t), dtype=bool)
    gap_ok[:-1] = np.diff(t) <= watchdog
    bad = ~(bit & gap_ok)
    return t, u, np.concatenate([[0.0], np.cumsum(bad, dtype=float)])


def _problem(log: FlightLog, axis: Axis, gyro: FloatArray, max_delay_s: float,
             min_segment: int) -> _Problem:
    """Select the axis's usable samples and cut them into segments (module docstring)."""
    period = log.data_period_s
    idx = log.imu
    t = log.rows["imu_t"][idx].astype(float)
    y = gyro[:, _BODY_INDEX[axis]]
    air = log.airborne[idx]
    send_t, send_u, bad_cum = _command_ok(log, axis)
    n = len(t)
    # interval k = [t[k], t[k+1]] is usable if both ends are airborne, it is one DATA
    # period long, and every COMMAND in force over [t[k] - max_delay, t[k+1]] is trusted
    dt = np.diff(t)
    ok = air[:-1] & air[1:] & (dt > 0.5 * period) & (dt < 1.5 * period)
    # and, when the log has the vehicle's STATUS, the vehicle says it applied our command
    # on this axis in the DATA frames of both samples
    mask = log.rows["vehicle_mask"]
    if np.any(mask != 0):
        applied = (mask[idx].astype(int) >> _MASK_BIT[axis]) & 1 == 1
        ok &= applied[:-1] & applied[1:]
    first = np.searchsorted(send_t, t[:-1] - max_delay_s, side="right") - 1
    last = np.searchsorted(send_t, t[1:], side="right") - 1
    has = first >= 0
    firstc = np.maximum(first, 0)
    n_bad = bad_cum[last + 1] - bad_cum[firstc]
    ok &= has & (n_bad == 0)
    segments: list[_Segment] = []
    keep_t: list[FloatArray] = []
    keep_y: list[FloatArray] = []
    pos = 0
    k = 0
    while k < n - 1:
        if not ok[k]:
            k += 1
            continue
        start = k
        while k < n - 1 and ok[k]:
            k += 1
        lo, hi = start, k + 1  # samples lo..hi-1
        if hi - lo >= min_segment:
            ts = t[lo:hi]
            i = np.arange(hi - lo, dtype=float)
            slope, offset = np.polyfit(i, ts, 1)  # the vehicle's regular sample clock
            keep_t.append(offset + slope * i)
            keep_y.append(y[lo:hi])
            segments.append(_Segment(pos, pos + hi - lo, float(slope)))
            pos += hi - lo
    if not segments:
        return _Problem(np.empty(0), np.empty(0), [], send_t, send_u, np.empty(0),
                        np.empty(0))
    tt = np.concatenate(keep_t)
    yy = np.concatenate(keep_y)
    t0 = np.concatenate([tt[s.lo:s.hi - 1] for s in segments])
    t1 = np.concatenate([tt[s.lo + 1:s.hi] for s in segments])
    return _Problem(tt, yy, segments, send_t, send_u, t0, t1)


def _stick_in_force(p: _Problem, delay: float) -> FloatArray:
    """The stick at the vehicle at each sample time [RC units] for total delay ``delay``."""
    j = np.searchsorted(p.send_t + delay, p.t, side="right") - 1
    return p.send_u[np.maximum(j, 0)]


def _lag1_autocorrelation(r: FloatArray, segments: list[_Segment]) -> float:
    """Lag-1 autocorrelation of the residuals, within segments."""
    num = 0.0
    den = 0.0
    for s in segments:
        e = r[s.lo:s.hi]
        num += float(e[1:] @ e[:-1])
        den += float(e @ e)
    return num / den if den > 0 else 0.0


def _fit_axis(p: _Problem, max_delay_s: float, tau_bounds: tuple[float, float]
              ) -> tuple[float, float, FloatArray, FloatArray, FloatArray]:
    """Minimise the residual over (D, tau); returns (D, tau, theta, cov of
    [D, ln tau, K, c, z...], prediction)."""
    from scipy.optimize import minimize

    period = float(np.median([s.dt for s in p.segments]))
    tau_lo, tau_hi = tau_bounds
    delays = np.arange(0.0, max_delay_s + 1e-12, period / 2.0)
    taus = np.geomspace(tau_lo, tau_hi, 12)
    rss = np.array([[p.solve(d, tau)[0] for tau in taus] for d in delays])
    i, j = np.unravel_index(int(np.argmin(rss)), rss.shape)

    def cost(v: FloatArray) -> float:
        d = float(np.clip(v[0], 0.0, max_delay_s))
        tau = float(np.exp(np.clip(v[1], math.log(tau_lo), math.log(tau_hi))))
        return p.solve(d, tau)[0]

    res = minimize(cost, np.array([delays[i], math.log(taus[j])]), method="Nelder-Mead",
                   options={"xatol": 1e-5, "fatol": 1e-9 * float(rss[i, j]), "maxiter": 400,
                            "initial_simplex": np.array([
                                [delays[i], math.log(taus[j])],
                                [delays[i] + period / 4.0, math.log(taus[j])],
                                [delays[i], math.log(taus[j]) + 0.2]])})
    d = float(np.clip(res.x[0], 0.0, max_delay_s))
    tau = float(np.exp(np.clip(res.x[1], math.log(tau_lo), math.log(tau_hi))))
    rss_opt, theta, design, pred = p.solve(d, tau)
    # Gauss-Newton covariance of all parameters: prediction derivatives in D and ln tau
    # at fixed linear parameters, the design columns for the linear ones
    def predict(dd: float, tt: float) -> FloatArray:
        s, free = p.model(dd, tt)
        out: FloatArray = np.column_stack([s, np.ones_like(s), free]) @ theta
        return out

    hd = 5e-4
    jd = (predict(d + hd, tau) - predict(max(d - hd, 0.0), tau)) / (d + hd - max(d - hd, 0.0))
    hl = 1e-3
    jl = (predict(d, tau * math.exp(hl)) - predict(d, tau * math.exp(-hl))) / (2 * hl)
    jac = np.column_stack([jd, jl, design])
    n, k = jac.shape
    resid = p.y - pred
    s2 = rss_opt / max(n - k, 1)
    rho = max(0.0, _lag1_autocorrelation(resid, p.segments))
    inflate = (1.0 + rho) / (1.0 - rho) if rho < 0.99 else 199.0
    cov = s2 * inflate * np.linalg.pinv(jac.T @ jac)
    return d, tau, theta, cov, pred


def _ci(value: float, sigma: float) -> tuple[float, float]:
    return (value - _Z95 * sigma, value + _Z95 * sigma)


def identify_rates(
    log_dir: str | Path,
    *,
    axes: Sequence[Axis] = AXES,
    gyro_scale: Sequence[float] | None = None,
    max_delay_s: float = 0.2,
    tau_bounds_s: tuple[float, float] = (0.005, 1.0),
    min_samples: int = 500,
    min_stick_std: float = 30.0,
    max_k_rel_ci: float = 0.1,
    min_height_m: float = 0.05,
    min_segment: int = 25,
) -> RateFit:
    """Identify the rate loop of each axis from a flight log (see the module docstring).

    log_dir : the flight directory
    axes : which of "roll", "pitch", "yaw" to fit (each must be excited); the others
        keep the configured gain
    gyro_scale : (3,) gyro scale [rad/s per count] to rescale the raw ``gyro_counts``
        with (the configuration's zero stays); None uses the logged ``gyro`` [rad/s]
    max_delay_s : longest total delay searched [s]; tau_bounds_s : (min, max) time
        constant searched [s]
    min_samples : fewest usable IMU samples per axis; min_stick_std : least standard
        deviation of the stick in force [RC units]; max_k_rel_ci : widest 95 % interval
        of the gain accepted, as a fraction of the gain (half-width)
    min_height_m : height above the floor [m] from which the vehicle counts as airborne
    min_segment : shortest run of consecutive usable samples kept

    Raises IdentificationError (a GroundStationError) naming the axis when the log has
    too little usable data or excitation on it, or when it is not a flight log.
    """
    unknown = [a for a in axes if a not in AXES]
    if unknown or not axes:
        raise IdentificationError(f"axes must be some of {', '.join(AXES)}; got {list(axes)}")
    log = load_flight_log(log_dir, min_height_m=min_height_m)
    if gyro_scale is None:
        gyro = log.rows["gyro"][log.imu].astype(float)
    else:
        scale = np.asarray(gyro_scale, dtype=float)
        if scale.shape != (3,) or not np.all(np.isfinite(scale)) or np.any(scale == 0):
            raise IdentificationError(f"gyro_scale must be three finite non-zero values, "
                                      f"got {list(gyro_scale)}")
        zero = np.asarray(log.config.vehicle.gyro_zero, dtype=float)
        gyro = scale * (log.rows["gyro_counts"][log.imu].astype(float) - zero)
    wire = wire_time_s(link_params(log.config.serial))
    fits: dict[str, AxisRateFit] = {}
    for axis in AXES:
        if axis in axes:
            fits[axis] = _identify_axis(log, axis, gyro, wire, max_delay_s, tau_bounds_s,
                                        min_samples, min_stick_std, max_k_rel_ci, min_segment)
    configured = log.config.vehicle.k_rate
    k = tuple(fits[a].k_rate if a in fits else float(configured[i])
              for i, a in enumerate(AXES))
    main = [fits[a] for a in ("roll", "pitch") if a in fits] or [fits["yaw"]]
    return RateFit(
        roll=fits.get("roll"), pitch=fits.get("pitch"), yaw=fits.get("yaw"),
        k_rate=(k[0], k[1], k[2]),
        command_delay_s=float(np.mean([f.delay_s for f in main])),
        rate_loop_tau_s=float(np.mean([f.tau_s for f in main])),
        wire_time_s=wire, source=log.path,
    )


def _identify_axis(log: FlightLog, axis: Axis, gyro: FloatArray, wire: float,
                   max_delay_s: float, tau_bounds: tuple[float, float], min_samples: int,
                   min_stick_std: float, max_k_rel_ci: float,
                   min_segment: int) -> AxisRateFit:
    where = f"{log.path}: {axis}"
    p = _problem(log, axis, gyro, max_delay_s, min_segment)
    n = len(p.y)
    if n < min_samples:
        raise IdentificationError(
            f"{where}: only {n} usable IMU samples (at least {min_samples} needed): the "
            f"vehicle must be airborne with the {axis} channel commanded by the ground "
            f"station (cmd_mask bit {_MASK_BIT[axis]}) for longer: {SYSID_HINT}")
    u_now = _stick_in_force(p, 0.0)
    stick_std = float(np.std(u_now))
    if stick_std < min_stick_std:
        raise IdentificationError(
            f"{where}: too little excitation: the {axis} stick varies by "
            f"{stick_std:.1f} RC units (standard deviation; at least {min_stick_std:g} "
            f"needed): {SYSID_HINT}")
    d, tau, theta, cov, pred = _fit_axis(p, max_delay_s, tau_bounds)
    k_rate, bias = float(theta[0]), float(theta[1])
    sd = np.sqrt(np.maximum(np.diag(cov), 0.0))
    k_ci = _ci(k_rate, float(sd[2]))
    if not (abs(k_rate) > 0 and _Z95 * sd[2] <= max_k_rel_ci * abs(k_rate)):
        raise IdentificationError(
            f"{where}: too little excitation to determine the gain: K = {k_rate:.3e} "
            f"rad/s/unit with a 95 % interval [{k_ci[0]:.3e}, {k_ci[1]:.3e}], wider than "
            f"+-{100 * max_k_rel_ci:g} %: {SYSID_HINT}")
    resid = p.y - pred
    rss = float(resid @ resid)
    tss = float(np.sum((p.y - np.mean(p.y)) ** 2))
    d_ci = _ci(d, float(sd[0]))
    ln_ci = _ci(math.log(tau), float(sd[1]))
    series = _series(p, pred, d)
    return AxisRateFit(
        axis=axis, k_rate=k_rate, k_rate_ci=k_ci,
        delay_s=d - wire, delay_ci=(d_ci[0] - wire, d_ci[1] - wire), total_delay_s=d,
        tau_s=tau, tau_ci=(math.exp(ln_ci[0]), math.exp(ln_ci[1])), gyro_bias=bias,
        rms_residual=math.sqrt(rss / n), r2=1.0 - rss / tss if tss > 0 else 0.0,
        samples=n, segments=len(p.segments), stick_std=stick_std, series=series,
    )


def _series(p: _Problem, pred: FloatArray, delay: float) -> RateSeries:
    """The fitted samples with a NaN row between segments (so a plot breaks there)."""
    parts: list[list[FloatArray]] = [[], [], [], []]
    stick = _stick_in_force(p, delay)
    nan = np.full(1, np.nan)
    for s in p.segments:
        for out, arr in zip(parts, (p.t, p.y, pred, stick), strict=True):
            out += [arr[s.lo:s.hi], nan]
    t, y, m, u = (np.concatenate(a) for a in parts)
    return RateSeries(t=t, measured=y, model=m, stick=u)

