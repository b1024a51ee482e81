"""The metrics of one flight: what the report tables and the regression test read.

:func:`flight_metrics` applies the pure functions of
:mod:`groundstation.evaluation.metrics` to a :class:`FlightRecord`:

* tracking (RMS, per-axis RMS, maximum, lag) over the supervisor's TRACK
  phase after the first ``settle_s`` of trajectory time, from the truth (or,
  for a real flight, from the estimate: ``truth`` says which); the lag (not
  for steps) is measured on the trajectory's own clock, so a HOLD does not
  count as delay;
* the estimator error, truth against estimate, over the same window;
* for a step: overshoot, 2 % settling time, rise time and steady-state error of
  the stepped axis, on the trajectory's clock;
* time in HOLD and the largest distance from the hold point while holding;
* the largest tilt while airborne;
* timing percentiles (see ``timing`` for how they were measured).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from groundstation.evaluation.metrics import (
    error_norms,
    lag_s,
    percentiles,
    step_figures,
    tilt_deg,
    track_clock,
    tracking_errors,
)
from groundstation.evaluation.record import FlightRecord
from groundstation.loop.supervisor import AIRBORNE, State

StepSpec = tuple[int, float, float, float]
"""(axis 0/1/2, step time on the trajectory clock [s], initial, final set point [m])."""


def _timing(record: FlightRecord) -> dict[str, float]:
    p50, p99, worst = percentiles(record.compute_s, 1e6)
    out = {"compute_p50_us": p50, "compute_p99_us": p99, "compute_max_us": worst}
    if record.jitter_s is not None:
        out["jitter_p99_ms"] = percentiles(np.abs(record.jitter_s), 1e3)[1]
    if record.latency_s is not None:
        lat = percentiles(record.latency_s, 1e3)
        out["latency_p50_ms"], out["latency_p99_ms"] = lat[0], lat[1]
    return out


def _hold(record: FlightRecord) -> dict[str, float]:
    hold = record.during(State.HOLD)
    dt = np.diff(record.t, prepend=record.t[0])
    if not hold.any():
        return {"hold_s": 0.0, "hold_max_m": math.nan}
    err = error_norms(record.position[hold], record.ref_pos[hold])
    return {"hold_s": float(np.sum(dt[hold])), "hold_max_m": float(np.max(err))}


def _step(record: FlightRecord, clock: np.ndarray, track: np.ndarray,
          step: StepSpec) -> dict[str, float]:
    axis, t_step, initial, final = step
    if clock[track].size == 0 or clock[track][-1] <= t_step:
        return dict.fromkeys(("overshoot_pct", "settling_s", "rise_s", "steady_state_m"),
                             math.nan)
    return step_figures(clock[track], record.position[track, axis], t_step=t_step,
                        initial=initial, final=final)


def flight_metrics(record: FlightRecord, *, settle_s: float = 2.0,
                   duration_s: float | None = None,
                   step: StepSpec | None = None) -> dict[str, Any]:
    """Metrics of one flight as a flat dict (JSON-ready; NaN where not applicable).

    settle_s : trajectory time at the start of tracking left out of the tracking
    metrics [s]; duration_s : the trajectory time the flight was meant to fly
    (``completed`` then also requires it was flown); step : see :data:`StepSpec`.
    Lengths [m], times [s], tilt [deg], compute [us], jitter and latency [ms].
    """
    track = record.during(State.TRACK)
    clock = track_clock(record.t, track)
    window = track & (clock >= settle_s)
    flown = float(clock[-1]) if len(clock) else 0.0
    reached = bool(track.any())
    done = record.final_state is State.DONE and reached
    out: dict[str, Any] = {
        "final_state": record.final_state.name, "reached_track": reached,
        "completed": done and (duration_s is None or flown >= duration_s - 0.05),
        "track_s": flown, "truth": record.truth_source,
    }
    pos, ref = record.position[window], record.ref_pos[window]
    out.update(tracking_errors(pos, ref))
    # a step is judged by its step figures; a lag needs a reference that keeps moving
    moving = step is None and window.sum() > 3
    out["lag_s"] = lag_s(clock[window], pos, ref) if moving else math.nan
    est = (tracking_errors(record.est_pos[window], pos) if record.has_truth
           else tracking_errors(pos[:0], pos[:0]))
    out["est_rms_m"], out["est_max_m"] = est["rms_m"], est["max_m"]
    if step is not None:
        out.update(_step(record, clock, track, step))
    out.update(_hold(record))
    airborne = record.during(*AIRBORNE)
    out["max_tilt_deg"] = (float(np.max(tilt_deg(record.attitude[airborne])))
                           if airborne.any() else math.nan)
    out.update(_timing(record))
    out["timing"] = record.timing_source
    return out
