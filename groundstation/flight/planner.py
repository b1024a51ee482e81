"""What a run-time motion is planned from, and the jobs that plan it off the flight loop.

Planning a motion (:mod:`groundstation.flight.commander`) builds, shapes and checks a
trajectory, allocating up to hundreds of thousands of short-lived objects. In the
daemon that work runs in a process of its own (:class:`~groundstation.app.
planner_process.PlannerProcess`): a thread of the daemon's interpreter would share the
GIL and the garbage collector with the flight loop, and every full collection would walk
the planner's live objects (the hostile tester's 12 s plan made 28 full collections of
up to 38 ms and the vehicle's watchdog expire). This module holds what both sides share:

* :class:`PlannerSettings`, the plain record a planner plans with (the flight limits and
  volume, the shaping), built once with the flight's parameters
  (:mod:`groundstation.flight.assembly`);
* the jobs, small picklable records a planner runs: :class:`PrepareFollow` (build, bound,
  shape and check a trajectory to follow; the expensive part, before the loop is asked
  for a :class:`~groundstation.flight.commander.PlanBase`) and :class:`PlanMotion` (plan
  one motion from a base: a :class:`GoTo`, :class:`TakeOff`, :class:`Hold` or
  :class:`Follow`);
* :class:`InlinePlanner`, which runs them in the caller's thread: for a flight core
  nobody else steps (the in-process runner on its simulated clock, tests). Its work is
  bounded by the same checks before it starts (a motion of at most
  :data:`~groundstation.flight.commander.MAX_MOTION_S`), not by a deadline.

Every job bounds its work before doing it: durations, laps, ramps and the motion's
length are compared with :data:`~groundstation.flight.commander.MAX_MOTION_S` before
anything is sampled, so no request can make a planner sample more than that span.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal, Protocol

import numpy as np

from groundstation.control.feasibility import check_feasibility
from groundstation.control.shaping import shape_for_flight
from groundstation.control.trajectories import (
    TrajectorySpec,
    build_trajectory,
    waypoints_from_rows,
)
from groundstation.control.trajectory import Trajectory
from groundstation.errors import TrajectoryError
from groundstation.flight.commander import (
    MAX_MOTION_S,
    CommandRefusedError,
    Motion,
    MotionLimits,
    Plan,
    PlanBase,
    Planned,
    plan_follow,
    plan_go_to,
    plan_hold,
)
from groundstation.types import FloatArray


@dataclass(frozen=True, slots=True)
class PlannerSettings:
    """What motions are planned with: ``limits`` (the flight limits and volume, the default
    speed), the trajectory ``shaping`` (``trajectory.shaping``) and ``corner_smoothing_s``
    [s] of waypoint paths (``trajectory.corner_smoothing_s``)."""

    limits: MotionLimits
    shaping: Literal["min-jerk", "none"]
    corner_smoothing_s: float


class PlanJob(Protocol):
    """A unit of planning work: a picklable record whose :meth:`run` computes its result.
    Raises CommandRefusedError for a motion that cannot be flown."""

    def run(self, settings: PlannerSettings) -> Any:
        """The job's result, planned with ``settings``."""
        ...


class Planner(Protocol):
    """Runs planning jobs (:class:`InlinePlanner`, or the daemon's planner process)."""

    def run(self, job: PlanJob, deadline: float) -> Any:
        """``job``'s result; CommandRefusedError if the job refuses, or if it is not done by
        ``deadline`` (``time.monotonic()`` [s]) where the planner enforces one."""
        ...


class InlinePlanner:
    """Runs jobs in the caller's thread (a flight core nobody else steps: the in-process
    runner, tests). No deadline: each job bounds its own work (see the module)."""

    def __init__(self, settings: PlannerSettings) -> None:
        self.settings = settings

    def run(self, job: PlanJob, deadline: float) -> Any:
        """``job.run(settings)``; ``deadline`` is not enforced here."""
        return job.run(self.settings)


# --------------------------------------------------------------------------- follow
@dataclass(frozen=True, slots=True)
class Followable:
    """A trajectory to follow, shaped and checked from its time 0, flown for ``duration``
    [s]."""

    trajectory: Trajectory
    duration: float


def _refuse_long(what: str, seconds: float, start_in: float) -> None:
    """CommandRefusedError('infeasible') if ``seconds`` [s] (plus a ``start_in`` [s] before
    it begins) is longer than a motion may be."""
    total = seconds + max(start_in, 0.0)
    if not total <= MAX_MOTION_S:
        later = f" starting {start_in:.1f} s from now" if start_in > 0.0 else ""
        raise CommandRefusedError(
            "infeasible", f"{what} is {seconds:.1f} s{later}: longer than a motion may be "
            f"({MAX_MOTION_S:g} s); give a shorter duration")


