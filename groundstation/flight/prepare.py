"""The trajectory as it will be flown: built, shaped and checked before anything is
connected.

The configured trajectory (:attr:`FlightParams.trajectory <groundstation.flight.params.
FlightParams.trajectory>`) is built, dense samples are fitted, corners shaped, a path
that starts or ends moving eased in and out, and the curve to be flown is checked
against the flight limits and the volume; a commanded flight (``trajectory.name: none``)
gets its :class:`~groundstation.flight.commander.Commander`. Pure computation on the
flight's parameters.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import structlog

from groundstation.control.feasibility import FeasibilityReport, check_feasibility
from groundstation.control.polynomial import PiecewisePolynomial
from groundstation.control.shaping import describe, shape_for_flight
from groundstation.control.trajectories import build_trajectory
from groundstation.control.trajectory import PiecewiseLinear, Trajectory
from groundstation.errors import TrajectoryError
from groundstation.flight.commander import Commander
from groundstation.flight.params import FlightParams

_log = structlog.get_logger(__name__)


def commander_for_flight(params: FlightParams) -> Commander:
    """The commanded trajectory of ``trajectory.name: none``: hover at ``trajectory.center``
    (heading ``trajectory.yaw_deg``, or the one at take-off) until a client asks for more;
    TrajectoryError if the hover point is outside the volume."""
    commander = Commander.from_params(params.commander)
    check_feasibility(commander, params.limits, volume=params.volume, horizon_s=1.0)
    return commander


@dataclass(frozen=True)
class PreparedTrajectory:
    """A trajectory as it will be flown: ``trajectory`` for ``duration_s`` [s],
    ``report`` its feasibility (problems listed, if any), ``description`` what it was
    taken to be (fitted samples with their noise and residual, corners, polynomial
    segments, a closed form; eased or not)."""

    trajectory: Trajectory
    duration_s: float
    report: FeasibilityReport
    description: str


def prepare_trajectory(params: FlightParams, trajectory: Trajectory | None = None,
                       duration_s: float | None = None) -> PreparedTrajectory:
    """:func:`trajectory_for_flight` without raising on broken limits: the shaped
    trajectory, its duration, its feasibility report and what it was taken to be.
    TrajectoryError only if it cannot be built (a file that cannot be read)."""
    # the identification flight sizes its doublets from the limits and the volume
    sysid = {"limits": params.limits, "volume": params.volume,
             "rate_tau_s": params.vehicle.rate_tau} if params.trajectory.name == "sysid" else {}
    traj = trajectory if trajectory is not None else build_trajectory(params.trajectory,
                                                                      **sysid)
    if duration_s is None:
        lap = traj.periodic and traj.duration > 0.0
        if lap or isinstance(traj, PiecewiseLinear | PiecewisePolynomial):  # a file: once
            duration_s = traj.duration
        else:
            duration_s = max(traj.duration, params.trajectory.period_s)
    limits = params.limits
    traj, duration_s = shape_for_flight(traj, duration_s, limits.max_accel_m_s2, limits=limits,
                                        shaping=params.shaping)
    report = check_feasibility(traj, limits, volume=params.volume, horizon_s=duration_s,
                               raise_on_error=False)
    return PreparedTrajectory(traj, duration_s, report, describe(traj))


def trajectory_for_flight(params: FlightParams, trajectory: Trajectory | None = None,
                          duration_s: float | None = None) -> tuple[Trajectory, float]:
    """The trajectory to fly and how long to fly it [s], checked before flight.

    Builds ``params.trajectory`` unless ``trajectory`` is given; the default duration
    is one lap of a periodic trajectory, a file's (or a path's) own length, else the
    longer of the trajectory and ``trajectory.period_s``. Dense samples are fitted with
    a smooth curve, corners shaped with ``trajectory.shaping: min-jerk``, and a path
    that starts or ends moving is eased in and out (an eased start and end lengthen the
    flight by the ramp; :func:`~groundstation.control.shaping.shape_for_flight`). Then
    the curve to be flown is checked against the limits and the volume. What it was
    taken to be and its peaks are logged. Raises TrajectoryError (a file that cannot be
    read, one line per broken limit) before anything is connected.
    ``trajectory.name: none`` is the :func:`commander_for_flight`, flown until it lands.
    """
    if trajectory is None and params.commanded:  # flown by run-time commands
        return commander_for_flight(params), math.inf
    prepared = prepare_trajectory(params, trajectory, duration_s)
    traj, r = prepared.trajectory, prepared.report
    _log.info("trajectory", name=traj.name, taken_as=prepared.description,
              duration_s=round(prepared.duration_s, 3), feasible=r.feasible,
              max_speed_m_s=round(r.max_speed_m_s, 3), max_accel_m_s2=round(r.max_accel_m_s2, 3),
              max_tilt_deg=round(math.degrees(r.max_tilt_rad), 2),
              max_tilt_rate_rad_s=round(r.max_tilt_rate_rad_s, 3),
              max_yaw_rate_deg_s=round(math.degrees(r.max_yaw_rate_rad_s), 2))
    if r.problems:
        raise TrajectoryError(f"trajectory {traj.name!r} cannot be flown:\n  "
                              + "\n  ".join(r.problems))
    return traj, prepared.duration_s
