"""One flight as aligned per-tick arrays, whichever way it was flown.

A :class:`FlightRecord` is what the metrics and figures read. It is built

* from an in-process flight (:func:`record_from_trace`): the flight core's own
  trace, with the virtual lab's truth log interpolated at every tick's time;
* from a flight log (:func:`record_from_log`), optionally with the virtual
  lab's truth file: the truth is interpolated at the log's tick times on the
  monotonic clock (``truth.t + truth.start_monotonic``, written by
  :mod:`sim_device.realtime`). Without truth (a real flight) the position used
  for the metrics is the estimate, and the record says so.

Rows are control ticks. Frames: NED [m]; quaternions scalar-first.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from groundstation.app.inprocess import FlightResult
from groundstation.app.recorder import read_flight
from groundstation.errors import RecorderError
from groundstation.flight.supervisor import State, Transition
from groundstation.types import FloatArray

TIMING_FAST = "back-to-back cost of FlightCore.tick (time.perf_counter, in-process)"
TIMING_REAL_TIME = "real-time daemon: compute, jitter and latency per tick (time.monotonic)"
TRUTH_LAB = "virtual-lab ground truth"
TRUTH_NONE = "estimate (no ground truth: real flight)"

IntArray = npt.NDArray[np.int64]


@dataclass(frozen=True)
class FlightRecord:
    """Aligned per-tick arrays of one flight (N ticks, M Vicon poses).

    t : (N,) tick time [s] (lab time in-process, ``time.monotonic()`` for a log)
    state : (N,) supervisor state (:class:`~groundstation.flight.supervisor.State` values)
    ref_pos, est_pos : (N, 3) reference and estimate, NED [m] (estimate NaN before init)
    est_q : (N, 4) estimated attitude
    true_pos, true_q : (N, 3), (N, 4) ground truth, or None (real flight)
    vicon_t, vicon_pos : (M,) measurement times [s] and (M, 3) positions of the poses
    compute_s : (N,) per-tick compute time [s]; jitter_s, latency_s : (N,) [s] or
        None (in-process: no schedule); NaN where not measured
    transitions : supervisor transitions (reasons empty when derived from a log)
    timing_source, truth_source : how the timing and the "true" position were obtained
    ref_yaw : (N,) reference heading [rad] (NaN where there is none), or None if unknown
    """

    t: FloatArray
    state: IntArray
    ref_pos: FloatArray
    est_pos: FloatArray
    est_q: FloatArray
    true_pos: FloatArray | None
    true_q: FloatArray | None
    vicon_t: FloatArray
    vicon_pos: FloatArray
    compute_s: FloatArray
    jitter_s: FloatArray | None
    latency_s: FloatArray | None
    transitions: tuple[Transition, ...]
    timing_source: str
    truth_source: str
    meta: dict[str, Any] = field(default_factory=dict)
    ref_yaw: FloatArray | None = None

    @property
    def has_truth(self) -> bool:
        """True when ``true_pos`` holds ground truth."""
        return self.true_pos is not None

    @property
    def position(self) -> FloatArray:
        """The position the metrics judge: truth if known, else the estimate (N, 3)."""
        return self.true_pos if self.true_pos is not None else self.est_pos

    @property
    def attitude(self) -> FloatArray:
        """The attitude the metrics judge: truth if known, else the estimate (N, 4)."""
        return self.true_q if self.true_q is not None else self.est_q

    @property
    def final_state(self) -> State:
        """The last supervisor state."""
        return State(int(self.state[-1])) if len(self.state) else State.PREFLIGHT

    def during(self, *states: State) -> npt.NDArray[np.bool_]:
        """Boolean mask of the ticks spent in any of ``states``."""
        return np.isin(self.state, [int(s) for s in states])

    def entered(self, state: State) -> float:
        """Time of the first tick in ``state`` [s] (NaN if never)."""
        idx = np.flatnonzero(self.state == int(state))
        return float(self.t[idx[0]]) if idx.size else math.nan


def record_from_trace(result: FlightResult, compute_s: FloatArray,
                      vicon: FloatArray, ref_yaw: FloatArray | None = None) -> FlightRecord:
    """A record of an in-process flight.

    result : the flight's :class:`~groundstation.app.inprocess.FlightResult`
    compute_s : (N,) per-tick cost of ``FlightCore.tick`` [s], one per trace row
    vicon : (M, 4) rows ``[t, x, y, z]`` of the poses handed to the core
    ref_yaw : (N,) reference heading per trace row [rad] (the trace does not keep it)
    """
    tr = result.trace
    v = np.asarray(vicon, dtype=float).reshape(-1, 4)
    # The trace's own true_pos is the plant's state after the whole DATA period was
    # simulated (about 9 ms after the tick's time); the lab's truth log interpolated at
    # the tick time is the truth the estimate is compared with, as for a logged flight.
    log = result.lab.truth_log.arrays()
    true_pos, true_q = align_truth(tr["t"], log["t"], log["position"], log["quaternion"])
    return FlightRecord(
        t=tr["t"], state=tr["state"].astype(np.int64), ref_pos=tr["ref_pos"],
        est_pos=tr["est_pos"], est_q=tr["est_q"], true_pos=true_pos,
        true_q=true_q, vicon_t=v[:, 0], vicon_pos=v[:, 1:4],
        compute_s=np.asarray(compute_s, dtype=float), jitter_s=None, latency_s=None,
        transitions=tuple(result.transitions), timing_source=TIMING_FAST,
        truth_source=TRUTH_LAB,
        ref_yaw=np.asarray(ref_yaw, dtype=float) if ref_yaw is not None else None,
    )


def _transitions_from_states(t: FloatArray, state: IntArray) -> tuple[Transition, ...]:
    change = np.flatnonzero(np.diff(state) != 0) + 1
    return tuple(Transition(float(t[i]), State(int(state[i - 1])), State(int(state[i])), "")
                 for i in change)


def load_truth(path: str | Path) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Read a virtual-lab truth file: monotonic times (N,) [s], positions (N, 3) NED [m],
    attitudes (N, 4). RecorderError if unreadable or without ``start_monotonic``."""
    try:
        loaded = np.load(Path(path), allow_pickle=False)
    except (OSError, ValueError) as exc:
        raise RecorderError(f"{path}: not a readable truth file: {exc!r}") from exc
    if not isinstance(loaded, np.lib.npyio.NpzFile):  # a .npy: one array, not a truth file
        raise RecorderError(f"{path}: not a truth file (a single array; the virtual lab "
                            "writes an .npz with t, position, quaternion, start_monotonic)")
    try:
        with loaded as data:
            arrays = {k: np.array(data[k], dtype=float) for k in ("t", "position", "quaternion")}
            start = float(data["start_monotonic"]) if "start_monotonic" in data.files else None
    except (OSError, ValueError, KeyError) as exc:
        raise RecorderError(f"{path}: not a readable truth file: {exc!r}") from exc
    if start is None:
        raise RecorderError(f"{path}: truth file has no start_monotonic (written by an older "
                            "sim_device); it cannot be aligned with a flight log")
    return arrays["t"] + start, arrays["position"], arrays["quaternion"]


