"""The targets, checked against the worst case over the perturbed plants.

:data:`TARGETS` holds, per scenario, the figures the issue asks for; :func:`check_targets`
compares them with the metrics of a run (``EvalReport.metrics``: the worst case over the
seeds under ``gs eval --perturb``, the one flight otherwise). A target is met only if
every flight of the scenario completed and the figure is within its limit. The report
prints the results next to the worst-case figures; a test can assert them::

    for result in check_targets(report.metrics, report.worst_seeds):
        assert result.met, result.line()
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class Target:
    """One figure the issue asks for: ``metrics[key] <= limit`` (in the metric's unit:
    metres, degrees), ``text`` as the issue words it."""

    key: str
    limit: float
    text: str


_SQUARE = (Target("off_path_rms_m", 0.010, "<= 1.0 cm RMS off the path"),
           Target("rms_m", 0.015, "<= 1.5 cm RMS against the reference in time"),
           Target("corner_m", 0.020, "every corner within 2 cm"))
_HOVER = (Target("rms_m", 0.005, "hover at any heading <= 0.5 cm RMS"),)
_HINF = (Target("rms_m", 0.010, "stable (completes) and <= 1 cm RMS"),
         Target("heading_rms_deg", 5.0, "stable in heading: <= 5 deg RMS (bound chosen "
                "here; the issue says only 'stable')"))

TARGETS: dict[str, tuple[Target, ...]] = {
    "square-shaped-lqr-ff": _SQUARE,
    "square-shaped-h135-lqr-ff": _SQUARE,
    "figure-eight-lqr-ff": (Target("rms_m", 0.020, "<= 2 cm RMS against the reference"),),
    "yaw-turn": (Target("rms_m", 0.015, "hover during the turn <= 1.5 cm RMS"),
                 Target("heading_end_deg", 5.0, "heading within 5 degrees at the end")),
    "takeoff-h135": _HOVER,
    "hover-h90": _HOVER,
    "hover-h180": _HOVER,
    "hover-h270": _HOVER,
    "hinf-rate-loop-model": _HINF,
    "hinf-rate-gains-low": _HINF,
    "hinf-rate-gains-high": _HINF,
    "file-eight-8s": (Target("rms_m", 0.010, "dense CSV eight, 8 s a lap: <= 1 cm RMS"),),
    "file-eight-4s": (Target("rms_m", 0.025, "dense CSV eight, 4 s a lap: <= 2.5 cm RMS"),),
    "file-figure8": (Target("rms_m", 0.025, "Crazyflie figure8.csv: <= 2.5 cm RMS"),),
    "hover-exact-angles": (Target("rms_m", 0.005, "hover on exact-angle Vicon: <= 0.5 cm RMS"),),
    # the disturbances' that this code meets (the others: OPEN below)
    "payload-eight-lqr-ff": (Target("lap_rms_m", 0.015, "+20 % payload during the 8 s "
                                    "figure-eight: <= 1.5 cm RMS over the lap with the step"),),
    "wind-hover-lqr-ff": (Target("rms_m", 0.005, "3 m/s steady wind: hover <= 0.5 cm RMS"),),
    "payload-hover-lqr-ff": (Target("event_recover_s", 1.0, "+20 % payload in hover: back "
                                    "within 1 cm in <= 1 s"),),
}
"""The targets this code meets, by scenario name (asserted in CI on five seeds)."""

OPEN: dict[str, tuple[Target, ...]] = {
    "payload-hover-lqr-ff": (Target("event_peak_m", 0.020, "+20 % payload in hover: peak "
                                    "<= 2 cm"),),
    "gust-hover-lqr-ff": (Target("event_peak_m", 0.020, "gust (1 s, 4 m/s): peak <= 2 cm"),),
    "outage-1s-hover": (Target("outage_est_max_m", 0.010, "1 s Vicon outage in hover: the "
                               "estimate's worst error <= 1 cm"),),
}
"""The disturbances' targets this code does not meet (the report shows them, not met, with the
figure reached; ``REACHED`` holds what it does reach, asserted in CI against regressions)."""

REACHED: dict[str, tuple[Target, ...]] = {
    "payload-hover-lqr-ff": (Target("event_peak_m", 0.034, "reached 3.12 cm; target: 2 cm"),),
    "gust-hover-lqr-ff": (Target("event_peak_m", 0.032, "reached 2.94 cm; target: 2 cm"),),
    "outage-1s-hover": (Target("outage_est_max_m", 0.026, "reached 2.35 cm; target: 1 cm; "
                               "the optimal filter's spread: 1.9 cm RMS"),),
}
"""Bounds on the figures of :data:`OPEN` (reached, worst of seeds 1-5, plus ~10 %)."""

SCALES: dict[str, tuple[float, str]] = {"_m": (100.0, "cm"), "_deg": (1.0, "deg"),
                                        "_s": (1.0, "s")}


def display(key: str, value: float) -> str:
    """``value`` of metric ``key`` in the report's unit (cm for lengths, degrees)."""
    for suffix, (scale, unit) in SCALES.items():
        if key.endswith(suffix):
            return f"{scale * value:.2f} {unit}"
    return f"{value:g}"


@dataclass(frozen=True)
class TargetResult:
    """One target against one scenario's figures.

    value : the (worst-case) figure, NaN if missing; seed : the seed that gave it (None
    for a nominal run); completed : every flight of the scenario completed
    """

    scenario: str
    target: Target
    value: float
    seed: int | None
    completed: bool

    @property
    def met(self) -> bool:
        """Completed and within the limit."""
        return self.completed and math.isfinite(self.value) and self.value <= self.target.limit

    def line(self) -> str:
        """One line for a failure message."""
        seed = f" (seed {self.seed})" if self.seed is not None else ""
        state = "" if self.completed else ", a flight did not complete"
        return (f"{self.scenario}: {self.target.key} = {display(self.target.key, self.value)}"
                f"{seed}, target {self.target.text}{state}")


def check_targets(metrics: Mapping[str, Mapping[str, Any]],
                  seed_of: Mapping[str, Mapping[str, int]] | None = None,
                  table: Mapping[str, tuple[Target, ...]] | None = None
                  ) -> list[TargetResult]:
    """The targets of every scenario present in ``metrics`` (name -> metrics).

    seed_of : name -> metric key -> the seed that gave the figure (worst case); None or
    missing for a nominal run; table : the targets to check (default :data:`TARGETS`).
    """
    out = []
    for name, targets in (TARGETS if table is None else table).items():
        m = metrics.get(name)
        if m is None:
            continue
        seeds = (seed_of or {}).get(name, {})
        for t in targets:
            v = m.get(t.key)
            value = float(v) if isinstance(v, int | float) and v is not None else math.nan
            out.append(TargetResult(name, t, value, seeds.get(t.key),
                                    bool(m.get("completed", False))))
    return out
