"""The figure set of one logged flight (``gs report LOG``), in the spirit of PX4's Flight Review.

One PNG per topic in the report directory (:data:`FIGURES`): the overview
(flight.png), position, top view, attitude, body rates, sticks, estimator, Vicon and
link health, battery and loop timing. Every time axis is in seconds since the first
logged tick and carries the supervisor's transitions (changes of the ``state`` column,
:func:`transitions`) as vertical lines, named once per figure along its top edge.
Legends sit outside the axes on the right; figures use matplotlib's constrained layout.

Frames and units: positions NED [m] (figures in m or cm), attitudes 3-2-1 Euler
angles [deg] from scalar-first quaternions (``eCb``, body FRD), body rates FRD
[deg/s], sticks in RC units (-2048..2047, thrust 0..4096), times [s] (timing in ms).

The pure functions here (:func:`transitions`, :func:`euler_angles`,
:func:`vicon_residuals`, :func:`pose_rate`, :func:`applied_sticks`) are what the
figures draw; they take the log's columns and are tested against independent answers.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import yaml

from groundstation.config import (
    EstimatorConfig,
    SafetyConfig,
    SerialConfig,
    VehicleConfig,
    ViconConfig,
)
from groundstation.evaluation.metrics import error_norms
from groundstation.evaluation.plotting import pyplot, save
from groundstation.evaluation.record import FlightRecord
from groundstation.flight.supervisor import AIRBORNE, State
from groundstation.types import FloatArray

Rows = npt.NDArray[np.void]
"""A flight log's rows as :data:`groundstation.app.recorder.RECORD_DTYPE`."""


@dataclass(frozen=True)
class TimingTargets:
    """Daemon-side p99 targets of one control tick [ms] (None: no target of its own)."""

    compute_p99_ms: float | None
    jitter_p99_ms: float | None
    latency_p99_ms: float | None


BENCHMARK_TARGETS = TimingTargets(compute_p99_ms=None, jitter_p99_ms=1.0, latency_p99_ms=2.0)
"""The real-time benchmark's daemon-side targets, drawn on ``timing.png``.

From ``benchmarks/bench_flight.py`` (module docstring, "Targets: ... jitter p99 <= 1 ms,
daemon-side latency p99 <= 2 ms"; compute has none since the old 200 us was retired: the
DATA-to-COMMAND latency, of which it is a part, is what the vehicle sees) and the README's
"Benchmarks"
section, which also reports what the development VM measured against them on a quiet
60 s square: compute p99 1.0 ms (target not met), jitter p99 0.13 ms, DATA-to-COMMAND
latency p99 1.25 ms. Compute: DATA sample in hand to COMMAND written; jitter: tick start
minus the DATA frame's receive time; latency: COMMAND write minus IMU receive time.
"""

NOMINAL_STATES = frozenset({"PREFLIGHT", "TAKEOFF", "TRACK", "LAND", "DISARM", "DONE"})
"""States of a nominal flight: their transitions are drawn grey, any other (HOLD, a
failsafe, the pilot taking over) red."""

LEGEND: dict[str, Any] = {"loc": "upper left", "bbox_to_anchor": (1.01, 1.0), "fontsize": 8,
                          "frameon": False, "borderaxespad": 0.0}
"""Legends outside the axes, to the right of the data."""

TIME_LABEL = "time since log start [s]"
TIME_AXIS_GID = "time axis"
"""``Axes.get_gid()`` of every axis whose x is :data:`TIME_LABEL` (the transitions are on it)."""
TRANSITION_GID = "transition"
"""``Line2D.get_gid()`` prefix of the transition lines: ``"transition <new state>"``."""

WIDTH_IN = 11.0
ROW_IN = 2.0
AXES = ("x", "y", "z")
BODY = ("roll (x)", "pitch (y)", "yaw (z)")
CHANNELS = ("roll", "pitch", "yaw", "thrust")
MASK_BIT = {"pitch": 0, "roll": 1, "yaw": 2, "thrust": 3}
"""ctrl mask bit of each stick channel (COMMAND and the X-3D's STATUS)."""
FLAG_NAMES = ("GS commands applied", "motors on", "RC link valid")
"""The X-3D's STATUS flags, bit 0 up (``vehicle_flags``)."""


# ------------------------------------------------------------------ limits from the config
def _default(model: Any, name: str) -> Any:
    """The default of ``model``'s field ``name`` (factories called)."""
    return model.model_fields[name].get_default(call_default_factory=True)


