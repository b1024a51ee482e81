"""Evaluation: the flights of thesis Ch. 11 and the later ones (shaped references, trajectory
files, disturbances) in the virtual lab, scored from ground truth.

``gs eval`` is :func:`run_eval` (the suite of :mod:`.scenarios`, in-process with the
simulated clock or in real time over the pty and UDP; with ``perturb`` seeds on the
vehicles :func:`perturbation` draws, reduced by
:func:`~groundstation.evaluation.worst_case` and checked against the targets (:mod:`.targets`) by
:func:`check_targets`). It writes ``report.md``, ``metrics.json`` and PNG figures; a
single flight's metrics and figure are the ground station's own
(:mod:`groundstation.evaluation`, ``gs report``).

>>> from groundstation.config import load_config
>>> from sim_device.evaluation import run_eval
>>> report = run_eval(load_config("config/sim.yaml"), fast=True, out_dir="eval")  # doctest: +SKIP
>>> report.metrics["square-lqr-cv"]["lag_s"]  # doctest: +SKIP
"""

from sim_device.evaluation.perturb import perturbation
from sim_device.evaluation.scenarios import SUITE, Scenario, select
from sim_device.evaluation.suite import EvalReport, ScenarioOutcome, run_eval
from sim_device.evaluation.targets import TARGETS, check_targets

__all__ = [
    "SUITE",
    "TARGETS",
    "EvalReport",
    "Scenario",
    "ScenarioOutcome",
    "check_targets",
    "perturbation",
    "run_eval",
    "select",
]
