"""Plot helpers shared by the suite's figures and ``gs report``, and the one-flight figure.

matplotlib is optional (the ``dev`` and ``plot`` extras); :func:`pyplot` imports
it lazily with the non-interactive Agg backend and raises a clear error
without it. Top views are NED seen from above: x (north) up, y (east) right.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from groundstation.errors import GroundStationError
from groundstation.evaluation.metrics import error_norms
from groundstation.evaluation.record import FlightRecord
from groundstation.loop.supervisor import AIRBORNE, State
from groundstation.types import FloatArray

TRUTH_STYLE: dict[str, Any] = {"lw": 1.3}
EST_STYLE: dict[str, Any] = {"lw": 0.8, "ls": "--", "alpha": 0.9}
REF_STYLE: dict[str, Any] = {"color": "k", "lw": 1.0, "ls": ":", "label": "reference"}
DPI = 110


def pyplot() -> Any:
    """``matplotlib.pyplot`` on the Agg backend; GroundStationError if not installed."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError as exc:
        raise GroundStationError("figures need matplotlib: pip install "
                                 "'groundstation[plot]'") from exc
    return plt


def save(fig: Any, path: Path) -> Path:
    """Write ``fig`` as PNG to ``path`` and close it."""
    fig.tight_layout()
    fig.savefig(path, dpi=DPI)
    pyplot().close(fig)
    return path


def t_origin(record: FlightRecord) -> float:
    """Time origin for plots: tracking start, else take-off, else the first tick [s]."""
    for state in (State.TRACK, State.TAKEOFF):
        t0 = record.entered(state)
        if not math.isnan(t0):
            return t0
    return float(record.t[0])


def since(record: FlightRecord) -> FloatArray:
    """Tick times relative to :func:`t_origin` [s]."""
    return np.asarray(record.t - t_origin(record))


def top_view(ax: Any, title: str, unit: str = "m") -> None:
    """Label ``ax`` as a NED top view (y east right, x north up), equal aspect."""
    ax.set(xlabel=f"y east [{unit}]", ylabel=f"x north [{unit}]", title=title)
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(True, alpha=0.3)


def flight_figure(record: FlightRecord, path: Path, title: str) -> Path:
    """One flight on four panels: top view, x/y/z over time, errors, timing histogram.

    Reference dotted black; estimate dashed; truth solid (when the record has it).
    """
    plt = pyplot()
    fig, axes = plt.subplots(2, 2, figsize=(12, 8.5))
    air = record.during(*AIRBORNE)
    t = since(record)
    ax = axes[0, 0]
    ax.plot(record.ref_pos[air, 1], record.ref_pos[air, 0], **REF_STYLE)
    ax.plot(record.est_pos[air, 1], record.est_pos[air, 0], color="C0", label="estimate",
            **EST_STYLE)
    if record.true_pos is not None:
        ax.plot(record.true_pos[air, 1], record.true_pos[air, 0], color="C1", label="truth",
                **TRUTH_STYLE)
    top_view(ax, "top view (airborne)")
    ax.legend(fontsize=8)
    ax = axes[0, 1]
    for k, name in enumerate("xyz"):
        ax.plot(t, record.ref_pos[:, k], color=f"C{k}", lw=0.8, ls=":")
        ax.plot(t, record.position[:, k], color=f"C{k}", lw=1.0, label=name)
    ax.set(xlabel="time since tracking started [s]", ylabel="position NED [m]",
           title=f"position ({record.truth_source}) and reference (dotted)")
    ax.legend(fontsize=8)
    ax = axes[1, 0]
    ax.plot(t[air], 100 * error_norms(record.position[air], record.ref_pos[air]), color="C3",
            lw=1.0, label="|position - reference|")
    if record.true_pos is not None:
        ax.plot(t[air], 100 * error_norms(record.est_pos[air], record.true_pos[air]),
                color="C2", lw=1.0, label="|estimate - truth|")
    ax.set(xlabel="time since tracking started [s]", ylabel="error [cm]", title="errors")
    ax.legend(fontsize=8)
    ax = axes[1, 1]
    _timing_hist(ax, record)
    for a in axes.flat[1:]:
        a.grid(True, alpha=0.3)
    fig.suptitle(title)
    return save(fig, path)


def _timing_hist(ax: Any, record: FlightRecord) -> None:
    series = [("compute", record.compute_s)]
    if record.latency_s is not None:
        series.append(("DATA->COMMAND latency", record.latency_s))
    for k, (name, values) in enumerate(series):
        v = 1e6 * values[np.isfinite(values)]
        if v.size:
            ax.hist(v, bins=60, color=f"C{k}", alpha=0.6, label=name)
    ax.set(xlabel="time per tick [us]", ylabel="ticks", yscale="log",
           title="timing: " + record.timing_source)
    ax.title.set_fontsize(8)
    ax.legend(fontsize=8)