@dataclass(frozen=True)
class LogLimits:
    """The flight configuration's values the figures mark (from the log's config.yaml;
    the configuration's defaults where it lacks them).

    data_period_s : DATA (IMU) period [s]; command_period_s : COMMAND period [s]
    vicon_rate_hz, vicon_min_rate_hz : expected rate and warning floor [Hz]
    vicon_latency_s : configured Tracker latency [s]; max_vicon_delay_s : older poses
        are dropped by the estimator [s]
    battery_land_v : failsafe landing voltage [V] (None: no battery failsafe)
    k_rate : body rate per stick unit, (roll, pitch, yaw) [rad/s per RC unit]
    volume : the tracked volume, ((x_min, x_max), (y_min, y_max)) NED [m]
    gate_probability : the estimator's chi-square gate on a pose's NIS (6 dof)
    """

    data_period_s: float
    command_period_s: float
    vicon_rate_hz: float
    vicon_min_rate_hz: float
    vicon_latency_s: float
    max_vicon_delay_s: float
    battery_land_v: float | None
    k_rate: tuple[float, float, float]
    volume: tuple[tuple[float, float], tuple[float, float]]
    gate_probability: float = 0.9999

    @classmethod
    def from_config(cls, text: str) -> LogLimits:
        """The limits in a flight's config.yaml text (unreadable or missing keys: the
        configuration's defaults)."""
        try:
            data = yaml.safe_load(text)
        except yaml.YAMLError:
            data = None
        cfg: Mapping[str, Any] = data if isinstance(data, Mapping) else {}
        models = {"serial": SerialConfig, "vicon": ViconConfig, "estimator": EstimatorConfig,
                  "safety": SafetyConfig, "vehicle": VehicleConfig}

        def get(section: str, key: str) -> Any:
            block = cfg.get(section)
            if isinstance(block, Mapping) and key in block:
                return block[key]
            return _default(models[section], key)

        def num(section: str, key: str) -> float:
            value = get(section, key)
            ok = isinstance(value, int | float) and not isinstance(value, bool)
            return float(value) if ok else float(_default(models[section], key))

        def vec(section: str, key: str, n: int) -> list[float]:
            value = get(section, key)
            if not (isinstance(value, list | tuple) and len(value) == n
                    and all(isinstance(v, int | float) for v in value)):
                value = _default(models[section], key)
            return [float(v) for v in value]

        land = get("safety", "battery_land_v")
        kx, ky, kz = vec("vehicle", "k_rate", 3)
        vx, vy = vec("safety", "volume_x", 2), vec("safety", "volume_y", 2)
        return cls(
            data_period_s=num("serial", "data_period_ms") / 1000.0,
            command_period_s=1.0 / num("serial", "command_rate_hz"),
            vicon_rate_hz=num("vicon", "expected_rate_hz"),
            vicon_min_rate_hz=num("vicon", "min_rate_hz"),
            vicon_latency_s=num("vicon", "latency_s"),
            max_vicon_delay_s=num("estimator", "max_vicon_delay_s"),
            battery_land_v=float(land) if isinstance(land, int | float) else None,
            k_rate=(kx, ky, kz), volume=((vx[0], vx[1]), (vy[0], vy[1])),
            gate_probability=num("estimator", "gate_probability"),
        )


# ------------------------------------------------------------------ derived quantities
def state_names(meta: Mapping[str, Any]) -> tuple[str, ...]:
    """The supervisor state names indexed by the ``state`` column (meta.json's
    ``supervisor_states``, else :class:`~groundstation.flight.supervisor.State`)."""
    names = meta.get("supervisor_states")
    if isinstance(names, list) and all(isinstance(n, str) for n in names):
        return tuple(names)
    return tuple(s.name for s in State)


def transitions(t: FloatArray, state: npt.ArrayLike,
                names: Sequence[str] | None = None) -> list[tuple[float, str]]:
    """The supervisor's transitions: ``[(time, new state's name), ...]`` in time order.

    t : (N,) tick times [s] (the result uses the same clock); state : (N,) the ``state``
    column; names : state names by value (default :class:`State`; values beyond it are
    shown as ``state <n>``). A transition is a tick whose state differs from the tick
    before; its time is that tick's.
    """
    s = np.asarray(state, dtype=np.int64)
    names = tuple(names) if names is not None else tuple(x.name for x in State)
    change = np.flatnonzero(s[1:] != s[:-1]) + 1
    return [(float(t[i]), names[s[i]] if 0 <= s[i] < len(names) else f"state {s[i]}")
            for i in change]


def euler_angles(q: FloatArray) -> FloatArray:
    """3-2-1 Euler angles ``(roll, pitch, yaw)`` [rad] of (N, 4) scalar-first quaternions.

    The body attitude ``eCb = Rz(yaw) Ry(pitch) Rx(roll)`` (body FRD -> NED); roll and yaw
    in (-pi, pi], pitch in [-pi/2, pi/2]. Quaternions need not be normalised; NaN rows
    give NaN. (The vectorised form of :func:`groundstation.model.quaternion.euler_from_quat`.)
    """
    q = np.asarray(q, dtype=float).reshape(-1, 4)
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    q0, q1, q2, q3 = q.T
    roll = np.arctan2(2 * (q2 * q3 + q0 * q1), q0 * q0 - q1 * q1 - q2 * q2 + q3 * q3)
    pitch = np.arcsin(np.clip(-2 * (q1 * q3 - q0 * q2), -1.0, 1.0))
    yaw = np.arctan2(2 * (q1 * q2 + q0 * q3), q0 * q0 + q1 * q1 - q2 * q2 - q3 * q3)
    return np.column_stack([roll, pitch, yaw])


def _rotvec(q: FloatArray) -> FloatArray:
    """Rotation vectors [rad] of (N, 4) scalar-first quaternions (angle in [0, pi])."""
    q = q * np.where(q[:, :1] < 0, -1.0, 1.0)
    n = np.linalg.norm(q[:, 1:], axis=1)
    angle = 2 * np.arctan2(n, q[:, 0])
    with np.errstate(invalid="ignore", divide="ignore"):
        scale = np.where(n > 1e-12, angle / n, 2.0)
    return np.asarray(q[:, 1:] * scale[:, None])


def _quat_error(q_est: FloatArray, q_meas: FloatArray) -> FloatArray:
    """Body-axis rotation vector [rad] of ``conj(q_est) ⊗ q_meas`` per row, (N, 3)."""
    w0, x0, y0, z0 = q_est[:, 0], -q_est[:, 1], -q_est[:, 2], -q_est[:, 3]
    w1, x1, y1, z1 = q_meas.T
    prod = np.column_stack([
        w0 * w1 - x0 * x1 - y0 * y1 - z0 * z1,
        w0 * x1 + x0 * w1 + y0 * z1 - z0 * y1,
        w0 * y1 - x0 * z1 + y0 * w1 + z0 * x1,
        w0 * z1 + x0 * y1 - y0 * x1 + z0 * w1,
    ])
    return _rotvec(prod)


