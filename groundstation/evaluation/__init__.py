"""Evaluation: the flights of thesis Ch. 11 and issue 13 in the virtual lab, scored from
ground truth.

``gs eval`` is :func:`run_eval` (the suite of :mod:`.scenarios`, in-process with the
simulated clock or in real time over the pty and UDP; with ``perturb`` seeds on the
vehicles :func:`perturbation` draws, reduced by :func:`worst_case` and checked against
issue 13's targets by :func:`check_targets`); ``gs report LOG`` is
:func:`report_flight` (one recorded flight, with or without the virtual lab's
truth). Both write ``report.md``, ``metrics.json`` and PNG figures.

>>> from groundstation.config import load_config
>>> from groundstation.evaluation import run_eval
>>> report = run_eval(load_config("config/sim.yaml"), fast=True, out_dir="eval")  # doctest: +SKIP
>>> report.metrics["square-lqr-cv"]["lag_s"]  # doctest: +SKIP
"""

from groundstation.evaluation.perturb import perturbation
from groundstation.evaluation.record import FlightRecord, record_from_log, record_from_trace
from groundstation.evaluation.report import FlightReport, report_flight
from groundstation.evaluation.scenarios import SUITE, Scenario, select
from groundstation.evaluation.scoring import WorstCase, flight_metrics, worst_case
from groundstation.evaluation.suite import EvalReport, ScenarioOutcome, run_eval
from groundstation.evaluation.targets import TARGETS, check_targets

__all__ = [
    "SUITE",
    "TARGETS",
    "EvalReport",
    "FlightRecord",
    "FlightReport",
    "Scenario",
    "ScenarioOutcome",
    "WorstCase",
    "check_targets",
    "flight_metrics",
    "perturbation",
    "record_from_log",
    "record_from_trace",
    "report_flight",
    "run_eval",
    "select",
    "worst_case",
]
