"""``gs eval``: fly the whole suite, score every flight, write the report.

:func:`run_eval` flies each :data:`~sim_device.evaluation.scenarios.SUITE`
scenario (in-process with ``fast``, else in real time over pty and UDP),
computes its metrics, and writes ``report.md`` (the metrics table and the
figures), ``metrics.json`` and the PNGs into ``out_dir``.

With ``perturb`` seeds (``gs eval --perturb 1-5``) every scenario flies once on each
seed's plant (:func:`~sim_device.evaluation.perturb.perturbation`); a scenario's
metrics are then the worst case over the seeds
(:func:`~groundstation.evaluation.scoring.worst_case`), each naming its seed, and
its record (for the figures) is that of its worst flight: one that did not complete,
else the one with the largest RMS error. Scenario overrides take precedence over the
drawn plant (the thrust-error flights keep their 10 %, the H-infinity rate-gain
flights their gains).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from groundstation.config import GroundStationConfig, apply_overrides
from groundstation.control.simulate import SimResult
from groundstation.evaluation.record import FlightRecord
from groundstation.evaluation.report import transitions_json, write_json
from groundstation.evaluation.scoring import StepSpec, flight_metrics, worst_case
from sim_device.evaluation.events import event_metrics
from sim_device.evaluation.figures import all_figures
from sim_device.evaluation.figures_disturbances import CAPTIONS as DISTURBANCE_CAPTIONS
from sim_device.evaluation.perturb import perturbation
from sim_device.evaluation.runner import run_in_process, run_real_time, simulate_model
from sim_device.evaluation.scenarios import (
    Scenario,
    corners_of,
    lap_period,
    scenario_config,
    scenario_trajectory,
    select,
    step_of,
)
from sim_device.evaluation.summary import eval_json, eval_markdown
from sim_device.evaluation.targets import OPEN, TargetResult, check_targets

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
    "hinf.png": "H-infinity designed without and with the rate-loop model (and the latter "
                "with rate gains 30 % low and high): tilt, height and heading.",
    "figure_eight.png": "Figure-eight 1.2 m x 0.6 m, 8 s per lap, top view: lqr-ff against "
                        "the reference, and the PID and the thesis's LQRs.",
    "yaw_turn.png": "360 degree yaw turn in 20 s: heading against the reference, heading "
                    "error, and horizontal position error.",
    "square_headings.png": "Shaped square at heading 0 and 135 degrees (lqr-ff): top views "
                           "with the nose direction, and the errors off the path and in time.",
    "takeoff_h135.png": "Take-off 2 cm off the hover point at heading 135 degrees: top view "
                        "and heading.",
    **DISTURBANCE_CAPTIONS,
}


@dataclass(frozen=True)
class SeedRun:
    """One flight of a scenario on one perturbed plant (its record is not kept)."""

    metrics: dict[str, Any]
    transitions: list[list[Any]]
    wall_s: float


@dataclass(frozen=True)
class ScenarioOutcome:
    """One flown scenario: its record, metrics and wall time [s].

    Nominal (one flight): ``runs`` empty, ``metrics`` that flight's. Perturbed:
    ``runs`` by seed, ``metrics`` the worst case over them, ``seed_of`` the seed of
    each figure, ``failed`` the seeds whose flight did not complete, ``record`` the
    flight of seed ``record_seed`` (the worst), ``wall_s`` the total.
    """

    scenario: Scenario
    record: FlightRecord
    metrics: dict[str, Any]
    wall_s: float
    runs: dict[int, SeedRun] = field(default_factory=dict)
    seed_of: dict[str, int] = field(default_factory=dict)
    failed: tuple[int, ...] = ()
    record_seed: int | None = None


@dataclass(frozen=True)
class EvalReport:
    """What :func:`run_eval` flew and wrote (``plants``: the drawn plant by seed, empty
    for a nominal run)."""

    outcomes: dict[str, ScenarioOutcome]
    fast: bool
    out_dir: Path
    report_md: Path
    metrics_json: Path
    figures: list[Path]
    wall_s: float
    plants: dict[int, dict[str, Any]] = field(default_factory=dict)

    @property
    def metrics(self) -> dict[str, dict[str, Any]]:
        """Metrics by scenario name (the worst case over the seeds when perturbed)."""
        return {name: o.metrics for name, o in self.outcomes.items()}

    @property
    def worst_seeds(self) -> dict[str, dict[str, int]]:
        """Scenario name -> metric -> the seed that gave the worst figure (empty: nominal)."""
        return {name: o.seed_of for name, o in self.outcomes.items()}

    def targets(self) -> list[TargetResult]:
        """The targets against :attr:`metrics`, those met and those still open
        (see :mod:`.targets`)."""
        return [*check_targets(self.metrics, self.worst_seeds),
                *check_targets(self.metrics, self.worst_seeds, OPEN)]


def _step_spec(scenario: Scenario, cfg: GroundStationConfig) -> StepSpec | None:
    if not scenario.is_step:
        return None
    axis = "xyz".index(scenario.trajectory[-1])
    t_step, initial, final = step_of(scenario_trajectory(scenario, cfg))
    return axis, t_step, float(initial[axis]), float(final[axis])


def fly_scenario(scenario: Scenario, config: GroundStationConfig, *, fast: bool,
                 workdir: Path) -> ScenarioOutcome:
    """Fly one scenario on the plant of ``config`` and score it."""
    start = time.perf_counter()
    record = (run_in_process(scenario, config) if fast
              else run_real_time(scenario, config, workdir))
    wall = time.perf_counter() - start
    cfg = scenario_config(scenario, config)
    metrics = flight_metrics(record, settle_s=scenario.settle_s, duration_s=scenario.duration_s,
                             step=_step_spec(scenario, cfg), period_s=lap_period(scenario, cfg),
                             corners=corners_of(scenario, cfg))
    t0 = 0.0 if fast else -lab_start(workdir / scenario.name / "truth.npz")
    metrics.update(event_metrics(
        record, event_s=scenario.event_s, window_s=scenario.window_s,
        outage_s=scenario.outage_s, period_s=lap_period(scenario, cfg), t0=t0))
    record = replace(record, meta={**record.meta, "lab_t0": t0})
    return ScenarioOutcome(scenario, record, metrics, wall)


def lab_start(truth_file: Path) -> float:
    """The monotonic time [s] at which a real-time lab's clock started (its truth file's
    ``start_monotonic``): lab time = monotonic time - this."""
    with np.load(truth_file, allow_pickle=False) as data:
        return float(data["start_monotonic"])


def _worse(a: dict[str, Any], b: dict[str, Any]) -> bool:
    """Flight ``a`` is worse than ``b``: it failed where ``b`` did not, or erred more."""
    if a["completed"] != b["completed"]:
        return not a["completed"]
    rms_a, rms_b = a.get("rms_m", math.nan), b.get("rms_m", math.nan)
    return bool(math.isfinite(rms_a) and not (math.isfinite(rms_b) and rms_b >= rms_a))


def plant_for(scenario: Scenario, plant: Mapping[str, Any]) -> dict[str, Any]:
    """The overrides of a drawn ``plant`` for ``scenario``: the plant, where the scenario's
    own overrides do not say otherwise (they are applied after it)."""
    return {k: v for k, v in plant.items() if k not in scenario.overrides}


def fly_perturbed(scenario: Scenario, config: GroundStationConfig,
                  plants: Mapping[int, Mapping[str, Any]], *, fast: bool,
                  workdir: Path) -> ScenarioOutcome:
    """Fly ``scenario`` on every seed's plant (``plants``: seed -> overrides, see
    :func:`plant_for`) and reduce the flights to the worst case; real-time flights go
    to ``workdir/seed-<s>``."""
    runs: dict[int, SeedRun] = {}
    kept: tuple[int, ScenarioOutcome] | None = None
    for seed, plant in plants.items():
        base = apply_overrides(config, plant_for(scenario, plant))
        o = fly_scenario(scenario, base, fast=fast, workdir=workdir / f"seed-{seed}")
        runs[seed] = SeedRun(o.metrics, transitions_json(o.record.transitions,
                                                         float(o.record.t[0])), o.wall_s)
        if kept is None or _worse(o.metrics, kept[1].metrics):
            kept = (seed, o)
    assert kept is not None, "fly_perturbed needs at least one seed"
    worst = worst_case({s: r.metrics for s, r in runs.items()})
    record = replace(kept[1].record, meta={**kept[1].record.meta, "seed": kept[0]})
    return ScenarioOutcome(scenario, record, worst.metrics,
                           sum(r.wall_s for r in runs.values()), runs, worst.seed_of,
                           worst.failed, kept[0])


def run_eval(config: GroundStationConfig, fast: bool = True, out_dir: str | Path = "eval", *,
             scenarios: Sequence[str] | None = None, figures: bool = True,
             progress: Progress | None = None,
             perturb: Sequence[int] | None = None) -> EvalReport:
    """Fly the suite (``gs eval``) and write ``report.md``, ``metrics.json`` and the figures.

    config : a virtual-lab configuration (``config/sim.yaml``); fast : in-process on
    the simulated clock, else in real time (flight logs under ``out_dir/flights``);
    scenarios : names to fly (default all); figures : render the PNGs (needs
    matplotlib); progress : receives one line per flight; perturb : seeds of the
    perturbed plants to fly every scenario on (None or empty: the nominal plant once).
    ConfigError for a configuration without ``sim``, an unknown scenario name or a
    negative seed.
    """
    chosen = select(scenarios)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    say = progress if progress is not None else (lambda _line: None)
    plants = {seed: perturbation(seed, config.vehicle.rate_loop_tau_s)
              for seed in (perturb or ())}
    start = time.perf_counter()
    outcomes: dict[str, ScenarioOutcome] = {}
    for k, scenario in enumerate(chosen, start=1):
        if plants:
            o = fly_perturbed(scenario, config, plants, fast=fast, workdir=out / "flights")
        else:
            o = fly_scenario(scenario, config, fast=fast, workdir=out / "flights")
        outcomes[scenario.name] = o
        seed = f" (worst: seed {o.seed_of['rms_m']})" if "rms_m" in o.seed_of else ""
        failed = f", failed on seed(s) {', '.join(map(str, o.failed))}" if o.failed else ""
        say(f"[{k}/{len(chosen)}] {scenario.name}: {o.metrics['final_state']}, RMS "
            f"{100 * o.metrics['rms_m']:.2f} cm{seed}{failed}, {o.wall_s:.1f} s")
    models: dict[str, SimResult] = {s.name: simulate_model(s, config)
                                    for s in chosen if s.is_step}
    pngs = all_figures({n: o.record for n, o in outcomes.items()}, models, out,
                       config.trajectory.period_s) if figures else []
    wall = time.perf_counter() - start
    report = EvalReport(outcomes, fast, out, out / "report.md", out / "metrics.json", pngs, wall,
                        plants)
    write_json(report.metrics_json, eval_json(report, config))
    report.report_md.write_text(eval_markdown(report, config, CAPTIONS), encoding="utf-8")
    return report
