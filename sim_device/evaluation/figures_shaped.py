"""The shaped flights' figures: figure-eight, yaw turn, the square at two headings, take-off
at 135 degrees.

Same conventions as :mod:`sim_device.evaluation.figures`: ground truth solid,
references dotted black, top views NED from above (x north up, y east right), times
since tracking started. Under ``gs eval --perturb`` each record is its scenario's worst
flight and the titles name its seed. Errors are drawn on their own axes in cm: at the
scale of a 1 m path, sub-centimetre errors do not show on a top view.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from groundstation.evaluation.metrics import (
    error_norms,
    heading_deg,
    path_distances,
    track_clock,
)
from groundstation.evaluation.plotting import REF_STYLE, TRUTH_STYLE, pyplot, save, since, top_view
from groundstation.evaluation.record import FlightRecord
from groundstation.flight.supervisor import AIRBORNE, State
from sim_device.evaluation.scenarios import EIGHT

Records = Mapping[str, FlightRecord]
LAP_S = float(EIGHT["trajectory.period_s"])
"""Lap time of the figure-eight [s]."""
SQUARE_LAP_S = 20.0
"""Lap time of the square [s] (trajectory.period_s of the Ch. 11 square)."""
ALL_LABELS = {"pid": "PID", "lqr-cp": "LQR, constant position",
              "lqr-cv": "LQR, constant velocity", "lqr-ff": "LQR, feed-forward (lqr-ff)"}


def _seed(r: FlightRecord) -> str:
    seed = r.meta.get("seed")
    return f", seed {seed}" if seed is not None else ""


def _track(r: FlightRecord) -> np.ndarray:
    return r.during(State.TRACK)


def _heading_arrows(ax: Any, r: FlightRecord, mask: np.ndarray, n: int = 8,
                    length: float = 0.08) -> None:
    """Nose direction (truth) at ``n`` points, evenly spaced in time over ``mask``, of a top
    view in metres (limits widened by ``length`` so the arrows stay inside)."""
    idx = np.flatnonzero(mask)[:: max(int(mask.sum()) // n, 1)]
    psi = np.radians(heading_deg(r.attitude[idx]))
    ax.quiver(r.position[idx, 1], r.position[idx, 0], length * np.sin(psi),
              length * np.cos(psi), angles="xy", scale_units="xy", scale=1.0, width=0.005,
              color="C3", label="nose (heading)")
    pad = length + 0.02
    ax.set(xlim=(r.position[mask, 1].min() - pad, r.position[mask, 1].max() + pad),
           ylim=(r.position[mask, 0].min() - pad, r.position[mask, 0].max() + pad))
    ax.set_aspect("equal", adjustable="box")  # fixed limits: keep the aspect with the box


def figure_eight(records: Records, out: Path) -> list[Path]:
    """Top views of lqr-ff and of the comparison controllers, and lqr-ff's errors."""
    if "figure-eight-lqr-ff" not in records:
        return []
    r = records["figure-eight-lqr-ff"]
    plt = pyplot()
    fig, (ax, cmp_ax, err) = plt.subplots(1, 3, figsize=(17, 6.0),
                                          gridspec_kw={"width_ratios": [1, 1, 1.25]})
    tr = _track(r)
    ax.plot(r.ref_pos[tr, 1], r.ref_pos[tr, 0], **REF_STYLE)
    ax.plot(r.position[tr, 1], r.position[tr, 0], color="C0", label="lqr-ff (truth)",
            **TRUTH_STYLE)
    top_view(ax, f"lqr-ff, every lap{_seed(r)}")
    ax.legend(fontsize=8, loc="upper right")
    cmp_ax.plot(r.ref_pos[tr, 1], r.ref_pos[tr, 0], **REF_STYLE)
    for k, c in enumerate(("lqr-ff", "lqr-cv", "lqr-cp", "pid")):
        name = f"figure-eight-{c}"
        if name in records:
            o = records[name]
            clock = track_clock(o.t, _track(o))
            lap = _track(o) & (clock >= LAP_S) & (clock <= 2 * LAP_S)
            cmp_ax.plot(o.position[lap, 1], o.position[lap, 0], color=f"C{k}", lw=1.1,
                        label=f"{ALL_LABELS[c]}{_seed(o)}")
    top_view(cmp_ax, "second lap, per controller")
    cmp_ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.14), ncol=2)
    t = since(r)
    err.plot(t[tr], 100 * error_norms(r.position[tr], r.ref_pos[tr]), color="C0", lw=1.0,
             label="|truth - reference| (in time)")
    err.plot(t[tr], 100 * path_distances(r.position[tr], r.ref_pos[tr]), color="C2", lw=1.0,
             label="distance off the path")
    err.axhline(2.0, color="C3", ls="--", lw=1, label="target: 2 cm RMS in time")
    err.axvspan(0.0, LAP_S, color="0.9", label="first lap (not scored)")
    err.set(xlabel="time since tracking started [s]", ylabel="error [cm]", ylim=(0.0, None),
            title="lqr-ff: error")
    err.grid(True, alpha=0.3)
    err.legend(fontsize=8, loc="upper right")
    speed = np.linalg.norm(np.gradient(r.ref_pos[tr], r.t[tr], axis=0), axis=1)
    fig.suptitle(f"Figure-eight 1.2 m x 0.6 m, 8 s per lap ({float(np.max(speed)):.2f} m/s "
                 "peak), Vicon 10 Hz")
    return [save(fig, out / "figure_eight.png")]


