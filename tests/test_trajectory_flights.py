"""Trajectory files flown in the virtual lab (in-process, simulated clock): a dense
waypoint CSV of a figure-eight, written by numpy from the closed form at 50 Hz, at 8 s
and 4 s a lap, and the Crazyflie examples' figure8.csv (polynomial segments). Each flight
ends DONE, and the ground truth follows the reference it was given: the RMS distance
between the plant's true position and the reference at the same instant, over tracking.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from lab_helpers import sim_config

from groundstation.app.inprocess import fly_in_process
from groundstation.evaluation.record import align_truth
from groundstation.flight.assembly import assemble
from groundstation.flight.supervisor import State

FIGURE8 = Path(__file__).resolve().parent / "data" / "figure8.csv"


def eight_csv(path: Path, period: float, hz: float = 50.0) -> Path:
    """One lap of x = 0.3 sin 2wt, y = 0.6 sin wt at 1 m height, as numpy writes it."""
    w = 2 * math.pi / period
    t = np.arange(0.0, period + 0.5 / hz, 1.0 / hz)
    rows = np.column_stack([t, 0.3 * np.sin(2 * w * t), 0.6 * np.sin(w * t), -np.ones_like(t)])
    np.savetxt(path, rows, delimiter=",", header="t,x,y,z", comments="")
    return path


def tracking_rms(file: Path) -> tuple[float, float]:
    """(RMS [m], tracked seconds) of truth minus reference over TRACK for ``file``."""
    cfg = sim_config(**{"trajectory.name": "waypoints", "trajectory.file": str(file)})
    result = fly_in_process(assemble(cfg), max_time_s=60.0)
    assert result.final_state is State.DONE, result.transitions
    trace = result.trace
    log = result.lab.truth_log.arrays()
    truth, _ = align_truth(trace["t"], log["t"], log["position"], log["quaternion"])
    track = trace["state"] == int(State.TRACK)
    error = np.linalg.norm(truth[track] - trace["ref_pos"][track], axis=1)
    return float(np.sqrt(np.mean(error ** 2))), float(np.count_nonzero(track)) / 100.0


@pytest.mark.slow
@pytest.mark.parametrize(("period", "limit_m"), [(8.0, 0.010), (4.0, 0.025)])
def test_a_dense_csv_figure_eight_is_flown_and_tracked(tmp_path: Path, period: float,
                                                       limit_m: float) -> None:
    rms, tracked = tracking_rms(eight_csv(tmp_path / "eight.csv", period))
    assert tracked >= period  # the whole lap (and its ease) was flown
    assert rms <= limit_m, f"{rms * 100:.2f} cm RMS"


@pytest.mark.slow
def test_the_crazyflie_figure8_is_flown_and_tracked() -> None:
    rms, tracked = tracking_rms(FIGURE8)
    assert tracked >= 7.28
    assert rms <= 0.025, f"{rms * 100:.2f} cm RMS"
