"""The CI regression test: the thesis's Ch. 11 flights of `gs eval --fast`, every metric held
to the figure reached.

The Ch. 11 part of the suite (scenarios.THESIS; the shaped flights are judged by their
targets under --perturb, tests/test_evaluation_targets.py) flies in-process against the
virtual lab with config/sim.yaml (seed 1, deterministic), each flight once, when the
first test that reads it asks for it (``FlownSuite``; the report test runs `gs eval` on
the same flights). Each metric
must stay within a stated margin of the figure this code reached (REACHED, printed
by `.venv/bin/python benchmarks/bench_eval.py`):

* RMS and maximum position error: <= 1.3 x reached + 1 mm (max: + 2 mm)
* estimator RMS error: <= 1.3 x reached + 0.5 mm
* lag: <= reached + 0.1 s (and no more than 0.1 s ahead for the constant-velocity LQR)
* overshoot: <= reached + 3 percentage points; 2 % settling time <= 1.3 x reached

and the thesis's qualitative results must hold (Ch. 10.3, 11.1, 11.3): see the tests.
Timing figures are reported, never asserted (wall clock).
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from eval_flights import nominal, sharing_flights

from groundstation.config import load_config
from groundstation.evaluation.metrics import step_figures, track_clock
from groundstation.flight.supervisor import State
from sim_device.evaluation import EvalReport, run_eval
from sim_device.evaluation.runner import simulate_model
from sim_device.evaluation.scenarios import STEP_TIME_S, THESIS, select
from sim_device.evaluation.suite import ScenarioOutcome

# one worker flies the module's flights, once; no test waits for more than the flights it
# reads (the longest, a 120 s square, is about 15 s)
pytestmark = [pytest.mark.slow, pytest.mark.xdist_group("thesis-flights")]

REPO = Path(__file__).resolve().parents[1]

# Figures reached by this code (config/sim.yaml, seed 1); SI units, overshoot in %.
REACHED: dict[str, dict[str, float]] = {
    "hover-1hz": {"rms_m": 0.03156, "max_m": 0.06632, "est_rms_m": 0.01102},
    "hover-10hz": {"rms_m": 0.005841, "max_m": 0.01055, "est_rms_m": 0.0008978},
    "hover-100hz": {"rms_m": 0.003015, "max_m": 0.00563, "est_rms_m": 0.0003655},
    "step-x": {"rms_m": 0.139, "max_m": 0.4934, "est_rms_m": 0.0008822, "overshoot_pct": 6.965,
               "settling_s": 3.78},
    "step-y": {"rms_m": 0.1419, "max_m": 0.5044, "est_rms_m": 0.0008865,
               "overshoot_pct": 9.526, "settling_s": 3.0},
    "step-z": {"rms_m": 0.1143, "max_m": 0.5018, "est_rms_m": 0.0009073,
               "overshoot_pct": 4.072, "settling_s": 2.6},
    "square-pid": {"rms_m": 0.1627, "max_m": 0.1861, "lag_s": 1.148, "est_rms_m": 0.00088},
    "square-lqr-cp": {"rms_m": 0.1365, "max_m": 0.1596, "lag_s": 0.9468, "est_rms_m": 0.0008795},
    "square-lqr-cv": {"rms_m": 0.03714, "max_m": 0.09896, "lag_s": 0.08708,
                      "est_rms_m": 0.0008854},
    "yz-rectangle-pid": {"rms_m": 0.1227, "max_m": 0.1572, "lag_s": 1.023,
                         "est_rms_m": 0.0009189},
    "yz-rectangle-lqr-cp": {"rms_m": 0.1025, "max_m": 0.1294, "lag_s": 0.84,
                            "est_rms_m": 0.0009198},
    "yz-rectangle-lqr-cv": {"rms_m": 0.02493, "max_m": 0.06459, "lag_s": 0.06569,
                            "est_rms_m": 0.0009229},
    "low-hover": {"rms_m": 0.005193, "max_m": 0.008618, "est_rms_m": 0.0008892},
    "square-vicon-outage": {"rms_m": 0.03658, "max_m": 0.09667, "lag_s": 0.09907,
                            "est_rms_m": 0.0009216},
    "hover-thrust-error": {"rms_m": 0.006425, "max_m": 0.01047, "est_rms_m": 0.0009014},
    "square-thrust-error": {"rms_m": 0.03605, "max_m": 0.09749, "lag_s": 0.09378,
                            "est_rms_m": 0.0009058},
    "hinf-thesis-model": {},  # does not fly: judged by the qualitative test below
    "hinf-rate-loop-model": {"rms_m": 0.005519, "max_m": 0.01378, "est_rms_m": 0.0009091},
}


LIMITS = {  # metric -> limit as a function of the reached figure
    "rms_m": lambda r: 1.3 * r + 0.001,
    "max_m": lambda r: 1.3 * r + 0.002,
    "est_rms_m": lambda r: 1.3 * r + 0.0005,
    "lag_s": lambda r: r + 0.1,
    "overshoot_pct": lambda r: r + 3.0,
    "settling_s": lambda r: 1.3 * r,
}


class _OnDemand(Mapping[str, Any]):
    """Scenario name -> ``get(name)``, computed on first use and kept."""

    def __init__(self, get: Callable[[str], Any]) -> None:
        self._get = get
        self._kept: dict[str, Any] = {}

    def __getitem__(self, name: str) -> Any:
        if name not in self._kept:
            self._kept[name] = self._get(name)
        return self._kept[name]

    def __iter__(self) -> Iterator[str]:
        return iter(THESIS)

    def __len__(self) -> int:
        return len(THESIS)


class FlownSuite:
    """The Ch. 11 flights of `gs eval --fast`, each flown (and scored as `gs eval` scores
    it) when a test first asks for it: ``outcomes[name]``, ``metrics[name]``. A test pays
    only for the flights it reads, and each is flown once in this module's worker."""

    def __init__(self, workdir: Path) -> None:
        self.outcomes: Mapping[str, ScenarioOutcome] = _OnDemand(
            lambda name: nominal(name, workdir))
        self.metrics: Mapping[str, dict[str, Any]] = _OnDemand(
            lambda name: self.outcomes[name].metrics)


