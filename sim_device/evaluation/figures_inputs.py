"""Figures of the flights on inputs users bring: trajectory files and a Vicon sender with
exact angles.

Same conventions as :mod:`sim_device.evaluation.figures`: ground truth solid, references
dotted black, top views NED from above (x north up, y east right), times since tracking
started, errors in cm on their own axes. Under ``gs eval --perturb`` each record is its
scenario's worst flight and the titles name its seed.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import numpy as np

from groundstation.evaluation.metrics import error_norms
from groundstation.evaluation.plotting import REF_STYLE, TRUTH_STYLE, pyplot, save, since, top_view
from groundstation.evaluation.record import FlightRecord
from groundstation.flight.supervisor import State
from sim_device.evaluation.targets import TARGETS

Records = Mapping[str, FlightRecord]
FILE_FLIGHTS = ("file-eight-8s", "file-eight-4s", "file-figure8")
"""The trajectory-file scenarios, one column each."""


def _seed(r: FlightRecord) -> str:
    seed = r.meta.get("seed")
    return f", seed {seed}" if seed is not None else ""


def _target_cm(name: str) -> float:
    return 100.0 * TARGETS[name][0].limit


def trajectory_files(records: Records, out: Path) -> list[Path]:
    """Per file flight: the top view (truth against the fitted reference) and the error."""
    names = [n for n in FILE_FLIGHTS if n in records]
    if not names:
        return []
    plt = pyplot()
    fig, axes = plt.subplots(2, len(names), figsize=(5.5 * len(names), 9.0), squeeze=False,
                             gridspec_kw={"height_ratios": [1.4, 1]})
    for k, name in enumerate(names):
        r = records[name]
        tr = r.during(State.TRACK)
        ax, err = axes[0][k], axes[1][k]
        ax.plot(r.ref_pos[tr, 1], r.ref_pos[tr, 0], **REF_STYLE)
        ax.plot(r.position[tr, 1], r.position[tr, 0], color="C0", label="truth", **TRUTH_STYLE)
        top_view(ax, f"{name}{_seed(r)}")
        ax.legend(fontsize=8, loc="upper right")
        t = since(r)
        e = 100.0 * error_norms(r.position[tr], r.ref_pos[tr])
        rms = float(np.sqrt(np.mean(e**2)))
        err.plot(t[tr], e, color="C0", lw=1.0, label=f"|truth - reference|, RMS {rms:.2f} cm")
        err.axhline(_target_cm(name), color="C3", ls="--", lw=1,
                    label=f"target: {_target_cm(name):g} cm RMS")
        err.set(xlabel="time since tracking started [s]", ylabel="error [cm]",
                ylim=(0.0, None))
        err.grid(True, alpha=0.3)
        err.legend(fontsize=8, loc="upper right")
    fig.suptitle("Trajectory files as users bring them (fitted dense CSVs, polynomial "
                 "segments), Vicon 10 Hz")
    return [save(fig, out / "trajectory_files.png")]


def exact_angles(records: Records, out: Path) -> list[Path]:
    """The hover on an exact-angle Vicon sender: position error over time, and top view."""
    name = "hover-exact-angles"
    if name not in records:
        return []
    r = records[name]
    plt = pyplot()
    fig, (top, err) = plt.subplots(1, 2, figsize=(12, 5.0),
                                   gridspec_kw={"width_ratios": [1, 1.5]})
    tr = r.during(State.TRACK)
    top.plot(100.0 * (r.position[tr, 1] - r.ref_pos[tr, 1]),
             100.0 * (r.position[tr, 0] - r.ref_pos[tr, 0]), color="C0", lw=0.8,
             label="truth - reference")
    top.set(xlabel="east [cm]", ylabel="north [cm]", title=f"hover, seen from above{_seed(r)}")
    top.set_aspect("equal", adjustable="datalim")
    top.grid(True, alpha=0.3)
    t = since(r)
    e = 100.0 * error_norms(r.position[tr], r.ref_pos[tr])
    rms = float(np.sqrt(np.mean(e**2)))
    err.plot(t[tr], e, color="C0", lw=1.0, label=f"|truth - reference|, RMS {rms:.2f} cm")
    err.axhline(_target_cm(name), color="C3", ls="--", lw=1,
                label=f"target: {_target_cm(name):g} cm RMS")
    err.set(xlabel="time since tracking started [s]", ylabel="error [cm]", ylim=(0.0, None))
    err.grid(True, alpha=0.3)
    err.legend(fontsize=8, loc="upper right")
    fig.suptitle("Hover on a Vicon sender with exact angles (rotation exactly 0 when level at "
                 "heading 0), Vicon 10 Hz")
    return [save(fig, out / "exact_angles.png")]


def input_figures(records: Records, out: Path) -> list[Path]:
    """Every figure of this module whose flights are present."""
    return [*trajectory_files(records, out), *exact_angles(records, out)]