def vicon_residuals(rows: Rows) -> tuple[FloatArray, FloatArray]:
    """Vicon pose minus the estimate predicted to it: position (N, 3) NED [m] and attitude
    (N, 3) body rotation vector [rad]; NaN on ticks without a pose (or estimate).

    The log records the filter's NIS per pose (``vicon_nis``, schema 5 on), not its
    innovation vector; for the vector in metres and degrees this proxy compares each pose with
    the estimate of the tick *before* it was used (which has not seen it), moved to the
    pose's time ``vicon_t`` with that tick's velocity (``eCb v_body``); the attitude
    residual is ``conj(q_est) ⊗ q_vicon``. Unlike the filter's own innovation it ignores
    the IMU propagation over that interval (a few ms).
    """
    n = len(rows)
    pos = np.full((n, 3), np.nan)
    att = np.full((n, 3), np.nan)
    if n < 2:
        return pos, att
    k = np.flatnonzero(rows["vicon_valid"][1:].astype(bool)) + 1
    prev = k - 1
    q = np.asarray(rows["est_quaternion"][prev], dtype=float)
    v_body = np.asarray(rows["est_velocity_body"][prev], dtype=float)
    v_ned = np.einsum("nij,nj->ni", _dcm(q), v_body)
    dt = np.asarray(rows["vicon_t"][k] - rows["t"][prev], dtype=float)
    predicted = np.asarray(rows["est_position"][prev], dtype=float) + v_ned * dt[:, None]
    pos[k] = np.asarray(rows["vicon_position"][k], dtype=float) - predicted
    att[k] = _quat_error(q, np.asarray(rows["vicon_quaternion"][k], dtype=float))
    return pos, att


def _dcm(q: FloatArray) -> FloatArray:
    """``eCb`` (N, 3, 3) of (N, 4) scalar-first unit quaternions."""
    q0, q1, q2, q3 = np.asarray(q, dtype=float).T
    return np.stack([
        np.stack([q0 * q0 + q1 * q1 - q2 * q2 - q3 * q3, 2 * (q1 * q2 - q0 * q3),
                  2 * (q1 * q3 + q0 * q2)], axis=-1),
        np.stack([2 * (q1 * q2 + q0 * q3), q0 * q0 - q1 * q1 + q2 * q2 - q3 * q3,
                  2 * (q2 * q3 - q0 * q1)], axis=-1),
        np.stack([2 * (q1 * q3 - q0 * q2), 2 * (q2 * q3 + q0 * q1),
                  q0 * q0 - q1 * q1 - q2 * q2 + q3 * q3], axis=-1),
    ], axis=-2)


def pose_rate(t: FloatArray, valid: npt.ArrayLike, window_s: float = 1.0) -> FloatArray:
    """Vicon poses used per second [Hz] at every tick, over the trailing ``window_s`` [s]
    (ticks ``t - window_s < t_k <= t`` with a pose); NaN for the first window."""
    t = np.asarray(t, dtype=float)
    used = np.concatenate([[0], np.cumsum(np.asarray(valid, dtype=bool))])
    start = np.searchsorted(t, t - window_s, side="right")
    rate = (used[1:] - used[start]) / window_s
    return np.where(t - t[0] >= window_s, rate, np.nan)


def applied_sticks(rows: Rows, channel: str) -> FloatArray:
    """The stick the X-3D applied on ``channel`` (roll, pitch, yaw, thrust) [RC units]:
    the ground station's COMMAND where the vehicle's mask (STATUS) gives it the channel,
    else the pilot's stick (as the log last saw them)."""
    gs = np.asarray(rows["vehicle_mask"], dtype=np.int64) >> MASK_BIT[channel] & 1
    return np.where(gs == 1, rows[f"cmd_{channel}"], rows[f"pilot_{channel}"]).astype(float)


def _mask_off_spans(t: FloatArray, on: npt.NDArray[np.bool_]) -> list[tuple[float, float]]:
    """``[(start, end), ...]`` of the runs where ``on`` is False [s]."""
    off = ~np.asarray(on, dtype=bool)
    edges = np.flatnonzero(np.diff(np.concatenate([[0], off.astype(np.int8), [0]])))
    return [(float(t[a]), float(t[min(b, len(t) - 1)])) for a, b in zip(edges[::2], edges[1::2],
                                                                       strict=True)]


def _p(values: FloatArray, q: float) -> float:
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    return float(np.percentile(v, q)) if v.size else math.nan


# ------------------------------------------------------------------ the data the figures read
@dataclass(frozen=True)
class FlightLog:
    """One flight log as the figures read it.

    rows : the log's rows (``RECORD_DTYPE``); record : the same flight as a
    :class:`FlightRecord` (ground truth aligned on the ticks when there is some);
    names : state names by value; limits : from the flight's configuration; title : figure
    title prefix
    """

    rows: Rows
    record: FlightRecord
    names: tuple[str, ...]
    limits: LogLimits
    title: str
    marks: list[tuple[float, str]] = field(init=False)
    t: FloatArray = field(init=False)

    def __post_init__(self) -> None:
        t = np.asarray(self.rows["t"], dtype=float)
        object.__setattr__(self, "t", t - t[0])
        object.__setattr__(self, "marks", transitions(self.t, self.rows["state"], self.names))

    @classmethod
    def of(cls, rows: Rows, meta: Mapping[str, Any], config_text: str, record: FlightRecord,
           title: str) -> FlightLog:
        """From :func:`~groundstation.app.recorder.read_flight`'s rows, meta and config and
        the flight's record."""
        return cls(rows, record, state_names(meta), LogLimits.from_config(config_text), title)

    def col(self, name: str) -> FloatArray:
        """Column ``name`` as float."""
        return np.asarray(self.rows[name], dtype=float)

    @property
    def has_innovations(self) -> bool:
        """True when the log records the estimator's NIS per pose (schema 5 on; an older
        log read into this schema has the column, all NaN)."""
        return bool(np.isfinite(self.col("vicon_nis")).any())


# ------------------------------------------------------------------ figure helpers
def _figure(rows: int, title: str, height: float | None = None) -> tuple[Any, Any]:
    plt = pyplot()
    fig, axes = plt.subplots(rows, 1, sharex=True, squeeze=False, layout="constrained",
                             figsize=(WIDTH_IN, height or 1.3 + ROW_IN * rows))
    fig.suptitle(title)
    return fig, list(axes[:, 0])


