"""``gs eval``: fly the whole suite, score every flight, write the report.

:func:`run_eval` flies each :data:`~groundstation.evaluation.scenarios.SUITE`
scenario (in-process with ``fast``, else in real time over pty and UDP),
computes its metrics, and writes ``report.md`` (the metrics table and the
figures), ``metrics.json`` and the PNGs into ``out_dir``.
"""

from __future__ import annotations

import datetime as dt
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from groundstation import __version__
from groundstation.config import GroundStationConfig
from groundstation.control.simulate import SimResult
from groundstation.evaluation.figures import all_figures
from groundstation.evaluation.record import TIMING_FAST, TIMING_REAL_TIME, FlightRecord
from groundstation.evaluation.report import (
    DEFINITIONS,
    metrics_table,
    states_line,
    transitions_json,
    write_json,
)
from groundstation.evaluation.runner import run_in_process, run_real_time, simulate_model
from groundstation.evaluation.scenarios import (
    STEP_TIME_S,
    Scenario,
    scenario_config,
    scenario_trajectory,
    select,
    step_of,
)
from groundstation.evaluation.scoring import StepSpec, flight_metrics

Progress = Callable[[str], None]

CAPTIONS: dict[str, str] = {
    "fig11_1_hover_x.png": "Hover x(t) at Vicon 1, 10 and 100 Hz (thesis Fig. 11.1).",
    "fig11_2_hover_top.png": "Hover top view at the three rates (thesis Fig. 11.2).",
    "fig11_3_hover_1hz.png": "1 Hz Vicon: estimate, truth and Vicon samples (Fig. 11.3).",
    "fig11_4_steps.png": "Step responses on x, y, z: virtual lab and model simulation "
                         "(Fig. 11.4).",
    "fig11_5_square_top.png": "Square, mean of laps 2-6, per controller (thesis Fig. 11.5).",
    "fig11_6_square_xy.png": "Square: x(t), y(t) against the reference (thesis Fig. 11.6).",
    "fig11_7_yz_rectangle.png": "The y-z rectangle per controller (thesis Fig. 11.7).",
    "fig11_8_low_hover.png": "Hover at 2 cm (thesis Fig. 11.8).",
    "vicon_outage.png": "1 s Vicon outage during the square.",
    "thrust_error.png": "10 % thrust error during hover and the square.",
    "hinf.png": "H-infinity designed without and with the rate-loop model.",
}


@dataclass(frozen=True)
class ScenarioOutcome:
    """One flown scenario: its record, metrics and wall time [s]."""

    scenario: Scenario
    record: FlightRecord
    metrics: dict[str, Any]
    wall_s: float


@dataclass(frozen=True)
class EvalReport:
    """What :func:`run_eval` flew and wrote."""

    outcomes: dict[str, ScenarioOutcome]
    fast: bool
    out_dir: Path
    report_md: Path
    metrics_json: Path
    figures: list[Path]
    wall_s: float

    @property
    def metrics(self) -> dict[str, dict[str, Any]]:
        """Metrics by scenario name."""
        return {name: o.metrics for name, o in self.outcomes.items()}


def _step_spec(scenario: Scenario, config: GroundStationConfig) -> StepSpec | None:
    if not scenario.is_step:
        return None
    axis = "xyz".index(scenario.trajectory[-1])
    cfg = scenario_config(scenario, config)
    t_step, initial, final = step_of(scenario_trajectory(scenario, cfg))
    return axis, t_step, float(initial[axis]), float(final[axis])


def fly_scenario(scenario: Scenario, config: GroundStationConfig, *, fast: bool,
                 workdir: Path) -> ScenarioOutcome:
    """Fly one scenario and score it."""
    start = time.perf_counter()
    record = (run_in_process(scenario, config) if fast
              else run_real_time(scenario, config, workdir))
    wall = time.perf_counter() - start
    metrics = flight_metrics(record, settle_s=scenario.settle_s, duration_s=scenario.duration_s,
                             step=_step_spec(scenario, config))
    return ScenarioOutcome(scenario, record, metrics, wall)


