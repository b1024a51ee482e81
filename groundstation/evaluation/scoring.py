"""The metrics of one flight: what the report tables and the regression test read.

:func:`flight_metrics` applies the pure functions of
:mod:`groundstation.evaluation.metrics` to a :class:`FlightRecord`:

* tracking (RMS, per-axis RMS, maximum, lag) over the supervisor's TRACK
  phase after the first ``settle_s`` of trajectory time, from the truth (or,
  for a real flight, from the estimate: ``truth`` says which); the lag (not
  for steps) is measured on the trajectory's own clock, so a HOLD does not
  count as delay;
* the path, whatever the timing: RMS distance of the flown points off the
  reference path (the reference positions of one lap, or of the whole window if
  the reference is not periodic, as a polyline), and for a square the worst
  corner: the largest, over the corners, of the closest approach of the flown
  path (a polyline through the flown points) to the corner;
* heading: RMS of the wrapped heading error and its size at the end of tracking;
* the estimator error, truth against estimate, over the same window;
* for a step: overshoot, 2 % settling time, rise time and steady-state error of
  the stepped axis, on the trajectory's clock;
* time in HOLD and the largest distance from the hold point while holding;
* the largest tilt while airborne;
* timing percentiles (see ``timing`` for how they were measured).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from groundstation.evaluation.metrics import (
    error_norms,
    heading_deg,
    lag_s,
    path_distances,
    percentiles,
    rms,
    step_figures,
    tilt_deg,
    track_clock,
    tracking_errors,
    wrap_deg,
)
from groundstation.evaluation.record import FlightRecord
from groundstation.flight.supervisor import AIRBORNE, State
from groundstation.types import FloatArray

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


def _path(record: FlightRecord, clock: FloatArray, window: npt.NDArray[np.bool_],
          period_s: float | None, corners: FloatArray | None) -> dict[str, float]:
    out = {"off_path_rms_m": math.nan, "corner_m": math.nan}
    if window.sum() < 2:
        return out
    lap = window & (clock <= clock[window][0] + period_s) if period_s else window
    # one tick past the lap closes the loop of a periodic reference
    last = int(np.flatnonzero(lap)[-1])
    if period_s and last + 1 < len(lap) and window[last + 1]:
        lap[last + 1] = True
    flown = record.position[window]
    out["off_path_rms_m"] = rms(path_distances(flown, record.ref_pos[lap]))
    if corners is not None and len(corners):
        out["corner_m"] = float(np.max(path_distances(np.asarray(corners), flown)))
    return out


def _heading(record: FlightRecord, window: npt.NDArray[np.bool_]) -> dict[str, float]:
    if record.ref_yaw is None or window.sum() == 0:
        return {"heading_rms_deg": math.nan, "heading_end_deg": math.nan}
    err = wrap_deg(heading_deg(record.attitude[window])
                   - np.degrees(record.ref_yaw[window]))
    return {"heading_rms_deg": rms(err), "heading_end_deg": float(abs(err[-1]))}


def flight_metrics(record: FlightRecord, *, settle_s: float = 2.0,
                   duration_s: float | None = None, step: StepSpec | None = None,
                   period_s: float | None = None,
                   corners: FloatArray | None = None) -> dict[str, Any]:
    """Metrics of one flight as a flat dict (JSON-ready; NaN where not applicable).

    settle_s : trajectory time at the start of tracking left out of the tracking
    metrics [s]; duration_s : the trajectory time the flight was meant to fly
    (``completed`` then also requires it was flown); step : see :data:`StepSpec`;
    period_s : lap time of a periodic reference [s] (the path is one lap of it; None:
    the whole window's reference); corners : (K, 3) NED corner points [m] of a square
    (``corner_m``). Lengths [m], times [s], tilt and heading [deg], compute [us],
    jitter and latency [ms].
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
    out.update(_path(record, clock, window, period_s, corners))
    out.update(_heading(record, window))
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


SIGNED = frozenset({"lag_s", "steady_state_m"})
"""Signed metrics: the worst is the one of largest magnitude (a lead is as bad as a lag)."""

LEAST = frozenset({"track_s"})
"""Metrics whose worst is the smallest (trajectory time flown)."""


@dataclass(frozen=True)
class WorstCase:
    """The worst of one scenario's flights over the perturbed plants.

    metrics : a flat dict like :func:`flight_metrics`'s: each number the worst over the
        seeds (the largest; for :data:`SIGNED` ones the largest magnitude, sign kept;
        for :data:`LEAST` ones the smallest);
        ``completed`` and ``reached_track`` only if every flight did; ``final_state``
        that of the first failed flight (else the first flight's)
    seed_of : the seed that gave each number (none where several flights tie)
    failed : seeds whose flight did not complete
    """

    metrics: dict[str, Any]
    seed_of: dict[str, int]
    failed: tuple[int, ...]


def _number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)


def _badness(key: str, value: float) -> float:
    return abs(value) if key in SIGNED else -value if key in LEAST else value


def worst_case(per_seed: Mapping[int, Mapping[str, Any]]) -> WorstCase:
    """The worst case over ``per_seed`` (seed -> :func:`flight_metrics` of that flight).

    A flight that did not complete counts as failed whatever its numbers; numbers that
    are NaN in every flight stay NaN. ValueError if ``per_seed`` is empty.
    """
    if not per_seed:
        raise ValueError("worst_case needs the metrics of at least one flight")
    seeds = list(per_seed)
    failed = tuple(s for s in seeds if not per_seed[s].get("completed", False))
    first = per_seed[failed[0] if failed else seeds[0]]
    metrics: dict[str, Any] = dict(first)
    seed_of: dict[str, int] = {}
    keys = {k for m in per_seed.values() for k, v in m.items() if _number(v)}
    for key in sorted(keys):
        values = [(s, float(per_seed[s][key])) for s in seeds if _number(per_seed[s].get(key))]
        seed, value = max(values, key=lambda sv: _badness(key, sv[1]))
        metrics[key] = value
        if len(values) == 1 or any(v != value for _, v in values):  # a tie names no seed
            seed_of[key] = seed
    for key in ("completed", "reached_track"):
        metrics[key] = all(bool(m.get(key, False)) for m in per_seed.values())
    return WorstCase(metrics, seed_of, failed)
