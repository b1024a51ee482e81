"""Plots of a recorded flight: flown path against the reference.

matplotlib is optional (installed by the ``dev`` and ``plot`` extras, not by the
lab deployment); :func:`plot_flight` raises a clear error without it.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from groundstation.errors import GroundStationError
from groundstation.loop.recorder import read_flight
from groundstation.loop.supervisor import State


def plot_flight(log_dir: str | Path, out_png: str | Path,
                truth_file: str | Path | None = None) -> Path:
    """Top view (x, y) and height over time of a flight: reference, estimate and, when a
    virtual-lab truth file (.npz) is given, the true path. Returns the PNG path."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError as exc:
        raise GroundStationError("plotting needs matplotlib: pip install "
                                 "'groundstation[plot]'") from exc
    rows, meta, _ = read_flight(log_dir)
    flying = np.isin(rows["state"], [State.TAKEOFF, State.TRACK, State.HOLD, State.LAND])
    t0 = float(rows["t"][0]) if rows.size else 0.0
    fig, (top, height) = plt.subplots(1, 2, figsize=(11, 4.8))
    ref, est = rows["ref_position"][flying], rows["est_position"][flying]
    # NED top view: north (x) up, east (y) right, as seen from the ceiling.
    top.plot(ref[:, 1], ref[:, 0], "k--", lw=1, label="reference")
    top.plot(est[:, 1], est[:, 0], "C0", lw=1, label="estimate")
    height.plot(rows["t"] - t0, -rows["ref_position"][:, 2], "k--", lw=1, label="reference")
    height.plot(rows["t"] - t0, -rows["est_position"][:, 2], "C0", lw=1, label="estimate")
    if truth_file is not None and Path(truth_file).exists():
        truth = np.load(truth_file)
        pos = truth["position"]
        airborne = ~truth["on_ground"]
        top.plot(pos[airborne, 1], pos[airborne, 0], "C1", lw=1, alpha=0.8, label="truth")
    top.set(xlabel="y east [m]", ylabel="x north [m]", title="top view", aspect="equal")
    height.set(xlabel="time since start [s]", ylabel="height -z [m]", title="height")
    for ax in (top, height):
        ax.grid(True, alpha=0.3)
        ax.legend(loc="best", fontsize=8)
    fig.suptitle(f"flight {Path(log_dir).name} ({meta.get('version', '?')})")
    fig.tight_layout()
    out = Path(out_png)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out
