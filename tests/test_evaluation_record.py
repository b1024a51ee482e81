"""Flight records from logs and truth files, their metrics, and ``gs report``'s function.

Synthetic flight logs are written with the real FlightRecorder; synthetic truth
files with np.savez in the format of sim_device.truth. Expected values are the
synthetic inputs themselves (a truth ramp interpolates to the ramp; a constant
offset is its own RMS), and the real-time lab's start stamp is checked against
time.monotonic() taken around the run.
"""

from __future__ import annotations

import json
import math
import socket
import time
from pathlib import Path

import numpy as np
import pytest

from groundstation.app.recorder import FlightRecorder
from groundstation.asctec.messages import CommandMsg
from groundstation.config import apply_overrides, load_config
from groundstation.errors import RecorderError
from groundstation.evaluation.record import (
    TRUTH_LAB,
    TRUTH_NONE,
    FlightRecord,
    record_from_log,
)
from groundstation.evaluation.report import report_flight, step_from_reference
from groundstation.evaluation.scoring import flight_metrics
from groundstation.flight.supervisor import State
from groundstation.model.quaternion import quat_from_euler
from groundstation.types import ImuSample, Pose, Reference, StateEstimate, Sticks
from sim_device.realtime import run_sim_device

T0 = 1000.0  # monotonic time of the first logged tick [s]
HOVER = np.array([0.0, 0.0, -1.0])
NORTH_1CM = np.array([0.01, 0.0, 0.0])
EAST_2CM = np.array([0.0, 0.02, 0.0])
ROLL = quat_from_euler(math.radians(10.0), 0.0, 0.0)


def state_at(k: int) -> State:
    """1 s PREFLIGHT, 1 s TAKEOFF, 6 s TRACK, 1 s LAND, then DONE (100 ticks per second)."""
    for limit, state in ((100, State.PREFLIGHT), (200, State.TAKEOFF), (800, State.TRACK),
                         (900, State.LAND)):
        if k < limit:
            return state
    return State.DONE


def write_log(directory: Path, n: int = 1000) -> Path:
    """A hover log: reference HOVER, estimate 1 cm north of it, a Vicon pose every 10 ticks."""
    with FlightRecorder.create(directory, "sim: {}\n",
                               {"supervisor_states": [s.name for s in State]}) as rec:
        for k in range(n):
            t = T0 + 0.01 * k
            est = StateEstimate(t=t, position=HOVER + NORTH_1CM, quaternion=ROLL,
                                velocity_body=np.zeros(3), omega=np.zeros(3),
                                gyro_bias=np.zeros(3), acc_bias=np.zeros(3),
                                covariance_diag=np.full(16, 1e-4))
            pose = Pose(t - 0.005, HOVER + EAST_2CM, ROLL) if k % 10 == 0 else None
            rec.append(t=t, imu=ImuSample(t, np.zeros(3), np.array([0.0, 0.0, -9.82]), k),
                       gyro_counts=(2048, 2048, 2048), acc_counts=(2048, 2048, 1163),
                       pose=pose, estimate=est, reference=Reference(t, HOVER, np.zeros(3)),
                       command=CommandMsg(thrust=2000, ctrl=15),
                       controller=Sticks(0, 0, 0, 2000), sent=k % 2 == 0,
                       state=int(state_at(k)), compute_time=1e-4 + 1e-6 * (k % 50),
                       jitter=1e-4, latency=2e-4)
        return rec.directory


def write_truth(path: Path, start_monotonic: float | None, *, ramp: bool = False) -> Path:
    """Truth on a 2 ms grid from lab time 0 to 12 s: 2 cm east of HOVER (or a ramp in x)."""
    t = np.arange(0.0, 12.0, 0.002)
    pos = np.tile(HOVER + EAST_2CM, (len(t), 1))
    if ramp:
        pos[:, 0] = 0.1 * t
    data = {"t": t, "position": pos, "quaternion": np.tile(ROLL, (len(t), 1))}
    if start_monotonic is not None:
        data["start_monotonic"] = np.array(start_monotonic)
    np.savez(path, **data)
    return path


def test_truth_is_aligned_on_the_monotonic_clock(tmp_path: Path) -> None:
    log = write_log(tmp_path / "logs")
    truth = write_truth(tmp_path / "truth.npz", start_monotonic=T0 - 1.0, ramp=True)
    r = record_from_log(log, truth)
    assert r.has_truth and r.truth_source == TRUTH_LAB
    assert r.true_pos is not None
    # tick at monotonic t is lab time t - (T0 - 1): the ramp 0.1 * lab time, exactly
    assert r.true_pos[:, 0] == pytest.approx(0.1 * (r.t - (T0 - 1.0)), abs=1e-12)
    assert len(r.vicon_t) == 100 and r.vicon_pos[0] == pytest.approx(HOVER + EAST_2CM)
    assert [tr.new for tr in r.transitions] == [State.TAKEOFF, State.TRACK, State.LAND,
                                                State.DONE]
    assert r.transitions[1].t == pytest.approx(T0 + 2.0)


def test_truth_without_start_stamp_or_from_another_run_is_refused(tmp_path: Path) -> None:
    log = write_log(tmp_path / "logs")
    with pytest.raises(RecorderError, match="start_monotonic"):
        record_from_log(log, write_truth(tmp_path / "old.npz", None))
    with pytest.raises(RecorderError, match="not from the same run"):
        record_from_log(log, write_truth(tmp_path / "other.npz", T0 + 100.0))
    with pytest.raises(RecorderError, match="not a readable truth file"):
        record_from_log(log, tmp_path / "missing.npz")