def _mark_color(name: str) -> str:
    return "0.35" if name in NOMINAL_STATES else "tab:red"


def mark_transitions(axes: Sequence[Any], marks: Sequence[tuple[float, str]],
                     t_end: float) -> None:
    """Draw the transitions ``marks`` (time [s], new state) on every axis of ``axes``
    (time axes), as dashed vertical lines, and name them once, along the top of
    ``axes[0]`` (names closer than 5 % of the span share one label)."""
    for ax in axes:
        ax.set_gid(TIME_AXIS_GID)
        ax.grid(True, alpha=0.3)
        for t, name in marks:
            ax.axvline(t, color=_mark_color(name), lw=0.8, ls="--", alpha=0.8, zorder=0.5,
                       gid=f"{TRANSITION_GID} {name}")
    if not marks or not axes:
        return
    groups: list[tuple[float, list[str]]] = []
    for t, name in marks:
        if groups and t - groups[-1][0] < 0.05 * max(t_end, 1e-9):
            groups[-1][1].append(name)
        else:
            groups.append((t, [name]))
    top = axes[0].secondary_xaxis("top")
    top.set_xticks([g[0] for g in groups], labels=[" / ".join(g[1]) for g in groups])
    top.tick_params(axis="x", labelsize=8, length=3, pad=1)
    for label, (_, names) in zip(top.get_xticklabels(), groups, strict=True):
        label.set(rotation=30, ha="left", rotation_mode="anchor",
                  color="tab:red" if set(names) - NOMINAL_STATES else "0.25")


def legends(axes: Sequence[Any]) -> None:
    """A legend right of every axis that has labelled artists, except where it would
    repeat the legend of the axis above (the same labels): rows of one quantity per axis
    (x, y, z) share the top row's legend. Dot markers are enlarged in the legend."""
    above: list[str] | None = None
    for ax in axes:
        labels = ax.get_legend_handles_labels()[1]
        if labels and labels != above:
            leg = ax.legend(**LEGEND)
            for handle in leg.legend_handles:
                if getattr(handle, "get_marker", lambda: None)() == ".":
                    handle.set_markersize(6.0)
        above = labels


def _finish(fig: Any, axes: Sequence[Any], log: FlightLog) -> Any:
    """Transitions on the time axes, time label at the bottom, x limits the log's span,
    legends; linear y axes without an offset (values read as they are)."""
    from matplotlib.ticker import ScalarFormatter

    for ax in axes:
        if isinstance(ax.yaxis.get_major_formatter(), ScalarFormatter):
            ax.ticklabel_format(axis="y", useOffset=False)
    mark_transitions(axes, log.marks, float(log.t[-1]))
    axes[-1].set_xlabel(TIME_LABEL)
    axes[-1].set_xlim(0.0, float(log.t[-1]) if log.t[-1] > 0 else 1.0)
    legends(axes)
    return fig


def log_y(ax: Any, plain: bool = False) -> None:
    """A logarithmic y axis with minor ticks at 2 and 5 of every decade; ``plain``: every
    tick labelled as a plain number (0.2, 0.5, 1, 2, ...), for ranges of a few decades."""
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter

    ax.set_yscale("log")
    ax.yaxis.set_minor_locator(LogLocator(subs=(2.0, 5.0)))
    if plain:
        number = FuncFormatter(lambda v, _: f"{v:g}")
        ax.yaxis.set_major_formatter(number)
        ax.yaxis.set_minor_formatter(number)
    else:
        ax.yaxis.set_minor_formatter(NullFormatter())


def robust_ylim(ax: Any, values: FloatArray, quantile: float = 99.5,
                margin: float = 1.5) -> None:
    """Limit ``ax``'s y range to ``margin`` times the ``quantile`` of ``|values|`` when a
    few outliers would squash the rest; their count goes into the legend."""
    v = np.abs(np.asarray(values, dtype=float))
    v = v[np.isfinite(v)]
    if not v.size:
        return
    lim = margin * float(np.percentile(v, quantile))
    beyond = int(np.sum(v > lim))
    if lim > 0 and beyond:
        ax.set_ylim(-lim, lim)
        ax.plot([], [], " ", label=f"{beyond} points beyond the axis")


# ------------------------------------------------------------------ the figures
def overview_figure(log: FlightLog) -> Any:
    """The flight on four panels: top view (airborne), x/y/z and reference against time,
    errors [cm], and a histogram of the per-tick timing [us]."""
    plt = pyplot()
    r, t = log.record, log.t
    fig, axes = plt.subplots(2, 2, figsize=(13.0, 8.5), layout="constrained")
    fig.suptitle(f"{log.title}: overview ({r.truth_source})")
    air = r.during(*AIRBORNE)
    ax = axes[0, 0]
    ax.plot(r.ref_pos[air, 1], r.ref_pos[air, 0], color="k", lw=1.0, ls=":", label="reference")
    ax.plot(r.est_pos[air, 1], r.est_pos[air, 0], color="C0", lw=1.0, ls="--",
            label="estimate")
    if r.true_pos is not None:
        ax.plot(r.true_pos[air, 1], r.true_pos[air, 0], color="C1", lw=1.2, label="truth")
    ax.set(xlabel="y east [m]", ylabel="x north [m]", title="top view (airborne)")
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(True, alpha=0.3)
    ax.legend(**LEGEND)
    ax = axes[0, 1]
    for k, name in enumerate(AXES):
        ax.plot(t, r.position[:, k], color=f"C{k}", lw=1.0, label=name)
        ax.plot(t, r.ref_pos[:, k], color=f"C{k}", lw=0.8, ls=":")
    ax.plot([], [], color="0.4", lw=0.8, ls=":", label="reference")
    ax.set(xlabel=TIME_LABEL, ylabel="position NED [m]",
           title=f"position ({'truth' if r.has_truth else 'estimate'}) and reference")
    ax = axes[1, 0]
    ax.plot(t[air], 100 * error_norms(r.position[air], r.ref_pos[air]), color="C3", lw=1.0,
            label=f"|{'truth' if r.has_truth else 'estimate'} - reference|")
    if r.true_pos is not None:
        ax.plot(t[air], 100 * error_norms(r.est_pos[air], r.true_pos[air]), color="C2",
                lw=1.0, label="|estimate - truth|")
    ax.set(xlabel=TIME_LABEL, ylabel="error [cm]", title="errors (airborne)")
    mark_transitions([axes[0, 1], axes[1, 0]], log.marks, float(t[-1]))
    for a in (axes[0, 1], axes[1, 0]):
        a.set_xlim(0.0, float(t[-1]) if t[-1] > 0 else 1.0)
        a.legend(**LEGEND)
    ax = axes[1, 1]
    series = [("compute", r.compute_s)]
    if r.latency_s is not None:
        series.append(("DATA -> COMMAND latency", r.latency_s))
    for k, (name, values) in enumerate(series):
        v = 1e6 * values[np.isfinite(values)]
        if v.size:
            ax.hist(v, bins=60, color=f"C{k}", alpha=0.6, label=name)
    ax.set(xlabel="time per tick [us]", ylabel="ticks", yscale="log", title="timing")
    ax.grid(True, alpha=0.3)
    ax.legend(**LEGEND)
    return fig


