"""Scoring a flight: one recorded flight's metrics, figures and report.

``gs report LOG`` is :func:`report_flight`: a flight log (real, or flown in the
virtual lab with the lab's truth file), aligned with its reference and, where
there is one, the ground truth (:mod:`.record`); metrics (:mod:`.metrics`,
:mod:`.scoring`) and the flight's figure set (:mod:`.flight_figures`). It writes
``report.md``, ``metrics.json``, ``flight.png`` (the overview) and one figure per
subject (position, top view, attitude, rates, commands, estimator, health, battery,
timing).

The evaluation suite that flies the thesis's Ch. 11 tests in the virtual lab
(``gs eval``) is the lab's: :mod:`sim_device.evaluation`, built on this package.
"""

from groundstation.evaluation.record import FlightRecord, record_from_log, record_from_trace
from groundstation.evaluation.report import FlightReport, report_flight
from groundstation.evaluation.scoring import WorstCase, flight_metrics, worst_case

__all__ = [
    "FlightRecord",
    "FlightReport",
    "WorstCase",
    "flight_metrics",
    "record_from_log",
    "record_from_trace",
    "report_flight",
    "worst_case",
]