@pytest.fixture(scope="module")
def suite(tmp_path_factory: pytest.TempPathFactory) -> FlownSuite:
    return FlownSuite(tmp_path_factory.mktemp("eval-flights"))


@pytest.fixture(scope="module")
def report(tmp_path_factory: pytest.TempPathFactory) -> EvalReport:
    """`gs eval --fast` over the Ch. 11 flights, report and figures written (the flights
    are the ones the other tests flew)."""
    with sharing_flights():
        return run_eval(load_config(REPO / "config" / "sim.yaml"), fast=True,
                        out_dir=tmp_path_factory.mktemp("eval"), scenarios=THESIS)


def test_reached_table_covers_the_thesis_flights() -> None:
    assert list(REACHED) == list(THESIS)


@pytest.mark.parametrize("name", list(REACHED))
def test_metrics_stay_within_the_margin_of_the_figures_reached(suite: FlownSuite,
                                                               name: str) -> None:
    m = suite.metrics[name]
    for key, reached in REACHED[name].items():
        assert m[key] <= LIMITS[key](reached), (key, m[key], reached)
    if name != "hinf-thesis-model":
        assert m["completed"] and m["final_state"] == "DONE", m


def test_constant_velocity_lqr_has_the_least_lag_and_error(suite: FlownSuite) -> None:
    # Thesis Ch. 11.3/11.5: "the LQR with a constant velocity model clearly stands out being
    # able to match the position time correlated with the reference"; PID and the
    # constant-position LQR lag behind and cut the corners (Fig. 11.5-11.7).
    for shape in ("square", "yz-rectangle"):
        m = {c: suite.metrics[f"{shape}-{c}"] for c in ("pid", "lqr-cp", "lqr-cv")}
        assert abs(m["lqr-cv"]["lag_s"]) < 0.2
        assert m["lqr-cp"]["lag_s"] > 0.5 and m["pid"]["lag_s"] > 0.5
        for other in ("pid", "lqr-cp"):
            assert m["lqr-cv"]["lag_s"] < 0.25 * m[other]["lag_s"]
            assert m["lqr-cv"]["rms_m"] < 0.5 * m[other]["rms_m"]
    lag = {c: suite.metrics[f"square-{c}"]["lag_s"] for c in ("pid", "lqr-cp")}
    # the constant-position LQR trails by (along-track error) / speed: 0.12 m at 0.15 m/s
    assert lag["lqr-cp"] == pytest.approx(suite.metrics["square-lqr-cp"]["rms_m"] / 0.15,
                                          rel=0.15)


