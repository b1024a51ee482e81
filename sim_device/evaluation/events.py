"""How a flight answers one disturbance: the figures it is judged by, from the truth.

A payload step, a gust or a Vicon outage happens at a known lab time ``event_s``; the
figures look at the ``window_s`` after it, over the ticks the vehicle was flown to a
reference (TRACK, and HOLD while Vicon is lost):

* ``event_peak_m``: the largest distance of the truth from the reference;
* ``event_recover_s``: from the event to the first tick after that peak from which the
  distance stays within :data:`RECOVERED_M` for :data:`RECOVERED_FOR_S` (NaN if it never
  does in the window): "back within 1 cm";
* ``event_rms_m``: the RMS distance over the window;
* ``lap_rms_m`` (periodic references): the RMS distance over the lap, on the tracking
  clock, that contains the event;
* ``outage_est_max_m`` (a Vicon outage of ``outage_s``): the largest distance of the
  estimate from the truth from the outage's start to :data:`AFTER_OUTAGE_S` after its end:
  what dead reckoning let the estimate drift; ``outage_peak_m``: the truth's largest
  distance from the reference over the same span.

And for every flight, take-off and landing (ground effect acts there): ``takeoff_peak_m``
and ``land_peak_m``, the truth's largest distance from the reference during TAKEOFF and
LAND while the vehicle is above :data:`OFF_THE_FLOOR_M`.

Lab time is the record's clock in-process; in real time the caller passes ``t0``, the lab
time of the record's clock zero (the truth file's ``start_monotonic``).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from groundstation.evaluation.metrics import error_norms, track_clock
from groundstation.evaluation.record import FlightRecord
from groundstation.flight.supervisor import State

RECOVERED_M = 0.01
""""Back within 1 cm" [m]."""
RECOVERED_FOR_S = 0.5
"""...and staying there this long [s], so a crossing on the way is not a recovery."""
AFTER_OUTAGE_S = 0.2
"""The estimate's drift is judged until this long after Vicon is back [s]: the first poses
have to be fused (10 Hz Vicon: two of them)."""
OFF_THE_FLOOR_M = 0.01
"""Take-off and landing are judged above this height over the floor [m] (below it the
vehicle sits on the floor, where no reference is followed)."""

EVENT_KEYS = ("event_peak_m", "event_recover_s", "event_rms_m", "lap_rms_m",
              "outage_est_max_m", "outage_peak_m")
"""The figures of :func:`event_metrics` (NaN where the flight has no such event)."""


def event_metrics(record: FlightRecord, *, event_s: float | None, window_s: float = 10.0,
                  outage_s: float | None = None, period_s: float | None = None,
                  t0: float = 0.0) -> dict[str, Any]:
    """The figures of the module docstring (metres, seconds); NaN where not applicable.

    record : the flight; event_s : the event's lab time [s] or None; window_s : how long
    after it to look [s]; outage_s : a Vicon outage's length [s] from ``event_s``;
    period_s : the reference's lap [s] (periodic references); t0 : the lab time at the
    record's clock 0 (0 in-process).
    """
    out: dict[str, Any] = {k: math.nan for k in EVENT_KEYS}
    out.update(_phases(record))
    if event_s is None:
        return out
    t = record.t + t0
    err = error_norms(record.position, record.ref_pos)
    flown = record.during(State.TRACK, State.HOLD)
    window = flown & (t >= event_s) & (t <= event_s + window_s)
    if window.any():
        e, tw = err[window], t[window]
        out["event_peak_m"] = float(np.max(e))
        out["event_rms_m"] = float(np.sqrt(np.mean(e * e)))
        out["event_recover_s"] = _recovered(tw, e, event_s)
    if period_s is not None:
        track = record.during(State.TRACK)
        clock = track_clock(record.t, track)
        at = np.flatnonzero(track & (t >= event_s))
        if at.size:
            lap = math.floor(float(clock[at[0]]) / period_s)
            in_lap = track & (clock >= lap * period_s) & (clock < (lap + 1) * period_s)
            if in_lap.any():
                out["lap_rms_m"] = float(np.sqrt(np.mean(err[in_lap] ** 2)))
    if outage_s is not None and record.true_pos is not None:
        span = (t >= event_s) & (t <= event_s + outage_s + AFTER_OUTAGE_S)
        est = np.all(np.isfinite(record.est_pos), axis=1) & span
        if est.any():
            drift = error_norms(record.est_pos[est], record.true_pos[est])
            out["outage_est_max_m"] = float(np.max(drift))
        if (span & flown).any():
            out["outage_peak_m"] = float(np.max(err[span & flown]))
    return out


def _recovered(t: np.ndarray, e: np.ndarray, event_s: float) -> float:
    """Time from ``event_s`` to the first tick after the peak of ``e`` from which ``e``
    stays within :data:`RECOVERED_M` for :data:`RECOVERED_FOR_S` (or to the window's end,
    if that comes first); NaN if there is none."""
    within = e <= RECOVERED_M
    # index of the first tick outside at or after each tick (len(e) if none)
    nxt = np.full(len(e) + 1, len(e))
    for i in range(len(e) - 1, -1, -1):
        nxt[i] = nxt[i + 1] if within[i] else i
    for i in range(int(np.argmax(e)), len(e)):
        if within[i]:
            until = t[nxt[i]] if nxt[i] < len(e) else math.inf
            if until - t[i] >= RECOVERED_FOR_S or nxt[i] == len(e):
                return float(t[i] - event_s)
    return math.nan


def _phases(record: FlightRecord) -> dict[str, float]:
    """Take-off and landing: the truth's largest distance from the reference off the floor."""
    err = error_norms(record.position, record.ref_pos)
    floor = float(np.max(record.position[:, 2])) if len(record.position) else 0.0
    up = record.position[:, 2] < floor - OFF_THE_FLOOR_M
    out = {}
    for key, state in (("takeoff_peak_m", State.TAKEOFF), ("land_peak_m", State.LAND)):
        phase = record.during(state) & up
        out[key] = float(np.max(err[phase])) if phase.any() else math.nan
    return out