@dataclass(frozen=True, slots=True)
class PrepareFollow:
    """Build the trajectory of a ``follow`` request, bound it, shape it and check it.

    spec : the trajectory of a validated ``trajectory:`` section (None for waypoints;
        :func:`groundstation.flight.assembly.trajectory_spec`); rows : waypoints
    ``[t, x, y, z(, yaw)]`` (s, NED m, rad), already checked at the boundary (None for a
    section); duration : how long to fly it [s] (None: one lap of a periodic trajectory,
    the longer of the trajectory and its ``period_s`` for the other named ones, the
    whole path of waypoints); start_in : seconds from the request until ``start_at``
    (0 without one). Result: a :class:`Followable`.
    """

    spec: TrajectorySpec | None
    rows: list[list[float]] | None
    duration: float | None
    start_in: float = 0.0

    def run(self, settings: PlannerSettings) -> Followable:
        """Refuses (``infeasible``) a motion longer than MAX_MOTION_S before any sampling,
        then again once shaping has added its ease-in and out; ``volume``/``infeasible``
        for a trajectory the check refuses; ``request`` for unusable waypoints."""
        lim = settings.limits
        try:
            if self.spec is not None:
                traj = build_trajectory(self.spec)
                lap = traj.duration if traj.periodic and traj.duration > 0.0 \
                    else max(traj.duration, self.spec.period_s)
                what = "one lap" if traj.periodic else "the trajectory"
            else:
                assert self.rows is not None
                try:
                    traj = waypoints_from_rows(self.rows, smoothing_s=settings.corner_smoothing_s,
                                               yaw=None, source="waypoints")
                except TrajectoryError as exc:
                    raise CommandRefusedError("request", str(exc)) from None
                lap, what = traj.duration, "the path"
            name = traj.name
            duration = lap if self.duration is None else self.duration
            _refuse_long(f"{what} of {name}" if self.duration is None else "the duration",
                         duration, self.start_in)
            if settings.shaping == "min-jerk":
                traj, duration = shape_for_flight(traj, duration, lim.flight.max_accel_m_s2)
                _refuse_long(f"{name}, eased in and out,", duration, self.start_in)
            check_feasibility(traj, lim.flight, volume=lim.volume, horizon_s=duration)
        except TrajectoryError as exc:
            raise CommandRefusedError("volume" if "outside" in str(exc) else "infeasible",
                                      str(exc)) from None
        return Followable(traj, duration)


# --------------------------------------------------------------------------- motions
class MotionSpec(Protocol):
    """One motion a client asked for, planned from a base (see :class:`PlanMotion`)."""

    def plan(self, base: PlanBase, limits: MotionLimits) -> Planned:
        """The motion planned from ``base``; CommandRefusedError if it cannot be flown."""
        ...


@dataclass(frozen=True, slots=True)
class GoTo:
    """Move to ``target`` (NED [m]) with the absolute heading ``yaw`` [rad] (None: keep it)
    in ``duration`` [s] (None: sized within the limits)."""

    target: FloatArray
    yaw: float | None
    duration: float | None

    def plan(self, base: PlanBase, limits: MotionLimits) -> Planned:
        """See :func:`~groundstation.flight.commander.plan_go_to`."""
        return plan_go_to(base, self.target, self.yaw, self.duration, limits)


@dataclass(frozen=True, slots=True)
class TakeOff:
    """Climb or descend straight to ``height`` [m] above the take-off point."""

    height: float

    def plan(self, base: PlanBase, limits: MotionLimits) -> Planned:
        """A vertical go to from where the reference is."""
        here = base.reference().position
        target = np.array([here[0], here[1], base.ground[2] - self.height])
        return plan_go_to(base, target, None, None, limits)


@dataclass(frozen=True, slots=True)
class Hold:
    """Stop as soon as the limits allow."""

    def plan(self, base: PlanBase, limits: MotionLimits) -> Planned:
        """See :func:`~groundstation.flight.commander.plan_hold`."""
        return plan_hold(base, limits)


@dataclass(frozen=True, slots=True)
class Follow:
    """Fly ``followable`` from trajectory time ``start`` [s] (None: once at its start)."""

    followable: Followable
    start: float | None

    def plan(self, base: PlanBase, limits: MotionLimits) -> Planned:
        """See :func:`~groundstation.flight.commander.plan_follow`."""
        f = self.followable
        return plan_follow(base, f.trajectory, f.duration, limits, self.start)


@dataclass(frozen=True, slots=True)
class PlanMotion:
    """Plan ``spec`` from ``base``. Result: the new pieces and the motion record (the
    requester pairs them with its own base: the base need not travel back)."""

    spec: MotionSpec
    base: PlanBase

    def run(self, settings: PlannerSettings) -> tuple[Plan, Motion]:
        """The planned pieces and motion."""
        planned = self.spec.plan(self.base, settings.limits)
        return planned.pieces, planned.motion


def plan_with(planner: Planner, spec: MotionSpec, base: PlanBase, deadline: float) -> Planned:
    """``spec`` planned from ``base`` by ``planner`` within ``deadline`` (monotonic [s])."""
    pieces, motion = planner.run(PlanMotion(spec, base), deadline)
    return Planned(base, pieces, motion)
