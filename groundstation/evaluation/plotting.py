"""Plot helpers shared by the suite's figures, ``gs report``'s
(:mod:`groundstation.evaluation.flight_figures`) and the identification figures.

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
from groundstation.evaluation.record import FlightRecord
from groundstation.flight.supervisor import State
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
    """Write ``fig`` as PNG to ``path`` and close it (tight layout unless the figure
    has a layout engine of its own, e.g. ``layout="constrained"``)."""
    if fig.get_layout_engine() is None:
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
