"""The evaluation's targets, flown in CI: worst case over 5 perturbed vehicles.

Every scenario with a target (:data:`sim_device.evaluation.targets.TARGETS`) flies
in-process on the plants of seeds 1-5 (`gs eval --fast --perturb 1-5`): rate gains
+-30 % per axis, rate-loop time constant +-30 %, mass and thrust map +-15 %, command
delay 5-30 ms, the motors' lag 10-50 ms, IMU scale errors and biases, Vicon at 10 Hz.
The errors come from the virtual lab's ground truth. Deterministic for the seeds
(simulated clock), so a failure is a change of behaviour, never load on the machine.

One test per flight (scenario and seed): a target holds for the worst case over the
seeds exactly when it holds for each seed (the worst of these figures is their largest,
:func:`groundstation.evaluation.scoring.worst_case`), so the flights spread over the test
workers and none waits for another. A flight that another test also flies (the short
perturbed suite, `gs eval --perturb 3`, the disturbances) is flown once in the session,
by whichever worker needs it first (``eval_flights``).

Reached (this code), worst over the seeds, against the issue's targets: square 0.26 /
0.34 / 0.27 cm (1.0 off path / 1.5 in time / 2 per corner), at heading 135 deg 0.27 /
0.33 / 0.31 cm; figure-eight 0.57 cm (2); yaw turn 0.35 cm (1.5) and 1.5 deg at the
end (5); hover at 90/180/270 deg and after a take-off at 135 deg 0.35-0.42 cm (0.5);
H-infinity on the drawn plant / rate gains 30 % low / high 0.48 / 0.58 / 0.50 cm (1);
the trajectory files (dense eight 8 s / 4 s a lap, Crazyflie figure8.csv) 0.60 / 2.40 /
1.61 cm (1 / 2.5 / 2.5); hover on exact-angle Vicon 0.38 cm (0.5); +20 % payload mid-eight
0.84 cm over its lap (1.5) and in hover back within 1 cm in 0.72 s (1); 3 m/s wind 0.36 cm
(0.5).
"""

from __future__ import annotations

from pathlib import Path

import pytest
from eval_flights import PERTURBED_SEEDS, perturbed

from sim_device.evaluation.targets import TARGETS, check_targets

pytestmark = pytest.mark.slow


def _flights() -> list[object]:
    return [pytest.param(name, seed, id=f"{name}-seed{seed}")
            for name in TARGETS for seed in PERTURBED_SEEDS]


def test_the_targets_are_judged_on_five_seeds() -> None:
    assert PERTURBED_SEEDS == (1, 2, 3, 4, 5)  # `gs eval --fast --perturb 1-5`


@pytest.mark.parametrize(("name", "seed"), _flights())
def test_every_target_is_met_on_five_perturbed_vehicles(tmp_path: Path, name: str,
                                                        seed: int) -> None:
    outcome = perturbed(name, tmp_path, seeds=(seed,))
    results = check_targets({name: outcome.metrics}, {name: outcome.seed_of})
    assert len(results) == len(TARGETS[name])  # every target of the scenario was judged
    missed = [r.line() for r in results if not r.met]
    assert not missed, "\n".join(missed)