def position_figure(log: FlightLog) -> Any:
    """x, y, z (NED [m]) of the estimate, Vicon, truth and reference; tracking error [cm]."""
    r, t = log.record, log.t
    fig, axes = _figure(4, f"{log.title}: position (NED) and reference")
    vicon = np.where(log.rows["vicon_valid"][:, None], log.col("vicon_position"), np.nan)
    for k, name in enumerate(AXES):
        ax = axes[k]
        ax.plot(t, r.ref_pos[:, k], color="k", lw=1.0, ls=":", label="reference")
        ax.plot(t, vicon[:, k], color="C2", lw=0.6, alpha=0.5, label="Vicon", zorder=1.5)
        ax.plot(t, r.est_pos[:, k], color="C0", lw=1.0, ls="--", label="estimate")
        if r.true_pos is not None:
            ax.plot(t, r.true_pos[:, k], color="C1", lw=1.2, label="truth (virtual lab)")
        ax.set_ylabel(f"{name} [m]" + (" (down)" if name == "z" else ""))
    ax = axes[3]
    ax.plot(t, 100 * error_norms(r.position, r.ref_pos), color="C3", lw=1.0,
            label=f"|{'truth' if r.has_truth else 'estimate'} - reference|")
    if r.true_pos is not None:
        ax.plot(t, 100 * error_norms(r.est_pos, r.true_pos), color="C4", lw=1.0,
                label="|estimate - truth|")
    ax.set_ylabel("error [cm]")
    return _finish(fig, axes, log)


def top_view_figure(log: FlightLog) -> Any:
    """The flight seen from above (NED: north up, east right, equal aspect) [m], zoomed on
    the flown path and the reference (at least 10 cm across); the safety volume's edges
    where they fall in view."""
    plt = pyplot()
    r = log.record
    fig, ax = plt.subplots(figsize=(10.0, 7.0), layout="constrained")
    (x0, x1), (y0, y1) = log.limits.volume
    ax.plot([y0, y1, y1, y0, y0], [x0, x0, x1, x1, x0], color="0.6", lw=0.8, ls="-.",
            label=f"safety volume (x {x0:g}..{x1:g}, y {y0:g}..{y1:g} m)")
    seen = [a for a in (r.ref_pos, r.est_pos, r.true_pos) if a is not None]
    xy = np.concatenate([a[:, :2] for a in seen])
    xy = xy[np.isfinite(xy).all(axis=1)]
    if len(xy):  # a square view around the path, so that equal aspect keeps both limits
        lo, hi = xy.min(axis=0), xy.max(axis=0)
        mid, half = (lo + hi) / 2, max(float(np.max(hi - lo)) / 2 * 1.1, 0.05)
        ax.set(xlim=(mid[1] - half, mid[1] + half), ylim=(mid[0] - half, mid[0] + half))
    ax.plot(r.ref_pos[:, 1], r.ref_pos[:, 0], color="k", lw=1.0, ls=":", label="reference")
    ax.plot(r.est_pos[:, 1], r.est_pos[:, 0], color="C0", lw=1.0, ls="--", label="estimate")
    if r.true_pos is not None:
        ax.plot(r.true_pos[:, 1], r.true_pos[:, 0], color="C1", lw=1.2,
                label="truth (virtual lab)")
    p = r.position
    finite = np.flatnonzero(np.isfinite(p[:, 0]))
    if finite.size:
        a, b = finite[0], finite[-1]
        ax.plot(p[a, 1], p[a, 0], "o", color="C2", ms=6, label=f"start ({log.t[a]:.1f} s)")
        ax.plot(p[b, 1], p[b, 0], "s", color="C3", ms=6, label=f"end ({log.t[b]:.1f} s)")
    ax.set(xlabel="y east [m]", ylabel="x north [m]",
           title=f"{log.title}: top view (NED from above)")
    ax.set_aspect("equal", adjustable="box")
    ax.grid(True, alpha=0.3)
    ax.legend(**LEGEND)
    return fig


def attitude_figure(log: FlightLog) -> Any:
    """Roll, pitch, yaw [deg] of the estimate, Vicon and truth; the reference heading."""
    r, t = log.record, log.t
    fig, axes = _figure(3, f"{log.title}: attitude (3-2-1 Euler angles)")
    est = np.degrees(euler_angles(r.est_q))
    vq = np.where(log.rows["vicon_valid"][:, None], log.col("vicon_quaternion"), np.nan)
    vicon = np.degrees(euler_angles(vq))
    truth = np.degrees(euler_angles(r.true_q)) if r.true_q is not None else None
    for k, name in enumerate(("roll", "pitch", "yaw")):
        ax = axes[k]
        if k == 2 and r.ref_yaw is not None:
            ax.plot(t, np.degrees(r.ref_yaw), color="k", lw=1.0, ls=":", label="reference")
        ax.plot(t, vicon[:, k], color="C2", lw=0.5, alpha=0.45, label="Vicon", zorder=1.5)
        ax.plot(t, est[:, k], color="C0", lw=1.0, ls="--", label="estimate")
        if truth is not None:
            ax.plot(t, truth[:, k], color="C1", lw=1.2, label="truth (virtual lab)")
        ax.set_ylabel(f"{name} [deg]")
    return _finish(fig, axes, log)


