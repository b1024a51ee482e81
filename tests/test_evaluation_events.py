"""How a flight answers one disturbance (sim_device/evaluation/events.py), on records whose
answers are known: errors written here as functions of time, their peak, return within
1 cm, RMS and drift computed by hand (closed forms of the shapes chosen)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from groundstation.evaluation.record import TRUTH_LAB, FlightRecord
from groundstation.flight.supervisor import State
from sim_device.evaluation.events import event_metrics

DT = 0.01


def record(t: np.ndarray, error: np.ndarray, *, est_offset: np.ndarray | None = None,
           states: np.ndarray | None = None) -> FlightRecord:
    """Hover at (0, 0, -1) with the truth ``error`` (N, 3) off it; the estimate is the
    truth plus ``est_offset``."""
    n = len(t)
    ref = np.tile([0.0, 0.0, -1.0], (n, 1))
    pos = ref + error
    est = pos + (np.zeros((n, 3)) if est_offset is None else est_offset)
    q = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
    if states is None:
        states = np.full(n, int(State.TRACK))
        states[-1] = int(State.DONE)
    return FlightRecord(t=t, state=states, ref_pos=ref, est_pos=est, est_q=q, true_pos=pos,
                        true_q=q, vicon_t=t[:0], vicon_pos=np.zeros((0, 3)),
                        compute_s=np.full(n, 1e-4), jitter_s=None, latency_s=None,
                        transitions=(), timing_source="synthetic", truth_source=TRUTH_LAB)


def test_a_decaying_sag_peaks_returns_and_has_its_rms() -> None:
    """z error 3 cm x exp(-(t - 20) / 0.5) from t = 20: peak 3 cm at once, within 1 cm from
    20 + 0.5 ln 3, RMS over 10 s of a * sqrt(tau / (2 T)) (the exponential's, the tail
    being nothing)."""
    t = np.arange(0.0, 40.0, DT)
    z = np.where(t >= 20.0, 0.03 * np.exp(-(t - 20.0) / 0.5), 0.0)
    m = event_metrics(record(t, np.column_stack([0 * t, 0 * t, z])), event_s=20.0,
                      window_s=10.0)
    assert m["event_peak_m"] == pytest.approx(0.03, rel=1e-9)
    assert m["event_recover_s"] == pytest.approx(0.5 * math.log(3.0), abs=DT)
    assert m["event_rms_m"] == pytest.approx(0.03 * math.sqrt(0.5 / (2 * 10.0)), rel=0.02)
    assert math.isnan(m["lap_rms_m"]) and math.isnan(m["outage_est_max_m"])


def test_a_crossing_on_the_way_back_is_not_a_return() -> None:
    """An error that dips below 1 cm for 0.2 s, climbs to 1.5 cm, then stays below:
    it returned the second time."""
    t = np.arange(0.0, 30.0, DT)
    e = np.zeros_like(t)
    e[(t >= 20.0) & (t < 21.0)] = 0.02
    e[(t >= 21.0) & (t < 21.2)] = 0.005
    e[(t >= 21.2) & (t < 22.0)] = 0.015
    e[t >= 22.0] = 0.004
    m = event_metrics(record(t, np.column_stack([e, 0 * t, 0 * t])), event_s=20.0)
    assert m["event_recover_s"] == pytest.approx(2.0, abs=DT)


def test_an_error_that_never_returns_has_no_return_time() -> None:
    t = np.arange(0.0, 30.0, DT)
    e = np.where(t >= 20.0, 0.02, 0.0)
    m = event_metrics(record(t, np.column_stack([e, 0 * t, 0 * t])), event_s=20.0)
    assert math.isnan(m["event_recover_s"]) and m["event_peak_m"] == pytest.approx(0.02)


def test_the_lap_containing_the_event() -> None:
    """Laps of 8 s on the tracking clock (tracking from t = 4): the event at t = 21 falls in
    the third lap (tracking time 16-24 s, t = 20-28), where the error is 2 cm; elsewhere 0."""
    t = np.arange(0.0, 40.0, DT)
    states = np.full(len(t), int(State.TRACK))
    states[t < 4.0] = int(State.TAKEOFF)
    states[-1] = int(State.DONE)
    e = np.where((t >= 20.0) & (t < 28.0), 0.02, 0.0)
    m = event_metrics(record(t, np.column_stack([0 * t, e, 0 * t]), states=states),
                      event_s=21.0, period_s=8.0)
    assert m["lap_rms_m"] == pytest.approx(0.02, rel=1e-6)


def test_the_estimates_drift_through_an_outage() -> None:
    """The estimate leaves the truth as 0.5 a t^2 from the outage's start (a = 0.02 m/s^2):
    after 1 s and the 0.2 s allowed for Vicon to be fused again, 0.5 a 1.2^2."""
    t = np.arange(0.0, 30.0, DT)
    s = np.clip(t - 20.0, 0.0, None)
    drift = np.where(t <= 21.5, 0.5 * 0.02 * s**2, 0.0)
    m = event_metrics(record(t, np.zeros((len(t), 3)),
                             est_offset=np.column_stack([drift, 0 * t, 0 * t])),
                      event_s=20.0, outage_s=1.0)
    assert m["outage_est_max_m"] == pytest.approx(0.5 * 0.02 * 1.2**2, abs=2 * 0.02 * DT)
    assert m["outage_peak_m"] == 0.0


def test_lab_time_of_a_real_time_record() -> None:
    """A record on another clock (monotonic): t0 moves the event onto it."""
    t = np.arange(1000.0, 1030.0, DT)
    z = np.where(t >= 1020.0, 0.02, 0.0)
    m = event_metrics(record(t, np.column_stack([0 * t, 0 * t, z])), event_s=20.0, t0=-1000.0)
    assert m["event_peak_m"] == pytest.approx(0.02)
    assert m["event_rms_m"] == pytest.approx(0.02, rel=1e-3)


def test_take_off_and_landing_peaks_off_the_floor() -> None:
    t = np.arange(0.0, 10.0, DT)
    states = np.full(len(t), int(State.TRACK))
    states[t < 3.0] = int(State.TAKEOFF)
    states[t >= 7.0] = int(State.LAND)
    n = len(t)
    ref = np.tile([0.0, 0.0, -1.0], (n, 1))
    pos = ref.copy()
    pos[t < 0.5, 2] = 0.0  # on the floor: not judged
    pos[(t >= 1.0) & (t < 1.1), 2] = -1.03  # 3 cm above the reference during take-off
    pos[(t >= 8.0) & (t < 8.1), 2] = -0.98  # 2 cm below during the landing
    q = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
    r = FlightRecord(t=t, state=states, ref_pos=ref, est_pos=pos, est_q=q, true_pos=pos,
                     true_q=q, vicon_t=t[:0], vicon_pos=np.zeros((0, 3)),
                     compute_s=np.full(n, 1e-4), jitter_s=None, latency_s=None,
                     transitions=(), timing_source="synthetic", truth_source=TRUTH_LAB)
    m = event_metrics(r, event_s=None)
    assert m["takeoff_peak_m"] == pytest.approx(0.03) and m["land_peak_m"] == pytest.approx(0.02)
