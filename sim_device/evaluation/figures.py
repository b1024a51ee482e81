"""The suite's figures, mirroring thesis Ch. 11 (Fig. 11.1-11.8) plus the fault scenarios
(the shaped flights': :mod:`sim_device.evaluation.figures_shaped`).

Each function takes the flights by scenario name (see
:mod:`sim_device.evaluation.scenarios`) and writes one PNG; a figure whose
flights are missing (a partial run) is skipped. Positions are ground truth
(solid), estimates dashed, references dotted black. Top views are NED from
above: x north up, y east right. Times are seconds since tracking started.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from pathlib import Path

import numpy as np

from groundstation.control.simulate import SimResult
from groundstation.evaluation.metrics import (
    error_norms,
    heading_deg,
    lap_mean,
    tilt_deg,
    track_clock,
)
from groundstation.evaluation.plotting import (
    EST_STYLE,
    REF_STYLE,
    TRUTH_STYLE,
    pyplot,
    save,
    since,
    t_origin,
    top_view,
)
from groundstation.evaluation.record import FlightRecord
from groundstation.flight.supervisor import AIRBORNE, State
from sim_device.evaluation.figures_disturbances import disturbance_figures
from sim_device.evaluation.figures_inputs import input_figures
from sim_device.evaluation.figures_shaped import shaped_figures
from sim_device.evaluation.scenarios import STEP_TIME_S

Records = Mapping[str, FlightRecord]
RATES = ("hover-1hz", "hover-10hz", "hover-100hz")
TRACKING = ("pid", "lqr-cp", "lqr-cv")
LABELS = {"pid": "PID", "lqr-cp": "LQR, constant position", "lqr-cv": "LQR, constant velocity"}


def _have(records: Records, names: tuple[str, ...]) -> bool:
    return all(n in records for n in names)


def _tracking(r: FlightRecord) -> np.ndarray:
    return r.during(State.TRACK)


def hover_rates(records: Records, out: Path) -> list[Path]:
    """Fig. 11.1 (x over time), 11.2 (top view) and 11.3 (1 Hz: estimate vs Vicon)."""
    if not _have(records, RATES):
        return []
    return [_hover_x(records, out / "fig11_1_hover_x.png"),
            _hover_top(records, out / "fig11_2_hover_top.png"),
            _estimate_vs_vicon(records["hover-1hz"], out / "fig11_3_hover_1hz.png")]


def _rate_label(name: str) -> str:
    return f"Vicon {name.split('-')[1][:-2]} Hz"


def _hover_x(records: Records, path: Path) -> Path:
    plt = pyplot()
    fig, axes = plt.subplots(3, 1, figsize=(9, 7.5), sharex=True, sharey=True)
    for ax, name in zip(axes, RATES, strict=True):
        r = records[name]
        tr = _tracking(r)
        t = since(r)[tr]
        ax.plot(t, 100 * r.position[tr, 0], color="C0", label="truth", **TRUTH_STYLE)
        ax.plot(t, 100 * r.est_pos[tr, 0], color="C1", label="estimate", **EST_STYLE)
        ax.plot(t, 100 * r.ref_pos[tr, 0], **REF_STYLE)
        ax.set(ylabel="x [cm]", title=_rate_label(name))
        ax.grid(True, alpha=0.3)
    axes[0].legend(fontsize=8, loc="upper right")
    axes[-1].set_xlabel("time since tracking started [s]")
    fig.suptitle("Hover at (0, 0, -1) m, constant-position LQR (cf. thesis Fig. 11.1)")
    return save(fig, path)


def _hover_top(records: Records, path: Path) -> Path:
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(6.5, 6.5))
    for k, name in enumerate(RATES):
        r = records[name]
        tr = _tracking(r)
        ax.plot(100 * r.position[tr, 1], 100 * r.position[tr, 0], color=f"C{k}", lw=0.9,
                label=_rate_label(name))
    ax.plot([0], [0], "k+", ms=14, label="reference")
    top_view(ax, "Hover seen from the ceiling (cf. thesis Fig. 11.2)", "cm")
    ax.legend(fontsize=8)
    return save(fig, path)


def _estimate_vs_vicon(r: FlightRecord, path: Path) -> Path:
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(9, 4))
    t0 = r.entered(State.TRACK)
    win = (r.t >= t0 + 5.0) & (r.t <= t0 + 15.0)
    vwin = (r.vicon_t >= t0 + 5.0) & (r.vicon_t <= t0 + 15.0)
    ax.plot(r.t[win] - t0, 100 * r.position[win, 0], color="C0", label="truth", **TRUTH_STYLE)
    ax.plot(r.t[win] - t0, 100 * r.est_pos[win, 0], color="C1", label="estimate", lw=1.0)
    ax.plot(r.vicon_t[vwin] - t0, 100 * r.vicon_pos[vwin, 0], "ks", ms=5,
            label="Vicon sample")
    ax.set(xlabel="time since tracking started [s]", ylabel="x [cm]",
           title="Vicon at 1 Hz: the estimate drifts between samples (cf. thesis Fig. 11.3)")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    return save(fig, path)


def steps(records: Records, models: Mapping[str, SimResult], out: Path) -> list[Path]:
    """Fig. 11.4: step responses on x, y and z: virtual lab (truth) and model simulation."""
    names = ("step-x", "step-y", "step-z")
    if not _have(records, names):
        return []
    plt = pyplot()
    fig, axes = plt.subplots(1, 3, figsize=(13, 4.2), sharey=True)
    for k, (ax, name) in enumerate(zip(axes, names, strict=True)):
        r = records[name]
        sign = -1.0 if k == 2 else 1.0  # z: plot the height, so the step is upwards
        tr = _tracking(r)
        clock = track_clock(r.t, tr)[tr] - STEP_TIME_S
        base = sign * r.ref_pos[tr, k][0]
        ax.plot(clock, sign * r.ref_pos[tr, k] - base, **REF_STYLE)
        ax.plot(clock, sign * r.position[tr, k] - base, color="C0", label="virtual lab (truth)",
                **TRUTH_STYLE)
        model = models.get(name)
        if model is not None:
            ax.plot(model.t - STEP_TIME_S, sign * model.position[:, k] - base, color="C2",
                    lw=1.0, ls="--", label="model simulation")
        ax.set(xlabel="time since the step [s]", title=f"step on {'xyz'[k]}"
               + (" (height, -z)" if k == 2 else ""), xlim=(-1.0, 8.0))
        ax.grid(True, alpha=0.3)
    axes[0].set_ylabel("change of position [m]")
    axes[0].legend(fontsize=8)
    fig.suptitle("Step responses, constant-velocity LQR, Vicon 10 Hz (cf. thesis Fig. 11.4)")
    return [save(fig, out / "fig11_4_steps.png")]


def _lap_path(r: FlightRecord, period: float) -> tuple[np.ndarray, np.ndarray, int]:
    """Mean path and reference over the whole laps after the first (which starts from
    rest), and how many laps that is (at least one)."""
    tr = _tracking(r)
    clock = track_clock(r.t, tr)
    whole = int(clock[-1] // period + 1e-6)
    first = 1 if whole > 1 else 0
    laps = max(whole - first, 1)
    _, mean = lap_mean(clock[tr], r.position[tr], period, laps, first)
    _, ref = lap_mean(clock[tr], r.ref_pos[tr], period, laps, first)
    return mean, ref, laps


def square(records: Records, out: Path, period: float = 20.0) -> list[Path]:
    """Fig. 11.5 (top view, mean of the laps after the first) and 11.6 (x, y over one lap)."""
    names = tuple(f"square-{c}" for c in TRACKING)
    if not _have(records, names):
        return []
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(7, 7))
    ref, laps = None, 0
    for k, c in enumerate(TRACKING):
        mean, ref, laps = _lap_path(records[f"square-{c}"], period)
        ax.plot(mean[:, 1], mean[:, 0], color=f"C{k}", lw=1.3, label=LABELS[c])
    assert ref is not None
    ax.plot(ref[:, 1], ref[:, 0], **REF_STYLE)
    top_view(ax, f"Square, clockwise, mean of {laps} laps (cf. thesis Fig. 11.5)")
    ax.legend(fontsize=8)
    paths = [save(fig, out / "fig11_5_square_top.png")]
    fig, axes = plt.subplots(2, 1, figsize=(10, 6.5), sharex=True)
    for k, c in enumerate(TRACKING):
        r = records[f"square-{c}"]
        tr = _tracking(r)
        clock = track_clock(r.t, tr)
        lap = tr & (clock >= period) & (clock <= 2 * period)
        for j, ax in enumerate(axes):
            if k == 0:
                ax.plot(clock[lap], r.ref_pos[lap, j], **REF_STYLE)
            ax.plot(clock[lap], r.position[lap, j], color=f"C{k}", lw=1.2, label=LABELS[c])
    for j, ax in enumerate(axes):
        ax.set(ylabel=f"{'xy'[j]} [m]")
        ax.grid(True, alpha=0.3)
    axes[0].legend(fontsize=8, loc="lower left")
    axes[1].set_xlabel("trajectory time [s] (second lap)")
    fig.suptitle("Square: x and y against the reference, showing the lag (cf. Fig. 11.6)")
    paths.append(save(fig, out / "fig11_6_square_xy.png"))
    return paths


def yz_rectangle(records: Records, out: Path, period: float = 20.0) -> list[Path]:
    """Fig. 11.7: the y-z rectangle seen from the side (y east right, height up)."""
    names = tuple(f"yz-rectangle-{c}" for c in TRACKING)
    if not _have(records, names):
        return []
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(8, 6))
    ref, laps = None, 0
    for k, c in enumerate(TRACKING):
        mean, ref, laps = _lap_path(records[f"yz-rectangle-{c}"], period)
        ax.plot(mean[:, 1], -mean[:, 2], color=f"C{k}", lw=1.3, label=LABELS[c])
    assert ref is not None
    ax.plot(ref[:, 1], -ref[:, 2], **REF_STYLE)
    ax.set(xlabel="y east [m]", ylabel="height -z [m]",
           title=f"Rectangle in the y-z plane, mean of {laps} laps (cf. thesis Fig. 11.7)")
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    return [save(fig, out / "fig11_7_yz_rectangle.png")]


def low_hover(records: Records, out: Path) -> list[Path]:
    """Fig. 11.8: hovering 2 cm above the floor, top view and height."""
    if "low-hover" not in records:
        return []
    r = records["low-hover"]
    plt = pyplot()
    fig, (ax, hx) = plt.subplots(1, 2, figsize=(12, 5), gridspec_kw={"width_ratios": [1, 1.6]})
    tr = _tracking(r)
    ax.plot(100 * r.position[tr, 1], 100 * r.position[tr, 0], color="C0", lw=0.9,
            label="truth")
    ax.plot(100 * r.ref_pos[tr, 1][:1], 100 * r.ref_pos[tr, 0][:1], "k+", ms=14,
            label="reference")
    top_view(ax, "top view while tracking", "cm")
    ax.legend(fontsize=8)
    air = r.during(*AIRBORNE)
    t = since(r)
    hx.plot(t[air], -100 * r.ref_pos[air, 2], **REF_STYLE)
    hx.plot(t[air], -100 * r.position[air, 2], color="C0", label="truth", **TRUTH_STYLE)
    hx.plot(t[air], -100 * r.est_pos[air, 2], color="C1", label="estimate", **EST_STYLE)
    hx.set(xlabel="time since tracking started [s]", ylabel="height -z [cm]", title="height")
    hx.grid(True, alpha=0.3)
    hx.legend(fontsize=8)
    fig.suptitle("Hover at 2 cm (cf. thesis Fig. 11.8)")
    return [save(fig, out / "fig11_8_low_hover.png")]


def outage(records: Records, out: Path) -> list[Path]:
    """The 1 s Vicon outage on the square: errors over time with the outage and HOLD shaded."""
    if "square-vicon-outage" not in records:
        return []
    r = records["square-vicon-outage"]
    plt = pyplot()
    fig, (ax, top) = plt.subplots(1, 2, figsize=(13, 5), gridspec_kw={"width_ratios": [1.6, 1]})
    t = since(r)
    t0 = t_origin(r)
    hold = r.during(State.HOLD)
    t_hold = float(t[hold][0]) if hold.any() else 8.0
    air = r.during(*AIRBORNE) & (t > t_hold - 4.0) & (t < t_hold + 6.0)
    gaps = np.flatnonzero(np.diff(r.vicon_t) > 0.5)
    for i in gaps:
        ax.axvspan(r.vicon_t[i] - t0, r.vicon_t[i + 1] - t0, color="0.85", label="no Vicon")
    if hold.any():
        ax.axvspan(t[hold][0], t[hold][-1], color="C3", alpha=0.2, label="HOLD")
    ax.plot(t[air], 100 * error_norms(r.position[air], r.ref_pos[air]), color="C0",
            label="|truth - reference|")
    ax.plot(t[air], 100 * error_norms(r.est_pos[air], r.position[air]), color="C1",
            label="|estimate - truth|")
    ax.set(xlabel="time since tracking started [s]", ylabel="error [cm]",
           title="errors around the outage")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    top.plot(r.ref_pos[air, 1], r.ref_pos[air, 0], **REF_STYLE)
    top.plot(r.position[air, 1], r.position[air, 0], color="C0", label="truth", **TRUTH_STYLE)
    top.plot(r.position[hold, 1], r.position[hold, 0], color="C3", lw=2.5, label="in HOLD")
    top_view(top, "top view, same time window")
    top.legend(fontsize=8)
    fig.suptitle("Square with a 1 s Vicon outage: HOLD on the IMU estimate, then resume")
    return [save(fig, out / "vicon_outage.png")]


def thrust_error(records: Records, out: Path) -> list[Path]:
    """10 % less lift than the model: height over the hover, square top view vs nominal."""
    if not _have(records, ("hover-thrust-error", "square-thrust-error")):
        return []
    plt = pyplot()
    fig, (hx, top) = plt.subplots(1, 2, figsize=(13, 5.5))
    r = records["hover-thrust-error"]
    air = r.during(*AIRBORNE)
    t = since(r)
    hx.plot(t[air], -r.ref_pos[air, 2], **REF_STYLE)
    hx.plot(t[air], -r.position[air, 2], color="C0", label="truth", **TRUTH_STYLE)
    hx.set(xlabel="time since tracking started [s]", ylabel="height -z [m]",
           title="hover: take-off, hover, landing")
    hx.grid(True, alpha=0.3)
    hx.legend(fontsize=8)
    for k, name in enumerate(("square-lqr-cv", "square-thrust-error")):
        if name in records:
            s = records[name]
            tr = _tracking(s)
            top.plot(s.position[tr, 1], s.position[tr, 0], color=f"C{k}", lw=1.0,
                     label="nominal lift" if k == 0 else "10 % less lift")
    sq = records["square-thrust-error"]
    top.plot(sq.ref_pos[_tracking(sq), 1], sq.ref_pos[_tracking(sq), 0], **REF_STYLE)
    top_view(top, "square (constant-velocity LQR)")
    top.legend(fontsize=8)
    fig.suptitle("10 % thrust error (battery): the disturbance observer removes it")
    return [save(fig, out / "thrust_error.png")]


def hinf(records: Records, out: Path, tilt_limit_deg: float = 35.0) -> list[Path]:
    """The two H-infinity designs (and the rate-loop design with rate gains 30 % off, when
    flown): tilt, height and heading from take-off."""
    names = ("hinf-thesis-model", "hinf-rate-loop-model")
    if not _have(records, names):
        return []
    plt = pyplot()
    fig, (tx, hx, yx) = plt.subplots(3, 1, figsize=(10, 9.5), sharex=True)
    labels = ["designed on the thesis's model", "designed with the rate-loop lag"]
    extra = [(n, f"with the lag, rate gains 30 % {n.rsplit('-', 1)[1]}")
             for n in ("hinf-rate-gains-low", "hinf-rate-gains-high") if n in records]
    colors = ("C0", "C1", "C2", "C4")  # C3 is the tilt limit
    for color, (name, label) in zip(colors, [*zip(names, labels, strict=True), *extra],
                                    strict=False):
        r = records[name]
        air = r.during(*AIRBORNE)
        t = r.t - r.entered(State.TAKEOFF)
        tx.plot(t[air], tilt_deg(r.attitude[air]), color=color, label=label)
        hx.plot(t[air], -r.position[air, 2], color=color, label=label)
        yx.plot(t[air], np.degrees(np.unwrap(np.radians(heading_deg(r.attitude[air])))),
                color=color, label=label)
    tx.axhline(tilt_limit_deg, color="C3", ls="--", lw=1, label="supervisor tilt limit")
    tx.set(ylabel="tilt [deg]", ylim=(0.0, None))
    hx.set(ylabel="height -z [m]")
    yx.set(xlabel="time since take-off [s]", ylabel="heading [deg] (reference: held)")
    for ax in (tx, hx, yx):
        ax.grid(True, alpha=0.3)
    tx.legend(fontsize=8)
    fig.suptitle("H-infinity in the virtual lab (cf. thesis Ch. 10.3: the design without the "
                 "on-board dynamics does not hover)")
    return [save(fig, out / "hinf.png")]


def all_figures(records: Records, models: Mapping[str, SimResult], out: Path,
                period_s: float = 20.0) -> list[Path]:
    """Every figure whose flights are present; returns the PNG paths written.

    models : model-only simulations of the step flights (by scenario name);
    period_s : lap time of the square and the rectangle [s].
    """
    makers: list[Callable[[], list[Path]]] = [
        lambda: hover_rates(records, out), lambda: steps(records, models, out),
        lambda: square(records, out, period_s), lambda: yz_rectangle(records, out, period_s),
        lambda: low_hover(records, out), lambda: outage(records, out),
        lambda: thrust_error(records, out), lambda: hinf(records, out),
        lambda: shaped_figures(records, out), lambda: input_figures(records, out),
        lambda: disturbance_figures(records, out),
    ]
    paths: list[Path] = []
    for make in makers:
        paths += make()
    return paths