def rates_figure(log: FlightLog) -> Any:
    """Body rates (FRD [deg/s]): the bias-corrected gyro (the estimator's ``omega``; the
    biases are on estimator.png) and the rate command ``k_rate * applied stick`` (the
    X-3D's rate loop follows it with a lag)."""
    t = log.t
    fig, axes = _figure(3, f"{log.title}: body rates (FRD) and their commands")
    omega = np.degrees(log.col("est_omega"))
    for k, (name, channel) in enumerate(zip(BODY, ("roll", "pitch", "yaw"), strict=True)):
        ax = axes[k]
        cmd = np.degrees(log.limits.k_rate[k] * applied_sticks(log.rows, channel))
        ax.plot(t, omega[:, k], color="C0", lw=0.6, alpha=0.8,
                label="measured (gyro - estimated bias)")
        ax.step(t, cmd, where="post", color="C3", lw=1.0,
                label=f"command: {log.limits.k_rate[k]:.2g} rad/s x {channel} stick")
        ax.set_ylabel(f"{name} [deg/s]")
    return _finish(fig, axes, log)


def commands_figure(log: FlightLog) -> Any:
    """Sticks [RC units]: the ground station's COMMAND, the controller before the handover
    blend, the pilot's sticks; shaded where the vehicle gave the channel to the pilot."""
    t = log.t
    fig, axes = _figure(4, f"{log.title}: sticks, ground station vs pilot")
    mask = np.asarray(log.rows["vehicle_mask"], dtype=np.int64)
    for ax, channel in zip(axes, CHANNELS, strict=True):
        gs = (mask >> MASK_BIT[channel] & 1).astype(bool)
        for k, (a, b) in enumerate(_mask_off_spans(t, gs)):
            ax.axvspan(a, b, color="0.85", alpha=0.6, lw=0,
                       label="pilot has the channel (vehicle mask)" if k == 0 else None)
        ax.step(t, log.col(f"cmd_{channel}"), where="post", color="C0", lw=1.0,
                label="ground station COMMAND")
        ax.plot(t, log.col(f"ctrl_{channel}"), color="C1", lw=0.8, ls="--",
                label="controller (before handover blend)")
        ax.step(t, log.col(f"pilot_{channel}"), where="post", color="C2", lw=1.0,
                label="pilot stick")
        ax.set_ylabel(f"{channel} [RC unit]")
    return _finish(fig, axes, log)


def estimator_figure(log: FlightLog) -> Any:
    """Vicon residuals (innovation proxy, :func:`vicon_residuals`) [cm, deg], estimate
    minus truth where known, standard deviations from the covariance diagonal, biases."""
    r, t = log.record, log.t
    truth = r.true_pos is not None and r.true_q is not None
    nis = log.has_innovations
    note = "" if nis else \
        "\n(the log records no innovations: Vicon minus the estimate of the tick before, " \
        "moved to the pose time, instead)"
    fig, axes = _figure(6 + int(truth) + int(nis), f"{log.title}: estimator{note}")
    res_pos, res_att = vicon_residuals(log.rows)
    P = log.col("est_covariance_diag")
    sd = np.sqrt(np.clip(P, 0.0, None))
    rows = iter(axes)
    if nis:
        _nis_panel(next(rows), log)
    ax = next(rows)
    for k, name in enumerate(AXES):
        ax.plot(t, 100 * res_pos[:, k], ".", ms=1.5, color=f"C{k}", label=name)
    robust_ylim(ax, 100 * res_pos)
    ax.set_ylabel("Vicon - predicted\nposition [cm]")
    ax = next(rows)
    for k, name in enumerate(BODY):
        ax.plot(t, np.degrees(res_att[:, k]), ".", ms=1.5, color=f"C{k}", label=name)
    robust_ylim(ax, np.degrees(res_att))
    ax.set_ylabel("Vicon - estimate\nattitude [deg]")
    if truth:
        assert r.true_pos is not None and r.true_q is not None
        ax = next(rows)
        err = 100 * (r.est_pos - r.true_pos)
        for k, name in enumerate(AXES):
            ax.plot(t, err[:, k], color=f"C{k}", lw=0.9, label=f"position {name}")
        angle = np.degrees(np.linalg.norm(_quat_error(r.true_q, r.est_q), axis=1))
        ax.plot(t, angle, color="k", lw=0.8, label="attitude angle [deg]")
        robust_ylim(ax, np.concatenate([err.ravel(), angle]))
        ax.set_ylabel("estimate - truth\n[cm], [deg]")
    ax = next(rows)
    for k, name in enumerate(AXES):
        ax.plot(t, 100 * sd[:, k], color=f"C{k}", lw=1.0, label=f"position {name} [cm]")
        ax.plot(t, 100 * sd[:, 7 + k], color=f"C{k}", lw=1.0, ls="--",
                label=f"velocity {name} [cm/s]")
    ax.set_ylabel("sigma\n[cm], [cm/s]")
    log_y(ax)
    ax = next(rows)
    for k in range(4):
        ax.plot(t, sd[:, 3 + k], color=f"C{k}", lw=1.0, label=f"q{k}")
    ax.set_ylabel("sigma of the\nquaternion [-]")
    log_y(ax)
    ax = next(rows)
    bias = np.degrees(log.col("est_gyro_bias"))
    for k, name in enumerate(BODY):
        s = np.degrees(sd[:, 10 + k])
        ax.plot(t, bias[:, k], color=f"C{k}", lw=1.0, label=name)
        ax.fill_between(t, bias[:, k] - s, bias[:, k] + s, color=f"C{k}", alpha=0.15, lw=0)
    ax.set_ylabel("gyro bias\n+-sigma [deg/s]")
    ax = next(rows)
    bias = log.col("est_acc_bias")
    for k, name in enumerate(("x (forward)", "y (right)", "z (down)")):
        s = sd[:, 13 + k]
        ax.plot(t, bias[:, k], color=f"C{k}", lw=1.0, label=name)
        ax.fill_between(t, bias[:, k] - s, bias[:, k] + s, color=f"C{k}", alpha=0.15, lw=0)
    ax.set_ylabel("accelerometer bias\n+-sigma [m/s^2]")
    return _finish(fig, axes, log)


