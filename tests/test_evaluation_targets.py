"""Issue 13's targets, flown in CI: worst case over 5 perturbed vehicles.

Every scenario with a target (:data:`sim_device.evaluation.targets.TARGETS`) flies
in-process on the plants of seeds 1-5 (`gs eval --fast --perturb 1-5`): rate gains
+-30 % per axis, rate-loop time constant +-30 %, mass and thrust map +-15 %, command
delay 5-30 ms, IMU scale errors and biases, Vicon at 10 Hz. The errors come from the
virtual lab's ground truth. Deterministic for the seeds (simulated clock), so a
failure is a change of behaviour, never load on the machine.

Reached (this code), worst over the seeds, against the issue's targets: square 0.27 /
0.37 / 0.26 cm (1.0 off path / 1.5 in time / 2 per corner), at heading 135 deg 0.27 /
0.36 / 0.25 cm; figure-eight 0.58 cm (2); yaw turn 0.40 cm (1.5) and 1.5 deg at the
end (5); hover at 90/180/270 deg and after a take-off at 135 deg 0.37-0.44 cm (0.5);
H-infinity with rate gains 30 % low / high 0.69 / 0.64 cm (1); trajectory files flown once:
the dense CSV figure-eight at 8 s / 4 s a lap 0.66 / 2.50 cm (1 / 2.5), the Crazyflie
figure8.csv 1.54 cm (2.5).
"""

from __future__ import annotations

from pathlib import Path

import pytest

from groundstation.config import load_config
from sim_device.evaluation import run_eval
from sim_device.evaluation.targets import TARGETS, check_targets

pytestmark = [pytest.mark.slow, pytest.mark.timeout(900)]

REPO = Path(__file__).resolve().parents[1]


def test_every_target_is_met_on_five_perturbed_vehicles(tmp_path: Path) -> None:
    report = run_eval(load_config(REPO / "config" / "sim.yaml"), fast=True, out_dir=tmp_path,
                      scenarios=list(TARGETS), figures=False, perturb=[1, 2, 3, 4, 5])
    results = check_targets(report.metrics, report.worst_seeds)
    assert len(results) == sum(len(t) for t in TARGETS.values())
    missed = [r.line() for r in results if not r.met]
    assert not missed, "\n".join(missed)