def yaw_turn(records: Records, out: Path) -> list[Path]:
    """Heading against the reference, heading error and horizontal position error."""
    if "yaw-turn" not in records:
        return []
    r = records["yaw-turn"]
    plt = pyplot()
    fig, (hx, ex, px) = plt.subplots(3, 1, figsize=(10, 8.5), sharex=True,
                                     gridspec_kw={"height_ratios": [1.4, 1, 1]})
    air = r.during(*AIRBORNE)
    tr = _track(r)
    t = since(r)
    truth = np.degrees(np.unwrap(np.radians(heading_deg(r.attitude[air]))))
    hx.plot(t[air], truth, color="C0", label="heading (truth)", **TRUTH_STYLE)
    if r.ref_yaw is not None:
        ref = np.degrees(np.unwrap(r.ref_yaw[air]))
        hx.plot(t[air], ref, **REF_STYLE)
        err = (truth - ref + 180.0) % 360.0 - 180.0
        ex.plot(t[air], err, color="C0", lw=1.0, label="heading - reference")
    for ax in (hx, ex, px):
        ax.axvspan(float(t[tr][0]), float(t[tr][-1]), color="0.93", zorder=0)
    ex.axhline(5.0, color="C3", ls="--", lw=1, label="+-5 deg (target at the end)")
    ex.axhline(-5.0, color="C3", ls="--", lw=1)
    horiz = 100 * error_norms(r.position[tr, :2], r.ref_pos[tr, :2])
    px.plot(t[tr], horiz, color="C2", lw=1.0, label="horizontal |truth - reference| (tracking)")
    px.plot(t[tr], 100 * np.abs(r.position[tr, 2] - r.ref_pos[tr, 2]), color="C1", lw=0.8,
            label="vertical")
    hx.set(ylabel="heading [deg]",
           title=f"360 degree yaw turn in 20 s holding position (grey: tracking){_seed(r)}")
    ex.set(ylabel="heading error [deg]")
    px.set(xlabel="time since tracking started [s]", ylabel="position error [cm]",
           ylim=(0.0, None))
    for ax, where in ((hx, "upper left"), (ex, "upper left"), (px, "upper right")):
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=8, loc=where)
    return [save(fig, out / "yaw_turn.png")]