def _nis_panel(ax: Any, log: FlightLog) -> None:
    """The NIS of every pose the estimator judged, against its chi-square (6 dof) gate and
    median: a consistent filter's NIS has the chi-square's median (5.35)."""
    from scipy.stats import chi2

    t, values = log.t, log.col("vicon_nis")
    finite = np.isfinite(values)
    gate = float(chi2.ppf(log.limits.gate_probability, 6))
    median = float(chi2.median(6))
    flown = float(np.median(values[finite])) if finite.any() else math.nan
    ax.plot(t[finite], values[finite], ".", ms=1.5, color="C0",
            label=f"NIS of each pose judged (median {flown:.2f})")
    ax.axhline(median, color="C2", ls="--", lw=0.8,
               label=f"chi-square (6 dof) median {median:.2f}")
    ax.axhline(gate, color="C3", ls="--", lw=0.8,
               label=f"gate ({log.limits.gate_probability:g}): {gate:.1f}")
    ax.set_ylabel("NIS [-]")
    log_y(ax)
    floor = 1e-2  # chi-square (6 dof) falls below it with probability 2e-8: outliers only
    low = int(np.count_nonzero(values[finite] < floor))
    top = float(np.nanmax(values, initial=gate))
    ax.set_ylim(floor, max(2.0 * top, 2.0 * gate))
    if low:
        ax.plot([], [], " ", label=f"{low} below the axis (a reset)")


def health_figure(log: FlightLog) -> Any:
    """Vicon rate [Hz] and pose age [ms], ticks without a pose, DATA period and missed
    samples, COMMAND gaps [ms], the vehicle's STATUS flags and ctrl masks."""
    lim, t, rows = log.limits, log.t, log.rows
    fig, axes = _figure(6, f"{log.title}: Vicon and link health")
    valid = np.asarray(rows["vicon_valid"], dtype=bool)
    ax = axes[0]
    ax.plot(t, pose_rate(t, valid), color="C0", lw=1.0, label="poses used per second (1 s)")
    ax.axhline(lim.vicon_rate_hz, color="C2", ls="--", lw=0.8,
               label=f"expected {lim.vicon_rate_hz:g} Hz")
    ax.axhline(lim.vicon_min_rate_hz, color="C3", ls="--", lw=0.8,
               label=f"warning below {lim.vicon_min_rate_hz:g} Hz")
    ax.set(ylabel="Vicon rate [Hz]", ylim=(0, 1.25 * max(lim.vicon_rate_hz, 1.0)))
    ax = axes[1]
    age = 1e3 * np.where(valid, log.col("t") - log.col("vicon_t"), np.nan)
    ax.plot(t, age, ".", ms=1.5, color="C0", label="pose age when used")
    ax.axhline(1e3 * lim.vicon_latency_s, color="C2", ls="--", lw=0.8,
               label=f"configured Tracker latency {1e3 * lim.vicon_latency_s:g} ms")
    ax.axhline(1e3 * lim.max_vicon_delay_s, color="C3", ls="--", lw=0.8,
               label=f"estimator drops older ({1e3 * lim.max_vicon_delay_s:g} ms)")
    missing = np.flatnonzero(~valid)
    ax.plot(t[missing], np.full(missing.size, 1e3 * lim.vicon_latency_s / 2), "|",
            color="C3", ms=8,
            label=f"tick without a Vicon pose ({missing.size})")
    refused = np.asarray(rows["vicon_refused"], dtype=np.int64)
    hit = np.flatnonzero(refused > 0)
    ax.plot(t[hit], np.full(hit.size, 1e3 * lim.vicon_latency_s / 4), "|", color="k", ms=8,
            label=f"poses the estimator refused ({int(refused.sum())})")
    ax.set_ylabel("pose age [ms]")
    log_y(ax, plain=True)
    ax = axes[2]
    imu_t = log.col("imu_t")
    counter = np.asarray(rows["imu_counter"], dtype=np.int64)
    period = 1e3 * np.diff(imu_t)
    new = np.flatnonzero(np.diff(counter) != 0) + 1
    gaps = (np.diff(counter) % 65536) - 1
    lost = np.flatnonzero(gaps > 0) + 1
    ax.plot(t[new], 1e3 * np.diff(imu_t[np.concatenate([[0], new])]), ".", ms=1.5, color="C0",
            label="DATA sample interval")
    ax.axhline(1e3 * lim.data_period_s, color="C2", ls="--", lw=0.8,
               label=f"configured period {1e3 * lim.data_period_s:g} ms")
    ax.plot(t[lost], np.full(lost.size, 1e3 * lim.data_period_s), "x", color="C3",
            label=f"samples missed (counter; {int(gaps[gaps > 0].sum())} in all)")
    ax.set(ylabel="DATA interval [ms]",
           ylim=(0.0, 1.1 * max(2e3 * lim.data_period_s, np.nanmax(period, initial=0.0))))
    ax = axes[3]
    sent = np.flatnonzero(np.asarray(rows["cmd_sent"], dtype=bool))
    ts = log.col("t")[sent]
    ax.plot(t[sent[1:]], 1e3 * np.diff(ts), ".", ms=1.5, color="C0",
            label="time since the previous COMMAND")
    ax.axhline(1e3 * lim.command_period_s, color="C2", ls="--", lw=0.8,
               label=f"command period {1e3 * lim.command_period_s:g} ms")
    ax.axhline(50.0, color="C3", ls="--", lw=0.8, label="half the X-3D's 100 ms watchdog")
    ax.set(ylabel="COMMAND gap [ms]",
           ylim=(0.0, 1.1 * max(55.0, 1e3 * np.nanmax(np.diff(ts), initial=0.0))))
    ax = axes[4]
    flags = np.asarray(rows["vehicle_flags"], dtype=np.int64)
    levels = [*((name, (flags >> k) & 1) for k, name in enumerate(FLAG_NAMES)),
              ("pilot serial-enable switch", np.asarray(rows["pilot_enabled"], dtype=np.int64))]
    for k, (_, bits) in enumerate(levels):
        ax.fill_between(t, k + 0.15, k + 0.85, where=bits.astype(bool), step="post",
                        color=f"C{k}", alpha=0.7, lw=0)
    ax.set_yticks([k + 0.5 for k in range(len(levels))], labels=[n for n, _ in levels],
                  fontsize=8)
    ax.set(ylim=(0, len(levels)), ylabel="vehicle STATUS\n(bar = on)")
    ax = axes[5]
    ax.step(t, log.col("cmd_mask"), where="post", color="C0", lw=1.4,
            label="COMMAND mask (ground station asks)")
    ax.step(t, log.col("vehicle_mask"), where="post", color="C1", lw=1.0, ls="--",
            label="vehicle mask (X-3D applies)")
    ax.set_yticks([0, 3, 12, 15])
    ax.set(ylabel="ctrl mask\n(bit0 pitch..bit3 thrust)", ylim=(-1, 16))
    return _finish(fig, axes, log)