def align_truth(t: FloatArray, truth_t: FloatArray, position: FloatArray,
                quaternion: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Truth position (N, 3) and attitude (N, 4) at the flight's tick times ``t`` (N,).

    truth_t (M,) : the truth's times on the same clock [s]; position (M, 3);
    quaternion (M, 4). Linear interpolation (the lab logs its truth every 10 ms;
    the interpolated quaternions are renormalised). RecorderError if the truth
    does not cover the ticks.
    """
    tt = np.asarray(truth_t, dtype=float)
    if len(tt) < 2 or t[0] < tt[0] - 0.05 or t[-1] > tt[-1] + 0.05:
        raise RecorderError(
            f"the truth covers {tt[0] if len(tt) else math.nan:.3f}.."
            f"{tt[-1] if len(tt) else math.nan:.3f} s, the flight "
            f"{t[0]:.3f}..{t[-1]:.3f} s (monotonic for a log): they are not from the same run")
    pos = np.column_stack([np.interp(t, tt, position[:, k]) for k in range(3)])
    q = np.column_stack([np.interp(t, tt, quaternion[:, k]) for k in range(4)])
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    return pos, q


def record_from_log(log: str | Path, truth_file: str | Path | None = None) -> FlightRecord:
    """A record of a logged flight (:mod:`groundstation.app.recorder`), with the virtual
    lab's truth aligned on the monotonic clock when ``truth_file`` is given.

    RecorderError if the log or the truth cannot be read or do not belong together.
    """
    rows, meta, _ = read_flight(log)
    if len(rows) == 0:
        raise RecorderError(f"{log}: the flight log has no rows")
    t = np.asarray(rows["t"], dtype=float)
    state = rows["state"].astype(np.int64)
    true_pos = true_q = None
    if truth_file is not None:
        true_pos, true_q = align_truth(t, *load_truth(truth_file))
    valid = rows["vicon_valid"].astype(bool)
    return FlightRecord(
        t=t, state=state, ref_pos=np.array(rows["ref_position"], dtype=float),
        est_pos=np.array(rows["est_position"], dtype=float),
        est_q=np.array(rows["est_quaternion"], dtype=float), true_pos=true_pos,
        true_q=true_q, vicon_t=np.array(rows["vicon_t"][valid], dtype=float),
        vicon_pos=np.array(rows["vicon_position"][valid], dtype=float),
        compute_s=np.array(rows["compute_time"], dtype=float),
        jitter_s=np.array(rows["jitter"], dtype=float),
        latency_s=np.array(rows["latency"], dtype=float),
        transitions=_transitions_from_states(t, state), timing_source=TIMING_REAL_TIME,
        truth_source=TRUTH_LAB if true_pos is not None else TRUTH_NONE,
        meta={"log": str(log), "version": meta.get("version"),
              "start_time": meta.get("start_time")},
        ref_yaw=np.array(rows["ref_yaw"], dtype=float),
    )
