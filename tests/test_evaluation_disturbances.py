"""What the lab throws at the vehicle, flown in CI: a payload, wind, a gust, a sagging battery,
ground effect, Vicon lost (`gs eval --fast --perturb 1-5`, sim_device/evaluation/scenarios.py).

The targets this code meets are in :data:`sim_device.evaluation.targets.TARGETS` and flown by
tests/test_evaluation_targets.py. Those it does not meet (:data:`~sim_device.evaluation.
targets.OPEN`: a +20 % payload's peak and its recovery, the gust's peak, the estimate's
drift through a 1 s Vicon outage) are held here to what it reaches
(:data:`~sim_device.evaluation.targets.REACHED`), worst of the five seeds, so a change that
loses ground fails. And no controller loses the vehicle in any of them: on seed 1's plant
every one of the five controllers flies every disturbance to the end, never tilting past
the supervisor's limit; nor does ``lqr-ff`` on vehicles whose lift comes late or early
(the corners below). Deterministic for the seeds (the simulated clock); the truth is the
virtual lab's.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from eval_flights import PERTURBED_SEEDS, base_config, flown, perturbed

from groundstation.config import SafetyConfig, apply_overrides
from groundstation.flight.supervisor import State
from sim_device.evaluation.perturb import perturbation
from sim_device.evaluation.scenarios import DISTURBANCES, select
from sim_device.evaluation.suite import plant_for
from sim_device.evaluation.targets import OPEN, REACHED, check_targets

pytestmark = pytest.mark.slow


def test_every_open_target_has_a_bound() -> None:
    assert set(REACHED) == set(OPEN)
    for name, targets in OPEN.items():
        assert [t.key for t in REACHED[name]] == [t.key for t in targets]
        assert all(r.limit > t.limit for r, t in zip(REACHED[name], targets, strict=True))


@pytest.mark.parametrize(("name", "seed"), [pytest.param(n, s, id=f"{n}-seed{s}")
                                            for n in REACHED for s in PERTURBED_SEEDS])
def test_what_is_reached_of_the_open_targets_holds(tmp_path: Path, name: str,
                                                    seed: int) -> None:
    outcome = perturbed(name, tmp_path, seeds=(seed,))
    results = check_targets({name: outcome.metrics}, {name: outcome.seed_of}, REACHED)
    missed = [r.line() for r in results if not r.met]
    assert not missed, "\n".join(missed)


@pytest.mark.parametrize("name", DISTURBANCES)
def test_no_controller_loses_the_vehicle(tmp_path: Path, name: str) -> None:
    m = perturbed(name, tmp_path, seeds=(1,)).metrics
    assert m["completed"], (name, m["final_state"])
    assert m["max_tilt_deg"] < SafetyConfig().max_tilt_deg, m["max_tilt_deg"]
    assert math.isfinite(m["rms_m"]) and m["rms_m"] < 1.0


# Vehicles beyond the perturbation box, where the external force's prediction of the lift is
# wrong in time as well as in size: lift per newton asked 1.35 and 0.74 times the model's
# (0.62 with the payload), the COMMAND's delay 5-45 ms against the model's 20 ms, motors of
# 10-50 ms against 20 ms, rate gains 30 % low and their loop 30 % slow. The last is inside
# the box but for its motors (35 ms): with the prediction at the nominal 20 ms it ran away
# in its take-off. Masses, thrust scales, delays [s], motors' lags [s].
LIFT_CORNERS = [
    pytest.param(0.85, 1.15, 0.045, 0.050, id="lift-1.35-slow"),
    pytest.param(0.85, 1.15, 0.005, 0.010, id="lift-1.35-fast"),
    pytest.param(1.15, 0.85, 0.045, 0.050, id="lift-0.74-slow"),
    pytest.param(1.15, 0.85, 0.005, 0.010, id="lift-0.74-fast"),
    pytest.param(0.85, 1.15, 0.030, 0.035, id="lift-1.35-motors-35ms"),
]


@pytest.mark.parametrize(("mass", "thrust", "delay_s", "motor_s"), LIFT_CORNERS)
def test_the_vertical_loop_through_the_external_force_holds_on_any_lift_dynamics(
        mass: float, thrust: float, delay_s: float, motor_s: float) -> None:
    """lqr-ff picks up the +20 % payload on each corner and ends its flight as planned:
    never handed back, within 10 cm of the reference in height all along (no external force
    at all: 4.5-13 cm on these plants), and settled to 1 cm RMS in the last 5 s (no limit
    cycle). Judged by the virtual lab's truth."""
    scenario = select(["payload-hover-lqr-ff"])[0]
    cfg = base_config()
    plant = {**perturbation(1, cfg.vehicle.rate_loop_tau_s), "sim.mass_scale": mass,
             "sim.thrust_scale": thrust, "sim.command_delay_s": delay_s,
             "sim.motor_tau_s": motor_s, "sim.k_rate_scale": [0.7, 0.7, 0.7],
             "sim.rate_loop_tau_s": 1.3 * cfg.vehicle.rate_loop_tau_s}
    record = flown(scenario, apply_overrides(cfg, plant_for(scenario, plant)))
    assert [t.new for t in record.transitions][-1] == State.DONE, record.transitions
    assert record.true_pos is not None
    track = record.state == State.TRACK
    dz = record.true_pos[track, 2] - record.ref_pos[track, 2]
    assert float(np.max(np.abs(dz))) < 0.10
    last = record.t[track] > record.t[track][-1] - 5.0
    assert float(np.sqrt(np.mean(dz[last] ** 2))) < 0.01