def battery_figure(log: FlightLog) -> Any:
    """Battery voltage the X-3D reports [V], with the failsafe landing voltage."""
    fig, axes = _figure(1, f"{log.title}: battery", height=3.6)
    ax = axes[0]
    v = log.col("battery_v")
    ax.plot(log.t, v, color="C0", lw=1.2, label="battery (STATUS)")
    if log.limits.battery_land_v is not None:
        ax.axhline(log.limits.battery_land_v, color="C3", ls="--", lw=0.8,
                   label=f"failsafe landing below {log.limits.battery_land_v:g} V")
    if not np.isfinite(v).any():
        ax.text(0.5, 0.5, "no battery voltage logged (no STATUS block)", ha="center",
                transform=ax.transAxes)
    ax.set_ylabel("voltage [V]")
    return _finish(fig, axes, log)


def timing_figure(log: FlightLog) -> Any:
    """Per-tick compute time, schedule jitter and DATA-to-COMMAND latency [ms] with the
    data period (config) and :data:`BENCHMARK_TARGETS` marked."""
    lim, t = log.limits, log.t
    fig, axes = _figure(3, f"{log.title}: loop timing")
    period = 1e3 * lim.data_period_s
    series = (
        ("compute", "compute (DATA in hand -> COMMAND written)", BENCHMARK_TARGETS.compute_p99_ms,
         True),
        ("jitter", "jitter (tick start - DATA received)", BENCHMARK_TARGETS.jitter_p99_ms, False),
        ("latency", "DATA -> COMMAND latency (written commands)",
         BENCHMARK_TARGETS.latency_p99_ms, True),
    )
    for ax, (key, label, target, with_period) in zip(axes, series, strict=True):
        v = 1e3 * log.col("compute_time" if key == "compute" else key)
        ax.plot(t, v, ".", ms=1.5, color="C0",
                label=f"{label}\np50 {_p(v, 50):.2f} ms, p99 {_p(v, 99):.2f} ms")
        if target is not None:
            ax.axhline(target, color="C3", ls="--", lw=1.0,
                       label=f"benchmark target: p99 <= {target:g} ms")
        if with_period:
            ax.axhline(period, color="C2", ls="-.", lw=1.0,
                       label=f"DATA period {period:g} ms (config)")
        if np.nanmax(v, initial=0.0) > 0:
            log_y(ax, plain=True)
        else:
            ax.text(0.5, 0.5, f"no {key} measured (a flight without a real-time schedule)",
                    ha="center", va="center", transform=ax.transAxes, fontsize=9)
        ax.set_ylabel(f"{key} [ms]")
    return _finish(fig, axes, log)


FIGURES: tuple[tuple[str, str, Callable[[FlightLog], Any]], ...] = (
    ("flight", "overview: top view, position, errors, timing histogram", overview_figure),
    ("position", "position (NED) and reference per axis, tracking error", position_figure),
    ("top_view", "top view: NED from above, north up, east right", top_view_figure),
    ("attitude", "roll, pitch, yaw from the quaternions, reference heading", attitude_figure),
    ("rates", "body rates against the rate commands of the sticks", rates_figure),
    ("commands", "sticks and thrust: ground-station COMMAND, controller, pilot",
     commands_figure),
    ("estimator", "Vicon residuals, estimate vs truth, covariance sigmas, biases",
     estimator_figure),
    ("health", "Vicon rate and age, DATA and COMMAND gaps, vehicle flags and masks",
     health_figure),
    ("battery", "battery voltage and the failsafe threshold", battery_figure),
    ("timing", "compute, jitter and latency per tick with their targets", timing_figure),
)
"""``(file stem, what it shows, builder)`` of every figure of a flight, in report order."""


def write_flight_figures(log: FlightLog, out_dir: Path) -> list[Path]:
    """Draw :data:`FIGURES` of ``log`` into ``out_dir/<stem>.png``; the paths written.

    GroundStationError if matplotlib is missing.
    """
    pyplot()
    return [save(build(log), out_dir / f"{stem}.png") for stem, _, build in FIGURES]