def test_metrics_of_a_logged_hover_with_and_without_truth(tmp_path: Path) -> None:
    log = write_log(tmp_path / "logs")
    m = flight_metrics(record_from_log(log, write_truth(tmp_path / "t.npz", T0 - 1.0)))
    # truth 2 cm east of the reference; estimate 1 cm north: |(0.01, -0.02, 0)|
    assert m["rms_m"] == pytest.approx(0.02) and m["max_m"] == pytest.approx(0.02)
    assert m["est_rms_m"] == pytest.approx(math.hypot(0.01, 0.02))
    assert m["max_tilt_deg"] == pytest.approx(10.0)
    assert m["track_s"] == pytest.approx(5.99) and m["completed"] and math.isnan(m["lag_s"])
    assert m["compute_p50_us"] == pytest.approx(124.5, abs=0.5) and m["latency_p99_ms"] == 0.2
    no_truth = flight_metrics(record_from_log(log))
    assert no_truth["truth"] == TRUTH_NONE and math.isnan(no_truth["est_rms_m"])
    assert no_truth["rms_m"] == pytest.approx(0.01)  # judged from the estimate


def synthetic(t: np.ndarray, states: np.ndarray, ref: np.ndarray, pos: np.ndarray
              ) -> FlightRecord:
    n = len(t)
    q = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
    return FlightRecord(t=t, state=states, ref_pos=ref, est_pos=pos, est_q=q, true_pos=pos,
                        true_q=q, vicon_t=t[:0], vicon_pos=np.zeros((0, 3)),
                        compute_s=np.full(n, 1e-4), jitter_s=None, latency_s=None,
                        transitions=(), timing_source="synthetic", truth_source=TRUTH_LAB)


def test_a_hold_is_not_counted_as_lag() -> None:
    # 30 s of a circle at 0.3 s lag, interrupted by a 1 s HOLD during which both stand still.
    t = np.arange(0.0, 31.0, 0.01)
    states = np.full(len(t), int(State.TRACK))
    states[(t >= 10.0) & (t < 11.0)] = int(State.HOLD)
    clock = np.where(t < 10.0, t, np.where(t < 11.0, 10.0, t - 1.0))
    w = 2 * math.pi / 20.0
    def circle(s: np.ndarray) -> np.ndarray:
        return np.column_stack([0.4 * np.cos(w * s), 0.4 * np.sin(w * s), -np.ones_like(s)])
    m = flight_metrics(synthetic(t, states, circle(clock), circle(clock - 0.3)))
    assert m["lag_s"] == pytest.approx(0.3, abs=2e-3)
    assert m["hold_s"] == pytest.approx(1.0, abs=0.011)
    # |circle(s) - circle(s - d)| = 2 r sin(w d / 2) on the whole tracking window
    assert m["rms_m"] == pytest.approx(0.8 * math.sin(w * 0.3 / 2), rel=1e-6)


def test_the_step_is_read_back_from_the_reference() -> None:
    t = np.arange(0.0, 10.0, 0.01)
    states = np.where(t < 2.0, int(State.TAKEOFF), int(State.TRACK))
    ref = np.tile(HOVER, (len(t), 1))
    ref[t >= 5.0, 2] = -1.5  # 3 s after tracking started: 0.5 m up
    record = synthetic(t, states, ref, ref.copy())
    axis, t_step, before, after = step_from_reference(record)  # type: ignore[misc]
    assert (axis, before, after) == (2, -1.0, -1.5) and t_step == pytest.approx(3.0)
    hover = synthetic(t, states, np.tile(HOVER, (len(t), 1)), ref)
    assert step_from_reference(hover) is None


@pytest.mark.slow
def test_report_flight_writes_markdown_json_and_a_figure(tmp_path: Path) -> None:
    log = write_log(tmp_path / "logs")
    rep = report_flight(log, write_truth(tmp_path / "t.npz", T0 - 1.0), tmp_path / "out")
    assert rep.figure is not None and rep.figure.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    data = json.loads(rep.metrics_json.read_text())
    assert data["metrics"]["rms_m"] == pytest.approx(0.02)
    assert math.isnan(rep.metrics["lag_s"]) and data["metrics"]["lag_s"] is None
    text = rep.report_md.read_text()
    assert TRUTH_LAB in text and "| 2.00 |" in text  # RMS 2 cm in the table
    bare = report_flight(log, None, tmp_path / "bare", figures=False)
    assert bare.figure is None and TRUTH_NONE in bare.report_md.read_text()


def test_real_time_lab_stamps_its_monotonic_start_in_the_truth_file(repo: Path,
                                                                      tmp_path: Path) -> None:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
        cfg = apply_overrides(load_config(repo / "config" / "sim.yaml"), {"vicon.port": port})
        before = time.monotonic()
        run_sim_device(cfg, truth_file=tmp_path / "truth.npz", duration=0.3, announce=None)
        after = time.monotonic()
    with np.load(tmp_path / "truth.npz") as truth:
        start, t_last = float(truth["start_monotonic"]), float(truth["t"][-1])
        assert "columns" in truth.files and truth["position"].shape[1] == 3  # still the format
    # simulated time 0 is when the clock started, inside the run; the run lasted 0.3 s of it
    assert before <= start and start + 0.3 <= after
    assert t_last == pytest.approx(0.3, abs=0.01)