def square_headings(records: Records, out: Path) -> list[Path]:
    """The shaped square at heading 0 and 135: top views with the nose, and the error."""
    names = ("square-shaped-lqr-ff", "square-shaped-h135-lqr-ff")
    if not all(n in records for n in names):
        return []
    plt = pyplot()
    fig, axes = plt.subplots(1, 3, figsize=(17, 5.6), gridspec_kw={"width_ratios": [1, 1, 1.3]})
    err = axes[2]
    for k, (ax, name, heading) in enumerate(zip(axes[:2], names, (0, 135), strict=True)):
        r = records[name]
        tr = _track(r)
        ax.plot(r.ref_pos[tr, 1], r.ref_pos[tr, 0], **REF_STYLE)
        ax.plot(r.position[tr, 1], r.position[tr, 0], color=f"C{k}", label="truth",
                **TRUTH_STYLE)
        first_lap = tr & (track_clock(r.t, tr) < SQUARE_LAP_S)
        _heading_arrows(ax, r, first_lap)
        top_view(ax, f"heading {heading} deg{_seed(r)}")
        ax.legend(fontsize=8, loc="center")
        t = since(r)
        err.plot(t[tr], 100 * path_distances(r.position[tr], r.ref_pos[tr]), color=f"C{k}",
                 lw=1.0, label=f"heading {heading} deg: off the path")
        err.plot(t[tr], 100 * error_norms(r.position[tr], r.ref_pos[tr]), color=f"C{k}",
                 lw=0.7, ls="--", label=f"heading {heading} deg: in time")
    err.axhline(1.0, color="C3", ls=":", lw=1, label="targets: 1 cm RMS off path")
    err.axhline(1.5, color="C3", ls="--", lw=1, label="1.5 cm RMS in time")
    top = max(2.2, 1.1 * err.get_ylim()[1])
    err.set(xlabel="time since tracking started [s]", ylabel="error [cm]", ylim=(0.0, top),
            title="errors (a corner every 5 s)")
    err.grid(True, alpha=0.3)
    err.legend(fontsize=7, loc="upper center", ncol=3)
    fig.suptitle("Shaped 0.75 m square (min-jerk), lqr-ff, Vicon 10 Hz, at two headings")
    return [save(fig, out / "square_headings.png")]


def takeoff(records: Records, out: Path) -> list[Path]:
    """Take-off at heading 135 from 2 cm off the hover point: top view and heading."""
    if "takeoff-h135" not in records:
        return []
    r = records["takeoff-h135"]
    plt = pyplot()
    fig, (ax, hx) = plt.subplots(1, 2, figsize=(13, 5.2), gridspec_kw={"width_ratios": [1, 1.5]})
    air = r.during(*AIRBORNE)
    up = r.during(State.TAKEOFF)
    tr = _track(r)
    hover = r.ref_pos[tr][-1] if tr.any() else r.ref_pos[air][-1]
    rel = 100 * (r.position - hover)
    ax.plot(rel[up, 1], rel[up, 0], color="C1", lw=1.2, label="take-off")
    ax.plot(rel[tr, 1], rel[tr, 0], color="C0", lw=0.9, label="hover (tracking)")
    ax.plot(rel[air, 1][:1], rel[air, 0][:1], "o", color="C1", ms=7, label="start (2 cm north)")
    ax.plot([0.0], [0.0], "k+", ms=14, label="hover point")
    top_view(ax, f"top view around the hover point{_seed(r)}", "cm")
    ax.legend(fontsize=8)
    t = r.t - r.entered(State.TAKEOFF)
    hx.plot(t[air], heading_deg(r.attitude[air]), color="C0", label="heading (truth)",
            **TRUTH_STYLE)
    if r.ref_yaw is not None:
        hx.plot(t[air], np.degrees(r.ref_yaw[air]), **REF_STYLE)
    if tr.any():
        hx.axvspan(float(t[tr][0]), float(t[tr][-1]), color="0.93", zorder=0,
                   label="tracking")
    hx.set(xlabel="time since take-off started [s]", ylabel="heading [deg]",
           title="heading (free: the heading the vehicle was placed at)")
    hx.grid(True, alpha=0.3)
    hx.legend(fontsize=8)
    fig.suptitle("Take-off from 2 cm north of the hover point at heading 135 degrees, lqr-ff")
    return [save(fig, out / "takeoff_h135.png")]


def shaped_figures(records: Records, out: Path) -> list[Path]:
    """Every figure of the shaped flights whose flights are present."""
    return [*figure_eight(records, out), *yaw_turn(records, out),
            *square_headings(records, out), *takeoff(records, out)]