def test_1hz_vicon_hover_is_worse_and_10_and_100hz_are_similar(suite: FlownSuite) -> None:
    # Thesis Ch. 11.1, Fig. 11.1-11.3: 1 Hz lets the estimate drift; 10 and 100 Hz both hold
    # the hover closely, so 10 Hz is enough.
    rms = {hz: suite.metrics[f"hover-{hz}hz"]["rms_m"] for hz in (1, 10, 100)}
    est = {hz: suite.metrics[f"hover-{hz}hz"]["est_rms_m"] for hz in (1, 10, 100)}
    assert rms[1] > 3 * rms[10] and rms[1] > 3 * rms[100]
    assert est[1] > 5 * est[10]
    assert rms[10] < 0.01 and rms[100] < 0.01 and abs(rms[10] - rms[100]) < 0.005


def test_hinf_designed_without_the_rate_loop_does_not_hover(suite: FlownSuite) -> None:
    # Thesis Ch. 10.3: the H-infinity gain designed on the model without the on-board
    # dynamics "was not capable of stabilizing the quadrotor in hover"; designed with the
    # rate-loop lag (tests/test_control_closed_loop.py flies it on the model) it hovers.
    bad = suite.outcomes["hinf-thesis-model"]
    assert not bad.metrics["reached_track"] and not bad.metrics["completed"]
    land = next(tr for tr in bad.record.transitions if tr.new is State.LAND)
    assert land.old is State.TAKEOFF and "tilt" in land.reason
    assert bad.metrics["max_tilt_deg"] > 35.0  # the supervisor's limit
    good = suite.metrics["hinf-rate-loop-model"]
    assert good["completed"] and good["rms_m"] < 0.015 and good["max_tilt_deg"] < 5.0


def test_vicon_outage_holds_on_the_imu_and_resumes(suite: FlownSuite) -> None:
    o = suite.outcomes["square-vicon-outage"]
    states = [tr.new for tr in o.record.transitions]
    assert states == [State.TAKEOFF, State.TRACK, State.HOLD, State.TRACK, State.LAND,
                      State.DISARM, State.DONE]
    # HOLD from 0.5 s after the last pose until the third pose after the 1 s outage: after a
    # gap the pose filter believes a stream only once vicon.reanchor_poses (3) agree, 0.2 s
    # at this scenario's 10 Hz (never one pose); reached 0.8 s
    assert 0.3 < o.metrics["hold_s"] < 0.9 and o.metrics["hold_max_m"] < 0.1
    assert o.metrics["rms_m"] < 1.1 * suite.metrics["square-lqr-cv"]["rms_m"]


def test_thrust_error_leaves_no_height_offset(suite: FlownSuite) -> None:
    # 10 % less lift: without correction the LQR would sag by 0.1 m g / (0.9 K_z), several cm
    # (tests/test_control_closed_loop.py); the disturbance observer removes it.
    r = suite.outcomes["hover-thrust-error"].record
    track = r.during(State.TRACK)
    window = track & (track_clock(r.t, track) >= 2.0)
    assert r.true_pos is not None
    assert abs(float(np.mean(r.true_pos[window, 2] - r.ref_pos[window, 2]))) < 0.003
    nominal, faulty = suite.metrics["square-lqr-cv"], suite.metrics["square-thrust-error"]
    assert faulty["rms_m"] < 1.1 * nominal["rms_m"]


