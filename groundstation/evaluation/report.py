"""Writing results: ``metrics.json``, the Markdown tables, and ``gs report LOG``.

:func:`report_flight` is the whole of ``gs report``: one logged flight (real or
against the virtual lab, with its truth file) -> ``report.md``,
``metrics.json``, the overview ``flight.png`` and the figure set of
:mod:`.flight_figures` (position, top view, attitude, rates, sticks, estimator,
health, battery, timing). The suite's report
(:mod:`sim_device.evaluation.suite`) uses the same writers.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from groundstation import __version__
from groundstation.app.recorder import read_flight
from groundstation.errors import GroundStationError
from groundstation.evaluation.flight_figures import (
    BENCHMARK_TARGETS,
    FIGURES,
    FlightLog,
    write_flight_figures,
)
from groundstation.evaluation.metrics import SETTLING_BAND, track_clock
from groundstation.evaluation.plotting import pyplot
from groundstation.evaluation.record import FlightRecord, record_from_log
from groundstation.evaluation.scoring import StepSpec, flight_metrics
from groundstation.flight.supervisor import State, Transition

# (metrics key, column heading, scale, format)
COLUMNS: tuple[tuple[str, str, float, str], ...] = (
    ("rms_m", "RMS [cm]", 100.0, ".2f"),
    ("max_m", "max [cm]", 100.0, ".2f"),
    ("off_path_rms_m", "off path RMS [cm]", 100.0, ".2f"),
    ("corner_m", "corner [cm]", 100.0, ".2f"),
    ("lag_s", "lag [s]", 1.0, ".3f"),
    ("overshoot_pct", "overshoot [%]", 1.0, ".1f"),
    ("settling_s", "settling 2 % [s]", 1.0, ".2f"),
    ("heading_rms_deg", "heading RMS [deg]", 1.0, ".2f"),
    ("heading_end_deg", "heading end [deg]", 1.0, ".2f"),
    ("est_rms_m", "est. RMS [cm]", 100.0, ".2f"),
    ("est_max_m", "est. max [cm]", 100.0, ".2f"),
    ("hold_s", "HOLD [s]", 1.0, ".2f"),
    ("max_tilt_deg", "max tilt [deg]", 1.0, ".1f"),
    ("compute_p50_us", "tick p50 [us]", 1.0, ".0f"),
    ("compute_p99_us", "tick p99 [us]", 1.0, ".0f"),
)
REAL_TIME_COLUMNS: tuple[tuple[str, str, float, str], ...] = (
    ("jitter_p99_ms", "jitter p99 [ms]", 1.0, ".2f"),
    ("latency_p99_ms", "latency p99 [ms]", 1.0, ".2f"),
)

DEFINITIONS = f"""\
Definitions. Errors are Euclidean distances between the position and the reference
(NED), over the supervisor's TRACK phase after its first 2 s of trajectory time
(the end of the take-off); "position" is the virtual lab's ground truth unless a
row says otherwise. Off path: RMS distance of the same positions to the reference path
(the reference positions of one lap as a polyline), whatever the timing. Corner (squares):
the largest, over the four corners, of the closest approach of the flown path to the
corner. Lag: delay of the position behind the reference that maximises
their cross-correlation, over the axes on which the reference moves, refined below
one tick by a parabola through the peak (blank for hover and steps).
Overshoot and settling time: step flights, on the stepped axis, settling to within
{100 * SETTLING_BAND:g} % of the step. Heading: truth against the reference heading,
wrapped; RMS over the window and its size at the end of tracking.
Est.: estimate against truth over the same window.
HOLD: time spent holding on the IMU estimate. Max tilt: while airborne, from truth.
Tick p50/p99: time per flight-core tick (see "timing" above for how it was measured).
"""


def jsonable(value: Any) -> Any:
    """``value`` with NaN/inf floats as None and numpy scalars as Python numbers."""
    if isinstance(value, Mapping):
        return {str(k): jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [jsonable(v) for v in value]
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def transitions_json(transitions: Sequence[Transition], t0: float) -> list[list[Any]]:
    """``[[t - t0, old, new, reason], ...]`` for metrics.json."""
    return [[round(tr.t - t0, 3), tr.old.name, tr.new.name, tr.reason] for tr in transitions]


def states_line(transitions: Sequence[Transition]) -> str:
    """``TAKEOFF -> HOLD (Vicon lost ...) -> ...``: the states, with the reason of every
    transition that is not a step of a nominal flight (``Transition.nominal``)."""
    return " -> ".join(tr.new.name + ("" if tr.nominal or not tr.reason else f" ({tr.reason})")
                       for tr in transitions)


def write_json(path: Path, data: Mapping[str, Any]) -> Path:
    """Write ``data`` as indented JSON (NaN -> null)."""
    path.write_text(json.dumps(jsonable(data), indent=2) + "\n", encoding="utf-8")
    return path


def cell(metrics: Mapping[str, Any], key: str, scale: float, fmt: str) -> str:
    """One table cell: the scaled value, or blank if missing / not a number."""
    v = metrics.get(key)
    if not isinstance(v, int | float) or isinstance(v, bool) or not math.isfinite(v):
        return ""
    return format(v * scale, fmt)


def metrics_table(leading: Sequence[str], rows: Sequence[tuple[Sequence[str], Mapping[str, Any]]],
                  real_time: bool, seed_of: Sequence[Mapping[str, int]] | None = None) -> str:
    """A Markdown table: the ``leading`` columns, then :data:`COLUMNS` (and the real-time
    ones). rows : (leading cells as text, metrics) per row; seed_of : per row, the seed
    that gave each figure (worst case over perturbed plants), shown as ``(s3)``."""
    cols = COLUMNS + (REAL_TIME_COLUMNS if real_time else ())
    head = [*leading, *(heading for _, heading, _, _ in cols)]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for k, (lead, m) in enumerate(rows):
        seeds = seed_of[k] if seed_of is not None else {}
        values = [cell(m, key, scale, fmt) for key, _, scale, fmt in cols]
        values = [f"{v} (s{seeds[key]})" if v and key in seeds else v
                  for v, (key, _, _, _) in zip(values, cols, strict=True)]
        lines.append("| " + " | ".join([*lead, *values]) + " |")
    return "\n".join(lines) + "\n"


def step_from_reference(record: FlightRecord, min_step_m: float = 0.01) -> StepSpec | None:
    """The set-point step of a logged flight, read from its reference while tracking.

    A step flight's reference is constant apart from one jump: returns ``(axis,
    trajectory time of the jump [s], before, after)`` for the axis that jumped,
    or None if the reference moves otherwise (or not at all).
    """
    track = record.during(State.TRACK)
    if track.sum() < 3:
        return None
    clock = track_clock(record.t, track)[track]
    ref = record.ref_pos[track]
    jumps = np.abs(np.diff(ref, axis=0))
    moving = np.argwhere(jumps > 1e-9)
    if len(moving) != 1 or jumps[moving[0][0], moving[0][1]] < min_step_m:
        return None
    i, axis = int(moving[0][0]), int(moving[0][1])
    return axis, float(clock[i + 1]), float(ref[i, axis]), float(ref[i + 1, axis])


@dataclass(frozen=True)
class FlightReport:
    """What :func:`report_flight` wrote and computed.

    figure : the overview (``flight.png``), None without figures; figures : every PNG
    written (:data:`~.flight_figures.FIGURES` in order, the overview first)
    """

    record: FlightRecord
    metrics: dict[str, Any]
    report_md: Path
    metrics_json: Path
    figure: Path | None
    figures: tuple[Path, ...] = ()


def figures_section(figures: Sequence[Path], innovations: bool) -> list[str]:
    """report.md's list of the figures (Markdown lines), each with what it shows."""
    described = {stem: text for stem, text, _ in FIGURES}
    lines = ["## Figures", "",
             "Time axes: seconds since the first logged tick; dashed vertical lines are the "
             "supervisor's transitions (red: not a step of a nominal flight), named along "
             "the top of each figure.", ""]
    lines += [f"- [{p.name}]({p.name}): {described.get(p.stem, '')}" for p in figures]
    if innovations:
        lines += ["", "estimator.png starts with the NIS of every pose the estimator judged "
                  "against its chi-square gate; a consistent filter's NIS has the "
                  "chi-square (6 dof) median, 5.35. health.png marks the poses it refused."]
    else:
        lines += ["", "The flight log records no estimator innovations (a log older than "
                  "schema 5): estimator.png shows the Vicon pose minus the estimate of the "
                  "tick before it (moved to the pose time), an innovation proxy, with the "
                  "covariance diagonal's sigmas, and health.png counts the ticks that had "
                  "no pose at all."]
    t = BENCHMARK_TARGETS
    targets = ", ".join(f"{name} {value:g} ms" for name, value in (
        ("compute", t.compute_p99_ms), ("jitter", t.jitter_p99_ms),
        ("DATA-to-COMMAND latency", t.latency_p99_ms)) if value is not None)
    lines += ["", f"timing.png marks the real-time benchmark's p99 targets "
              f"(benchmarks/bench_flight.py): {targets}, and the configured DATA period."]
    for p in figures:
        lines += ["", f"![{p.stem}]({p.name})"]
    return lines


