"""``gs eval``'s ``metrics.json`` and ``report.md``, from an :class:`EvalReport`.

Nominal run: one flight per scenario, its metrics. Perturbed run (``--perturb``): per
scenario the worst case over the seeds with the seed that gave each figure, every
seed's own metrics and transitions in ``metrics.json``, the drawn plants, and the
targets (:mod:`sim_device.evaluation.targets`) next to the worst-case figures.
"""

from __future__ import annotations

import datetime as dt
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

from groundstation import __version__
from groundstation.config import GroundStationConfig
from groundstation.evaluation.record import TIMING_FAST, TIMING_REAL_TIME
from groundstation.evaluation.report import (
    DEFINITIONS,
    metrics_table,
    states_line,
    transitions_json,
)
from sim_device.config import sim_section
from sim_device.evaluation.perturb import PLANT_COLUMNS, RANGES, plant_row
from sim_device.evaluation.scenarios import STEP_TIME_S
from sim_device.evaluation.targets import TargetResult, display

if TYPE_CHECKING:
    from sim_device.evaluation.suite import EvalReport, ScenarioOutcome

TIMING_KEYS = ("compute_", "jitter_", "latency_")
"""Metrics that measure the code, not the plant: no seed is named for them."""


def _scenario_json(o: ScenarioOutcome) -> dict[str, Any]:
    s = o.scenario
    out: dict[str, Any] = {
        "title": s.title, "thesis": s.thesis, "controller": s.controller,
        "trajectory": s.trajectory, "vicon_hz": s.vicon_hz, "duration_s": s.duration_s,
        "overrides": dict(s.overrides), "wall_s": o.wall_s, "metrics": o.metrics,
        "transitions": transitions_json(o.record.transitions, float(o.record.t[0])),
    }
    if o.runs:
        out.update({"worst_seed": o.seed_of, "failed_seeds": list(o.failed),
                    "record_seed": o.record_seed,
                    "seeds": {str(seed): {"metrics": r.metrics, "transitions": r.transitions,
                                          "wall_s": r.wall_s} for seed, r in o.runs.items()}})
    return out


def eval_json(report: EvalReport, config: GroundStationConfig) -> dict[str, Any]:
    """The content of ``metrics.json``: per scenario its metrics (worst case when perturbed,
    with ``worst_seed``, ``failed_seeds`` and per-seed ``seeds``), the drawn plants
    (``perturbation``, null for a nominal run) and the targets."""
    perturbation = ({"ranges": RANGES, "seeds": list(report.plants),
                     "plants": {str(s): p for s, p in report.plants.items()}}
                    if report.plants else None)
    targets = [{"scenario": r.scenario, "metric": r.target.key, "limit": r.target.limit,
                "target": r.target.text, "value": r.value, "seed": r.seed,
                "completed": r.completed, "met": r.met} for r in report.targets()]
    return {"format": "groundstation evaluation", "version": __version__,
            "mode": "fast" if report.fast else "real-time",
            "date": dt.datetime.now(dt.UTC).isoformat(timespec="seconds"),
            "seed": sim_section(config).seed if config.sim is not None else None,
            "timing": TIMING_FAST if report.fast else TIMING_REAL_TIME,
            "wall_s": report.wall_s, "step_time_s": STEP_TIME_S,
            "perturbation": perturbation, "targets": targets,
            "scenarios": {name: _scenario_json(o) for name, o in report.outcomes.items()}}


def _plant_section(plants: Mapping[int, Mapping[str, Any]]) -> list[str]:
    lines = ["## Perturbed plants", "",
             "Each seed draws the virtual lab's vehicle uniformly and independently within "
             "(sim_device/evaluation/perturb.py):", ""]
    lines += [f"- {what}: {how}" for what, how in RANGES.items()]
    lines += ["", "Scenario overrides take precedence (the thrust-error flights keep their "
              "10 %, the H-infinity rate-gain flights their 30 %), and the H-infinity hovers "
              "take only the drawn rate gains and noise seed (the design has no integral "
              "action; the issue asks it to stand rate gains 30 % off)."]
    lines += ["", "Drawn (per cent off the design model; delay and time constant absolute):",
              "", "| " + " | ".join(PLANT_COLUMNS) + " |", "|" + "---|" * len(PLANT_COLUMNS)]
    lines += ["| " + " | ".join(plant_row(seed, p)) + " |" for seed, p in plants.items()]
    return [*lines, ""]


