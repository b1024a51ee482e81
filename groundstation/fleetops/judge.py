"""A fleet's flights judged against the virtual lab's ground truth.

Used by ``gs fleet demo``, the fleet's tests and ``benchmarks/bench_fleet.py``: for one
vehicle, its flight log (the reference it tracked, the supervisor's state, row by row on
the daemon's monotonic clock) and its truth file (the true position, on the lab's clock,
``start_monotonic`` aligning the two) give the true distance from the reference.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from groundstation.app.recorder import read_flight
from groundstation.flight.supervisor import State
from groundstation.types import FloatArray


@dataclass(frozen=True)
class Tracking:
    """One flight against the truth: per log row ``t`` (monotonic [s]), ``state``, the
    reference and the true position (NED [m]) and their distance ``error`` [m]."""

    t: FloatArray
    state: FloatArray
    reference: FloatArray
    truth: FloatArray
    error: FloatArray

    def window(self, state: State, start_after_s: float = 0.0,
               at_rest: bool = False, until: float | None = None) -> FloatArray:
        """The errors [m] in ``state``, from ``start_after_s`` after the first row in it
        up to the monotonic time ``until`` [s] (None: to the end); ``at_rest``: only rows
        whose reference does not move (a hover)."""
        rows = self.state == int(state)
        if not rows.any():
            return np.zeros(0)
        rows &= self.t >= self.t[rows][0] + start_after_s
        if until is not None:
            rows &= self.t <= until
        if at_rest:
            step = np.r_[0.0, np.linalg.norm(np.diff(self.reference, axis=0), axis=1)]
            rows &= step < 1e-6
        out: FloatArray = self.error[rows]
        return out


def tracking(log_dir: str | Path, truth_file: str | Path) -> Tracking:
    """The flight in ``log_dir`` against the truth in ``truth_file`` (see the module
    docstring); rows without a reference or outside the truth's span are dropped."""
    rows, _meta, _config = read_flight(log_dir)
    truth = np.load(truth_file)
    t_truth = truth["t"] + float(truth["start_monotonic"])
    t = rows["t"].astype(float)
    ref = np.asarray(rows["ref_position"], dtype=float)
    keep = np.isfinite(ref).all(axis=1) & (t >= t_truth[0]) & (t <= t_truth[-1])
    t, ref = t[keep], ref[keep]
    true = np.column_stack([np.interp(t, t_truth, truth["position"][:, k]) for k in range(3)])
    return Tracking(t, rows["state"][keep].astype(float), ref, true,
                    np.linalg.norm(true - ref, axis=1))


def rms(errors: FloatArray) -> float:
    """Root mean square [m] (NaN if empty)."""
    return float(np.sqrt(np.mean(np.square(errors)))) if len(errors) else float("nan")