def run_eval(config: GroundStationConfig, fast: bool = True, out_dir: str | Path = "eval", *,
             scenarios: Sequence[str] | None = None, figures: bool = True,
             progress: Progress | None = None) -> EvalReport:
    """Fly the suite (``gs eval``) and write ``report.md``, ``metrics.json`` and the figures.

    config : a virtual-lab configuration (``config/sim.yaml``); fast : in-process on
    the simulated clock, else in real time (flight logs under ``out_dir/flights``);
    scenarios : names to fly (default all); figures : render the PNGs (needs
    matplotlib); progress : receives one line per flight.
    ConfigError for a configuration without ``sim`` or an unknown scenario name.
    """
    chosen = select(scenarios)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    say = progress if progress is not None else (lambda _line: None)
    start = time.perf_counter()
    outcomes: dict[str, ScenarioOutcome] = {}
    for k, scenario in enumerate(chosen, start=1):
        o = fly_scenario(scenario, config, fast=fast, workdir=out / "flights")
        outcomes[scenario.name] = o
        say(f"[{k}/{len(chosen)}] {scenario.name}: {o.metrics['final_state']}, RMS "
            f"{100 * o.metrics['rms_m']:.2f} cm, {o.wall_s:.1f} s")
    models: dict[str, SimResult] = {s.name: simulate_model(s, config)
                                    for s in chosen if s.is_step}
    pngs = all_figures({n: o.record for n, o in outcomes.items()}, models, out,
                       config.trajectory.period_s) if figures else []
    wall = time.perf_counter() - start
    mj = write_json(out / "metrics.json", _json(outcomes, config, fast, wall))
    md = out / "report.md"
    md.write_text(_markdown(outcomes, config, fast, wall, pngs), encoding="utf-8")
    return EvalReport(outcomes, fast, out, md, mj, pngs, wall)


def _json(outcomes: dict[str, ScenarioOutcome], config: GroundStationConfig, fast: bool,
          wall: float) -> dict[str, Any]:
    scenarios = {}
    for name, o in outcomes.items():
        s = o.scenario
        scenarios[name] = {
            "title": s.title, "thesis": s.thesis, "controller": s.controller,
            "trajectory": s.trajectory, "vicon_hz": s.vicon_hz, "duration_s": s.duration_s,
            "overrides": dict(s.overrides), "wall_s": o.wall_s, "metrics": o.metrics,
            "transitions": transitions_json(o.record.transitions, float(o.record.t[0])),
        }
    return {"format": "groundstation evaluation", "version": __version__,
            "mode": "fast" if fast else "real-time",
            "date": dt.datetime.now(dt.UTC).isoformat(timespec="seconds"),
            "seed": config.sim.seed if config.sim is not None else None,
            "timing": TIMING_FAST if fast else TIMING_REAL_TIME, "wall_s": wall,
            "step_time_s": STEP_TIME_S, "scenarios": scenarios}


def _markdown(outcomes: dict[str, ScenarioOutcome], config: GroundStationConfig, fast: bool,
              wall: float, pngs: list[Path]) -> str:
    rows = [([f"`{n}`", o.scenario.controller, f"{o.scenario.vicon_hz:g}",
              o.metrics["final_state"] + ("" if o.metrics["completed"] else " (not completed)")],
             o.metrics) for n, o in outcomes.items()]
    table = metrics_table(["scenario", "controller", "Vicon [Hz]", "end"], rows,
                          real_time=not fast)
    seed = config.sim.seed if config.sim is not None else "-"
    lines = [
        "# Evaluation report", "",
        f"- mode: **{'fast (in-process, simulated clock)' if fast else 'real time (pty, UDP)'}**",
        f"- groundstation {__version__}, virtual lab seed {seed}, "
        f"{dt.datetime.now(dt.UTC):%Y-%m-%d %H:%M} UTC",
        f"- wall time: {wall:.1f} s for {len(outcomes)} flights",
        f"- timing: {TIMING_FAST if fast else TIMING_REAL_TIME}",
        f"- steps come {STEP_TIME_S:g} s after tracking starts; Vicon 10 Hz unless stated "
        "(thesis Ch. 11.1); hover uses the constant-position LQR as in the thesis",
        "", "## Metrics", "", table, DEFINITIONS, "## Flights", "",
    ]
    lines += [f"- `{n}`: {o.scenario.title} ({o.scenario.thesis}); states "
              f"{states_line(o.record.transitions)}" for n, o in outcomes.items()]
    if pngs:
        lines += ["", "## Figures", ""]
        for p in pngs:
            lines += [f"### {CAPTIONS.get(p.name, p.stem)}", "", f"![{p.stem}]({p.name})", ""]
    return "\n".join(lines) + "\n"