def test_low_hover_stays_off_the_floor(suite: FlownSuite) -> None:
    r = suite.outcomes["low-hover"].record
    track = r.during(State.TRACK)
    window = track & (track_clock(r.t, track) >= 2.0)
    assert r.true_pos is not None
    height = -r.true_pos[window, 2]
    assert height.min() > 0.01 and height.max() < 0.03  # reached 1.8 .. 2.1 cm


@pytest.mark.parametrize("name", ["step-x", "step-y", "step-z"])
def test_steps_agree_with_the_model_simulation(suite: FlownSuite, name: str) -> None:
    # Thesis Fig. 11.4 compares the flown step with a simulation on the model (true
    # state, no estimator, no motor lag). The responses are compared point by point
    # over the 6 s after the step (step-x reached 4 mm RMS on the 0.5 m step) and by their
    # overshoot (within 2.6 points). The 2 % settling time is not compared: near the
    # band's edge a millimetre moves it by a second (step-x: 2.9 s model, 3.8 s flown).
    scenario = select([name])[0]
    sim = simulate_model(scenario, load_config(REPO / "config" / "sim.yaml"))
    axis = "xyz".index(name[-1])
    model = step_figures(sim.t, sim.position[:, axis], t_step=STEP_TIME_S,
                         initial=sim.reference[0, axis], final=sim.reference[-1, axis])
    flown = suite.metrics[name]
    assert abs(flown["overshoot_pct"] - model["overshoot_pct"]) < 4.0
    assert flown["overshoot_pct"] < 12.0 and flown["settling_s"] < 4.5
    r = suite.outcomes[name].record
    track = r.during(State.TRACK)
    clock = track_clock(r.t, track)[track]
    window = (clock >= STEP_TIME_S) & (clock <= STEP_TIME_S + 6.0)
    pos = r.position[track][window, axis]
    model_pos = np.interp(clock[window], sim.t, sim.position[:, axis])
    diff = float(np.sqrt(np.mean((pos - model_pos) ** 2)))
    assert diff < 0.015, diff


def test_truth_is_aligned_with_the_ticks_to_the_vicon_noise(suite: FlownSuite) -> None:
    # Vicon samples are the truth plus Table 6.1 noise at their measurement time. On the
    # square (0.15 m/s) a 9 ms misalignment of the truth would add 1.4 mm; reached: the
    # per-axis scatter equals the configured standard deviations to within 1 %.
    r = suite.outcomes["square-lqr-cv"].record
    assert r.true_pos is not None
    track = r.during(State.TRACK)
    w = (r.vicon_t > r.t[track][0]) & (r.vicon_t < r.t[track][-1])
    truth = np.column_stack([np.interp(r.vicon_t[w], r.t, r.true_pos[:, k]) for k in range(3)])
    scatter = np.sqrt(np.mean((r.vicon_pos[w] - truth) ** 2, axis=0))
    sigma = np.sqrt(load_config(REPO / "config" / "sim.yaml").vehicle.vicon_position_variance)
    assert w.sum() > 1000 and scatter == pytest.approx(sigma, rel=0.1)


def test_report_metrics_json_and_figures_are_written(report: EvalReport) -> None:
    text = report.report_md.read_text(encoding="utf-8")
    for name in THESIS:
        assert f"| `{name}` |" in text
    data: dict[str, Any] = json.loads(report.metrics_json.read_text(encoding="utf-8"))
    assert data["mode"] == "fast" and list(data["scenarios"]) == list(THESIS)
    assert data["perturbation"] is None and "seeds" not in data["scenarios"]["hover-10hz"]
    cv = data["scenarios"]["square-lqr-cv"]["metrics"]
    assert cv["rms_m"] == pytest.approx(report.metrics["square-lqr-cv"]["rms_m"])
    assert data["scenarios"]["hover-10hz"]["metrics"]["lag_s"] is None  # NaN -> null
    assert len(report.figures) == 11
    for png in report.figures:
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 20_000
        assert f"]({png.name})" in text
    assert not math.isnan(report.wall_s)