def _targets_section(results: list[TargetResult], perturbed: bool) -> list[str]:
    if not results:
        return []
    worst = "the worst case over the seeds" if perturbed else "from the nominal plant"
    lines = ["## Targets", "",
             f"Each figure is {worst}; a target is met only if every flight of the "
             "scenario completed.", "",
             "| scenario | target | figure | seed | met |", "|---|---|---|---|---|"]
    for r in results:
        seed = str(r.seed) if r.seed is not None else "-"
        verdict = "yes" if r.met else ("**no**" if r.completed else "**no** (not completed)")
        lines.append(f"| `{r.scenario}` | {r.target.text} | {display(r.target.key, r.value)} "
                     f"| {seed} | {verdict} |")
    return [*lines, ""]


def eval_markdown(report: EvalReport, config: GroundStationConfig,
                  captions: Mapping[str, str]) -> str:
    """The content of ``report.md`` (figures captioned from ``captions`` by file name)."""
    perturbed = bool(report.plants)
    rows, seed_rows = [], []
    for name, o in report.outcomes.items():
        end = o.metrics["final_state"] + ("" if o.metrics["completed"] else " (not completed)")
        if o.failed:
            end += f", failed: seed {', '.join(map(str, o.failed))}"
        rows.append(([f"`{name}`", o.scenario.controller, f"{o.scenario.vicon_hz:g}", end],
                     o.metrics))
        seed_rows.append({k: v for k, v in o.seed_of.items() if not k.startswith(TIMING_KEYS)})
    table = metrics_table(["scenario", "controller", "Vicon [Hz]", "end"], rows,
                          real_time=not report.fast, seed_of=seed_rows if perturbed else None)
    seed = sim_section(config).seed if config.sim is not None else "-"
    plant = (f"perturbed, seeds {', '.join(map(str, report.plants))} (`--perturb`): every "
             "figure is the worst case over the seeds, the seed that gave it in parentheses "
             "(s3 = seed 3); a flight that did not complete counts as failed"
             if perturbed else f"nominal (the design model), virtual lab seed {seed}")
    n_flights = sum(max(len(o.runs), 1) for o in report.outcomes.values())
    mode = "fast (in-process, simulated clock)" if report.fast else "real time (pty, UDP)"
    lines = [
        "# Evaluation report", "",
        f"- mode: **{mode}**",
        f"- plant: {plant}",
        f"- groundstation {__version__}, {dt.datetime.now(dt.UTC):%Y-%m-%d %H:%M} UTC",
        f"- wall time: {report.wall_s:.1f} s for {n_flights} flights",
        f"- timing: {TIMING_FAST if report.fast else TIMING_REAL_TIME}",
        f"- steps come {STEP_TIME_S:g} s after tracking starts; Vicon 10 Hz unless stated "
        "(thesis Ch. 11.1); hover uses the constant-position LQR as in the thesis; the "
        "Ch. 11 flights fly the thesis's raw references, the later ones shaped ones (min-jerk)",
        "", *_targets_section(report.targets(), perturbed),
        "## Metrics" + (f" (worst case over {len(report.plants)} plants)" if perturbed else ""),
        "", table, DEFINITIONS,
    ]
    if perturbed:
        lines += _plant_section(report.plants)
    lines += ["## Flights", ""]
    for n, o in report.outcomes.items():
        which = f" (seed {o.record_seed}, the worst)" if o.record_seed is not None else ""
        lines.append(f"- `{n}`: {o.scenario.title} ({o.scenario.thesis}); states{which} "
                     f"{states_line(o.record.transitions)}")
    if report.figures:
        lines += ["", "## Figures", ""]
        if perturbed:
            lines += ["Each scenario is drawn from its worst flight (one that did not "
                      "complete, else the largest RMS error): the seed named under Flights.",
                      ""]
        for p in report.figures:
            lines += [f"### {captions.get(p.name, p.stem)}", "", f"![{p.stem}]({p.name})", ""]
    return "\n".join(lines) + "\n"