def report_after_flight(log_dir: Path, truth: Path | None) -> list[str]:
    """``gs fly --demo``'s report of the flight just flown (:func:`report_flight` into
    ``log_dir/report``, judged against the virtual lab's ``truth``): the lines saying where
    it is, or why there is none (the figure only where matplotlib is installed)."""
    lines = []
    try:
        try:
            report = report_flight(log_dir, truth)
        except GroundStationError as exc:  # matplotlib missing: the metrics still count
            lines.append(f"no figure: {exc}")
            report = report_flight(log_dir, truth, figures=False)
    except GroundStationError as exc:
        return [*lines, f"no report: {exc}"]
    lines.append(f"  report, judged from {report.record.truth_source}: {report.report_md}")
    if report.figure is not None:
        lines.append(f"  figure of the flown path against the reference: {report.figure}")
    return lines


def report_flight(log: str | Path, truth: str | Path | None = None,
                  out_dir: str | Path | None = None, *, figures: bool = True) -> FlightReport:
    """Metrics and figures of one recorded flight (``gs report LOG [--truth T] [--out DIR]``).

    log : flight-log directory; truth : the virtual lab's truth file (.npz) of the
    same run, else the metrics are computed from the estimate and labelled so;
    out_dir : default ``<log>/report``. Writes metrics.json, report.md and, with
    ``figures``, the figure set (:data:`~.flight_figures.FIGURES`: the overview
    flight.png, position.png, ...).
    RecorderError if the files cannot be read or do not belong together;
    GroundStationError if figures are asked for and matplotlib is missing (checked
    before anything is written).
    """
    record = record_from_log(log, truth)
    rows, meta, config_text = read_flight(log)
    if figures:
        pyplot()  # matplotlib missing: fail before writing anything
    out = Path(out_dir) if out_dir is not None else Path(log) / "report"
    out.mkdir(parents=True, exist_ok=True)
    metrics = flight_metrics(record, step=step_from_reference(record))
    t0 = float(record.t[0])
    flight_log = FlightLog.of(rows, meta, config_text, record, f"flight {Path(log).name}")
    written = tuple(write_flight_figures(flight_log, out)) if figures else ()
    figure = written[0] if written else None
    mj = write_json(out / "metrics.json", {
        "format": "groundstation flight report", "version": __version__, "log": str(log),
        "truth_file": str(truth) if truth is not None else None, "metrics": metrics,
        "transitions": transitions_json(record.transitions, t0)})
    table = metrics_table(["flight", "end"], [([Path(log).name, metrics["final_state"]], metrics)],
                          real_time=True)
    lines = [f"# Flight report: {Path(log).name}", "",
             f"- position judged from: **{record.truth_source}**",
             f"- timing: {record.timing_source}",
             f"- states: {states_line(record.transitions)}", "",
             table, DEFINITIONS]
    if written:
        lines += ["", *figures_section(written, flight_log.has_innovations)]
    md = out / "report.md"
    md.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return FlightReport(record, metrics, md, mj, figure, written)
