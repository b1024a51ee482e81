"""Scoring of one flight (path, corner and heading figures), the worst case over perturbed
plants, and the evaluation's targets.

Expected values are closed forms: a flight that follows the reference path late is on
the path (0 off it) but ``v d`` behind it in time; a path that cuts a square's corner
by a chamfer ``c`` along each edge passes the corner at ``c / sqrt(2)``; a constant
heading offset is its own RMS and end error, across the +-180 degree wrap. The worst
case is checked against the per-seed numbers written by hand.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from groundstation.evaluation.record import TRUTH_LAB, FlightRecord
from groundstation.evaluation.scoring import flight_metrics, worst_case
from groundstation.flight.supervisor import State
from groundstation.model.quaternion import quat_from_euler
from sim_device.evaluation.targets import TARGETS, check_targets

H = 0.375  # half-side of the Ch. 11 square [m]
CORNERS = np.array([[H, -H, -1.0], [H, H, -1.0], [-H, H, -1.0], [-H, -H, -1.0]])


def square_at(s: np.ndarray, period: float = 20.0) -> np.ndarray:
    """The square (NW, NE, SE, SW, NW) at trajectory times ``s`` (periodic), 0.15 m/s."""
    knots = np.vstack([CORNERS, CORNERS[:1]])
    phase = np.mod(s, period)
    times = np.linspace(0.0, period, 5)
    return np.column_stack([np.interp(phase, times, knots[:, k]) for k in range(3)])


def record(t: np.ndarray, ref: np.ndarray, pos: np.ndarray, *, yaw_true: np.ndarray | None = None,
           ref_yaw: np.ndarray | None = None) -> FlightRecord:
    """A flight that tracks for its whole length (2 s settle)."""
    n = len(t)
    q = (np.tile([1.0, 0.0, 0.0, 0.0], (n, 1)) if yaw_true is None
         else np.array([quat_from_euler(0.0, 0.0, y) for y in yaw_true]))
    states = np.full(n, int(State.TRACK))
    states[-1] = int(State.DONE)
    return FlightRecord(t=t, state=states, ref_pos=ref, est_pos=pos, est_q=q, true_pos=pos,
                        true_q=q, vicon_t=t[:0], vicon_pos=np.zeros((0, 3)),
                        compute_s=np.full(n, 1e-4), jitter_s=None, latency_s=None,
                        transitions=(), timing_source="synthetic", truth_source=TRUTH_LAB,
                        ref_yaw=ref_yaw)


@pytest.mark.slow
def test_late_on_the_path_is_off_in_time_but_not_off_the_path() -> None:
    t = np.arange(0.0, 60.0, 0.01)
    delay = 0.2
    m = flight_metrics(record(t, square_at(t), square_at(t - delay)), period_s=20.0,
                       corners=CORNERS)
    assert m["off_path_rms_m"] == pytest.approx(0.0, abs=1e-12)
    assert m["corner_m"] == pytest.approx(0.0, abs=1e-12)  # the path passes every corner
    # 0.15 m/s x 0.2 s = 3 cm behind on the edges; across a corner the chord is shorter,
    # so the RMS lies between 3 cm / sqrt(2) and 3 cm
    assert 0.03 / math.sqrt(2) < m["rms_m"] <= 0.03 + 1e-9
    assert m["lag_s"] == pytest.approx(delay, abs=0.01)


def chamfered(c: float) -> np.ndarray:
    """The square with every corner cut by a chamfer ``c`` along each edge, densely sampled."""
    knots = []
    for k in range(4):
        prev, corner, nxt = CORNERS[k - 1], CORNERS[k], CORNERS[(k + 1) % 4]
        knots += [corner + c * (prev - corner) / (2 * H), corner + c * (nxt - corner) / (2 * H)]
    knots.append(knots[0])
    s = np.linspace(0.0, 1.0, 4001)
    at = np.linspace(0.0, 1.0, len(knots))
    return np.column_stack([np.interp(s, at, np.array(knots)[:, j]) for j in range(3)])


@pytest.mark.parametrize("cut", [0.01, 0.05])
def test_a_cut_corner_is_passed_at_the_chamfer_distance(cut: float) -> None:
    flown = np.vstack([chamfered(cut)] * 2)
    t = np.linspace(0.0, 40.0, len(flown))
    m = flight_metrics(record(t, square_at(t), flown), period_s=20.0, corners=CORNERS)
    assert m["corner_m"] == pytest.approx(cut / math.sqrt(2), rel=1e-9)
    assert m["off_path_rms_m"] < cut / math.sqrt(2)  # only near the corners is it off


def test_no_corners_no_corner_figure_and_a_hover_path_is_the_hover_point() -> None:
    t = np.arange(0.0, 10.0, 0.01)
    ref = np.tile([0.0, 0.0, -1.0], (len(t), 1))
    pos = ref + np.array([0.003, -0.004, 0.0])
    m = flight_metrics(record(t, ref, pos))
    assert math.isnan(m["corner_m"]) and math.isnan(m["heading_rms_deg"])  # no ref_yaw
    assert m["off_path_rms_m"] == pytest.approx(0.005) and m["rms_m"] == pytest.approx(0.005)


def test_heading_error_is_wrapped() -> None:
    # the reference turns through north-south (+-180 deg); the vehicle is 3 deg short of it
    t = np.arange(0.0, 10.0, 0.01)
    ref_yaw = np.radians(170.0 + 2.0 * t)  # 170 .. 190 deg: crosses the wrap at t = 5 s
    true = ref_yaw - np.radians(3.0)
    ref = np.tile([0.0, 0.0, -1.0], (len(t), 1))
    m = flight_metrics(record(t, ref, ref.copy(), yaw_true=true, ref_yaw=ref_yaw))
    assert m["heading_rms_deg"] == pytest.approx(3.0, abs=1e-6)
    assert m["heading_end_deg"] == pytest.approx(3.0, abs=1e-6)
    turned = flight_metrics(record(t, ref, ref.copy(), yaw_true=ref_yaw + 2 * math.pi,
                                   ref_yaw=ref_yaw))  # a whole turn ahead is no error
    assert turned["heading_rms_deg"] == pytest.approx(0.0, abs=1e-6)


PER_SEED = {
    1: {"completed": True, "reached_track": True, "final_state": "DONE", "rms_m": 0.004,
        "lag_s": 0.05, "track_s": 40.0, "corner_m": 0.010, "settling_s": math.nan},
    2: {"completed": True, "reached_track": True, "final_state": "DONE", "rms_m": 0.006,
        "lag_s": -0.08, "track_s": 40.0, "corner_m": 0.004, "settling_s": math.nan},
    3: {"completed": False, "reached_track": True, "final_state": "DONE", "rms_m": 0.005,
        "lag_s": 0.01, "track_s": 12.5, "corner_m": math.nan, "settling_s": math.nan},
}


def test_worst_case_takes_the_worst_of_every_figure_and_names_its_seed() -> None:
    w = worst_case(PER_SEED)
    assert w.metrics["rms_m"] == 0.006 and w.seed_of["rms_m"] == 2
    assert w.metrics["corner_m"] == 0.010 and w.seed_of["corner_m"] == 1  # NaN ignored
    assert w.metrics["lag_s"] == -0.08 and w.seed_of["lag_s"] == 2  # largest magnitude
    assert w.metrics["track_s"] == 12.5 and w.seed_of["track_s"] == 3  # least flown
    assert math.isnan(w.metrics["settling_s"]) and "settling_s" not in w.seed_of
    tie = worst_case({1: PER_SEED[1], 2: {**PER_SEED[2], "track_s": 40.0}})
    assert tie.metrics["track_s"] == 40.0 and "track_s" not in tie.seed_of  # no seed gave it
    assert worst_case({7: PER_SEED[1]}).seed_of["track_s"] == 7  # one flight: its seed
    # a flight that did not complete fails the scenario, whatever its numbers
    assert w.failed == (3,) and not w.metrics["completed"] and w.metrics["reached_track"]
    ok = worst_case({1: PER_SEED[1], 2: PER_SEED[2]})
    assert ok.failed == () and ok.metrics["completed"] and ok.metrics["final_state"] == "DONE"
    with pytest.raises(ValueError):
        worst_case({})


def test_targets_need_every_flight_completed_and_the_figure_within_its_limit() -> None:
    good = {"completed": True, "off_path_rms_m": 0.009, "rms_m": 0.014, "corner_m": 0.019}
    results = check_targets({"square-shaped-lqr-ff": good, "not-a-target-scenario": good},
                            {"square-shaped-lqr-ff": {"rms_m": 4}})
    assert [r.target for r in results] == list(TARGETS["square-shaped-lqr-ff"])
    assert all(r.met for r in results)
    assert [r.seed for r in results] == [None, 4, None]
    over = check_targets({"square-shaped-lqr-ff": {**good, "corner_m": 0.021}})
    assert [r.met for r in over] == [True, True, False]
    assert "corner_m = 2.10 cm" in over[2].line()
    failed = check_targets({"hover-h90": {"completed": False, "rms_m": 0.001}})
    assert not failed[0].met and "did not complete" in failed[0].line()
    missing = check_targets({"yaw-turn": {"completed": True, "rms_m": 0.01}})
    assert [r.met for r in missing] == [True, False]  # no heading figure: not met
