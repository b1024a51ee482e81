"""Motions commanded at run time: the reference of ``gs fly --trajectory none``.

With ``trajectory.name: none`` the flight's trajectory is a :class:`Commander`. It
starts as a hover at ``trajectory.center`` (where the take-off goes) and changes
only when a client asks (:mod:`groundstation.client`, ``gs goto``): a move to a
point, a trajectory to follow, a stop. The ground station stays in charge: every
motion is planned here, checked against the same limits and volume as a
configured trajectory, and refused with a reason when it cannot be flown.

Planning and flying are split so that the flight loop never waits for a client:

* :class:`Commander` belongs to the flight core and is only touched by the loop
  thread. It is a :class:`~groundstation.control.trajectory.Trajectory` on the
  mission's trajectory clock (which HOLD pauses) and keeps the motions' book:
  started, arrived, pre-empted, how long the vehicle has been idle.
* The ``plan_*`` functions are pure and run off the loop, in the planner process
  (:mod:`groundstation.flight.planner`). They start from a :class:`PlanBase`, the plan in
  force and the
  trajectory time at which the new motion will begin (:data:`PLAN_LEAD_S` ahead of
  the loop), so the motion continues the reference exactly: position, velocity,
  acceleration and heading rate carry over. The loop installs the result
  (:meth:`Commander.install`) unless another motion was installed meanwhile or the
  start has already passed; the requester then plans again.

A plan is a tuple of :class:`Piece` s by start time; each holds until the next one
starts, and the last one is at rest. Motions:

* go to: a quintic in time from the reference's state at the start to rest at the
  target (position and heading at once), lasting ``duration`` or, by default, as
  long as the target is at ``api.speed_m_s`` (a mean speed) or longer if the
  acceleration, turn-rate or stop from the current velocity asks for it;
* follow: a go to the trajectory's start (at rest), the trajectory (shaped to start
  and end at rest), then rest at its end;
* hold: a stop from the current velocity to rest, as soon as the limits allow.

Positions are NED [m], headings [rad]. The plan's headings are on the mission's
scale (the mission adds its heading offset, see
:attr:`~groundstation.flight.mission.Mission.heading_offset`); a requested heading is
absolute and is converted with the offset in the :class:`PlanBase`.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from groundstation.config.ranges import MIN_MOTION_S
from groundstation.control.curve import HoldSet, PieceSet, PolySet
from groundstation.control.feasibility import FlightLimits, Volume, check_feasibility
from groundstation.control.minjerk import min_jerk_duration
from groundstation.control.trajectory import Trajectory
from groundstation.errors import GroundStationError, TrajectoryError
from groundstation.flight.mission import wrap_angle
from groundstation.types import FloatArray, Reference

PLAN_LEAD_S = 0.05
"""How far ahead of the loop's trajectory time a new motion starts [s]: time to plan it
and for the loop to install it (a go to plans in about 10 ms). A motion whose start has
passed when it reaches the loop is planned again with twice the lead."""

DEFAULT_MOVE_ACCEL_M_S2 = 1.0
"""Acceleration a go to without a duration is sized for [m/s^2] (the peak; the flight
limits allow g tan(20 deg) = 3.6): brisk but far from the tilt limit."""

MAX_MOTION_S = 600.0
"""Longest motion accepted [s], from its start to rest at its end, however its length
arises: a given duration, a trajectory's lap, the approach to a trajectory plus the
trajectory, a later ``start_at``. It also bounds the work of planning one (the checks
sample a motion's whole length)."""


RefusalKind = Literal["request", "state", "volume", "infeasible", "busy", "internal",
                      "separation"]


class CommandRefusedError(GroundStationError):
    """A motion command the ground station will not fly; ``kind`` says why:

    request : malformed or absurd (a position that is not 3 finite numbers, a heading
        beyond one turn, a duration outside [MIN_MOTION_S, MAX_MOTION_S], an unknown
        field)
    state : not now (not tracking yet, a failsafe acts, the flight has ended)
    volume : a point outside the flight volume (the sides and the ceiling less its
        margin; the floor itself)
    infeasible : beyond the vehicle's or the configured limits (speed, tilt, turn rate,
        a motion longer than MAX_MOTION_S, a plan not made within its deadline)
    busy : the plan changed while this one was planned, or the planner is starting (try
        again)
    internal : the ground station failed to answer (a fault of ours, logged)
    separation : it would bring the vehicle closer to a peer of its fleet than
        ``fleet.separation_m`` (groundstation/fleet/separation.py)
    """

    def __init__(self, kind: RefusalKind, reason: str) -> None:
        super().__init__(reason)
        self.kind: RefusalKind = kind
        self.reason = reason

    def __reduce__(self) -> tuple[type[CommandRefusedError], tuple[RefusalKind, str]]:
        """Pickled with its kind (it may cross to or from the planner process)."""
        return type(self), (self.kind, self.reason)


# --------------------------------------------------------------------------- pieces
@dataclass(frozen=True, slots=True)
class Piece:
    """One part of a plan, from trajectory time ``start`` [s] until the next one starts."""

    start: float

    def sample(self, tau: float) -> Reference:
        """The reference at trajectory time ``tau`` [s] (NED, SI units)."""
        raise NotImplementedError


@dataclass(frozen=True, slots=True)
class Rest(Piece):
    """Stay at ``point`` (NED [m]) with heading ``yaw`` [rad]."""

    point: FloatArray = field(default_factory=lambda: np.zeros(3))
    yaw: float = 0.0

    def sample(self, tau: float) -> Reference:
        """At rest."""
        return Reference(t=tau, position=self.point.copy(), velocity=np.zeros(3),
                         yaw=self.yaw)


@dataclass(frozen=True, slots=True)
class QuinticMove(Piece):
    """x, y, z and heading as quintics in time over ``[start, start + duration]``, at rest
    at the end (and held there after it).

    coeffs : (6, 4) polynomial coefficients, row k multiplying ``(tau - start)^k``, columns
    x, y, z [m] and heading [rad].
    """

    duration: float = 0.0
    coeffs: FloatArray = field(default_factory=lambda: np.zeros((6, 4)))

    @staticmethod
    def between(start: float, duration: float, p0: FloatArray, v0: FloatArray,
                a0: FloatArray, p1: FloatArray) -> QuinticMove:
        """The quintic from position, velocity and acceleration ``p0, v0, a0`` (4-vectors:
        x, y, z, heading) at ``start`` to rest at ``p1`` ``duration`` seconds later."""
        T = duration
        c0, c1, c2 = p0, v0, a0 / 2.0
        # the end conditions p(T) = p1, p'(T) = 0, p''(T) = 0 on c3..c5
        m = np.array([[T**3, T**4, T**5], [3 * T**2, 4 * T**3, 5 * T**4],
                      [6 * T, 12 * T**2, 20 * T**3]])
        rhs = np.stack([p1 - (c0 + c1 * T + c2 * T**2), -(c1 + 2 * c2 * T), -2 * c2])
        c345 = np.linalg.solve(m, rhs)
        return QuinticMove(start, duration, np.vstack([c0, c1, c2, c345]))

    @property
    def end(self) -> float:
        """When it is at rest at its target [trajectory s]."""
        return self.start + self.duration

    def sample(self, tau: float) -> Reference:
        """Exact position, velocity, acceleration, jerk, heading and heading rate."""
        s = min(max(tau - self.start, 0.0), self.duration)
        c = self.coeffs
        powers = s ** np.arange(6)
        p = powers @ c
        if tau >= self.end:
            v = a = j = np.zeros(4)
        else:
            v = (np.arange(1, 6) * powers[:5]) @ c[1:]
            a = (np.array([2, 6, 12, 20]) * powers[:4]) @ c[2:]
            j = (np.array([6, 24, 60]) * powers[:3]) @ c[3:]
        return Reference(t=tau, position=p[:3].copy(), velocity=v[:3].copy(),
                         acceleration=a[:3].copy(), yaw=float(p[3]), jerk=j[:3].copy(),
                         yaw_rate=float(v[3]))


@dataclass(frozen=True, slots=True)
class FollowPiece(Piece):
    """``trajectory`` from its time 0 at ``start`` for ``duration`` [s], its heading plus
    ``yaw_offset`` [rad]; after that its last point, at rest."""

    trajectory: Trajectory | None = None
    duration: float = 0.0
    yaw_offset: float = 0.0

    def sample(self, tau: float) -> Reference:
        """The trajectory on its own time axis."""
        assert self.trajectory is not None
        ref = self.trajectory.sample(min(max(tau - self.start, 0.0), self.duration))
        return dataclasses.replace(ref, t=tau, yaw=ref.yaw + self.yaw_offset)


Plan = tuple[Piece, ...]


def splice(plan: Plan, pieces: Plan) -> Plan:
    """``plan`` until the first of ``pieces`` starts, then ``pieces``."""
    return (*(p for p in plan if p.start < pieces[0].start), *pieces)


def sample_plan(plan: Plan, tau: float) -> Reference:
    """The reference of ``plan`` at trajectory time ``tau`` [s]: the last piece started by
    then (the first before any)."""
    current = plan[0]
    for piece in plan[1:]:
        if piece.start > tau:
            break
        current = piece
    return current.sample(tau)


# --------------------------------------------------------------------------- motions
MotionKind = Literal["go_to", "follow", "hold"]
MotionState = Literal["moving", "arrived", "superseded", "preempted"]


@dataclass
class Motion:
    """One accepted motion and what became of it.

    id : increasing from 1; kind : go_to, follow or hold; target : NED [m] where it ends,
    target_yaw : absolute heading there [rad] (None: kept); start, end : trajectory
    times [s] it starts moving and comes to rest; received : monotonic time [s] the
    request arrived; started : monotonic time [s] the reference began to move (None
    until then); arrived : monotonic time [s] it was at rest at the target and the
    estimate within the arrival tolerance (None until then); state, reason : what became
    of it (a failsafe or a later motion ends it early).
    """

    id: int
    kind: MotionKind
    target: FloatArray
    target_yaw: float | None
    start: float
    end: float
    received: float
    started: float | None = None
    arrived: float | None = None
    state: MotionState = "moving"
    reason: str = ""

    def report(self) -> dict[str, object]:
        """The motion for a status reply (plain JSON types; ``received_at`` and
        ``arrived_at`` on the daemon's monotonic clock [s], which on Linux is the machine's
        ``CLOCK_MONOTONIC``)."""
        return {"id": self.id, "kind": self.kind, "state": self.state, "reason": self.reason,
                "target": [float(v) for v in self.target],
                "target_yaw": self.target_yaw, "duration_s": self.end - self.start,
                "latency_s": None if self.started is None else self.started - self.received,
                "received_at": self.received, "arrived_at": self.arrived}


@dataclass(frozen=True, slots=True)
class PlanBase:
    """What a motion is planned from, taken in the loop: the plan in force and its
    ``version``, the trajectory time ``start`` [s] the new motion begins (the loop's time
    ``now`` plus the lead), the mission's heading ``offset`` [rad], the supervisor's state
    name and the take-off point ``ground`` (NED [m])."""

    plan: Plan
    version: int
    start: float
    offset: float
    state: str
    ground: FloatArray
    now: float = 0.0

    def reference(self) -> Reference:
        """The reference at the start: where the new motion begins."""
        return sample_plan(self.plan, self.start)


@dataclass(frozen=True, slots=True)
class Planned:
    """A motion planned from ``base``: the pieces from ``base.start`` on, and its motion
    record (``received`` filled in by the requester)."""

    base: PlanBase
    pieces: Plan
    motion: Motion


@dataclass(frozen=True, slots=True)
class MotionLimits:
    """How motions are sized and checked: the flight limits and volume (the configured
    trajectory's), the mean ``speed`` [m/s] of a go to without a duration and the
    acceleration ``accel`` [m/s^2] a default move is sized for."""

    flight: FlightLimits
    volume: Volume
    speed: float
    accel: float


def _state4(ref: Reference) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Position, velocity, acceleration of ``ref`` with the heading as a fourth axis."""
    return (np.append(ref.position, ref.yaw), np.append(ref.velocity, ref.yaw_rate),
            np.append(ref.acceleration, 0.0))


def check_target(point: FloatArray, volume: Volume, what: str = "") -> None:
    """CommandRefusedError('volume') unless ``point`` (NED [m]) is inside the volume: the
    sides and the ceiling less the margin, down to the floor itself (the floor has no
    margin, as in the feasibility check: a reference may go down to it). ``what`` starts
    the reason (e.g. ``"waypoint 3: "``)."""
    m = volume.margin_m
    for k, (axis, (lo, hi)) in enumerate(zip("xyz", (volume.x, volume.y, volume.z),
                                             strict=True)):
        v = float(point[k])
        box = f"{volume.name}_{axis} [{lo:.2f}, {hi:.2f}]"
        if axis == "z" and v > hi:
            raise CommandRefusedError("volume", f"{what}z = {v:.2f} m is below the floor: "
                                      f"outside {box} (the floor has no margin)")
        if not lo + m <= v <= (hi if axis == "z" else hi - m):
            raise CommandRefusedError("volume", f"{what}{axis} = {v:.2f} m is outside {box} "
                                      f"less the {m:.2f} m margin")


def _move_duration(start: Reference, target: FloatArray, yaw: float,
                   limits: MotionLimits) -> float:
    """A default duration [s] for a move from ``start`` to rest at ``target`` / ``yaw``: the
    distance at the mean speed, the acceleration limit, the turn at the yaw-rate limit,
    and time to stop from the current velocity."""
    distance = float(np.linalg.norm(target - start.position))
    speed = float(np.linalg.norm(start.velocity))
    lim = limits.flight
    return max(distance / limits.speed,
               min_jerk_duration(distance, math.inf, limits.accel),
               min_jerk_duration(yaw - start.yaw, lim.max_yaw_rate_rad_s, 1.0),
               3.0 * speed / limits.accel, 0.5)


@dataclass
class _PlanView:
    """``plan`` seen from time ``start`` as a trajectory from 0, for the feasibility check,
    which reads it exactly (:meth:`pieces`): no motion is checked by sampling."""

    plan: Plan
    start: float
    duration: float
    name: str = "motion"
    periodic: bool = False
    free_heading: bool = False

    def sample(self, t: float) -> Reference:
        return sample_plan(self.plan, self.start + t)

    def pieces(self, t0: float, t1: float) -> list[PieceSet] | None:
        """The plan over ``[t0, t1]`` (view time [s]) as the checker's piece sets: a quintic
        move is one polynomial segment (its coefficients; at rest at its end after it), a
        rest a hold. None (sampled instead) if a followed trajectory is flown in the span:
        it was checked on its own when it was planned."""
        out: list[PieceSet] = []
        plan = self.plan
        for i, piece in enumerate(plan):
            begin = piece.start - self.start
            end = plan[i + 1].start - self.start if i + 1 < len(plan) else max(t1, begin)
            if end <= t0 or begin > t1 or end <= begin:
                continue  # not the piece in force anywhere in the span
            if isinstance(piece, Rest):
                out.append(HoldSet(begin, end, piece.point, piece.yaw))
            elif isinstance(piece, QuinticMove):
                moving_until = min(end, begin + piece.duration)
                out.append(PolySet(np.array([begin]), np.array([moving_until]),
                                   piece.coeffs[None, :, :]))
                if moving_until < end:
                    rest = piece.sample(piece.end)
                    out.append(HoldSet(moving_until, end, rest.position, rest.yaw))
            else:
                return None
        return out


def _check(pieces: Plan, start: float, horizon: float, limits: MotionLimits) -> None:
    """CommandRefusedError('infeasible' or 'volume') listing every limit ``pieces`` break from
    ``start`` over ``horizon`` [s]."""
    try:
        check_feasibility(_PlanView(pieces, start, horizon), limits.flight,
                          volume=limits.volume, horizon_s=horizon, dt=0.02)
    except TrajectoryError as exc:
        kind: RefusalKind = "volume" if "outside" in str(exc) else "infeasible"
        raise CommandRefusedError(kind, str(exc)) from None


def plan_go_to(base: PlanBase, target: FloatArray, yaw: float | None,
               duration: float | None, limits: MotionLimits, *,
               kind: MotionKind = "go_to") -> Planned:
    """A move from the reference at ``base.start`` to rest at ``target`` (NED [m]) with the
    absolute heading ``yaw`` [rad] (None: keep the heading), taking ``duration`` [s] (None:
    see :func:`_move_duration`). Raises CommandRefusedError: ``request`` for a given
    duration outside [MIN_MOTION_S, MAX_MOTION_S], ``infeasible`` for a sized one longer
    than MAX_MOTION_S."""
    check_target(target, limits.volume)
    if duration is not None and not MIN_MOTION_S <= duration <= MAX_MOTION_S:
        raise CommandRefusedError("request", f"duration {duration:g} s: must be in "
                                  f"[{MIN_MOTION_S:g}, {MAX_MOTION_S:g}] s")
    ref = base.reference()
    goal_yaw = ref.yaw if yaw is None else ref.yaw + wrap_angle(yaw - base.offset - ref.yaw)
    if duration is None:
        duration = _move_duration(ref, target, goal_yaw, limits)
        if not duration <= MAX_MOTION_S:
            raise CommandRefusedError("infeasible", f"the move would take {duration:.1f} s, "
                                      f"longer than a motion may be ({MAX_MOTION_S:g} s)")
    p0, v0, a0 = _state4(ref)
    move = QuinticMove.between(base.start, duration, p0, v0, a0,
                               np.append(target, goal_yaw))
    pieces: Plan = (move, Rest(move.end, target.copy(), goal_yaw))
    _check(splice(base.plan, pieces), base.start, duration + 0.5, limits)
    motion = Motion(0, kind, target.copy(), None if yaw is None else goal_yaw + base.offset,
                    base.start, move.end, math.nan)
    return Planned(base, pieces, motion)


def plan_hold(base: PlanBase, limits: MotionLimits) -> Planned:
    """Stop from the reference's velocity ``v0`` at ``base.start`` and rest where that
    brings it. The stop is the quintic ``p0 + v0 T (x - x^3 + x^4 / 2)``, ``x = t / T``
    (zero speed and acceleration at its end, ``v0 T / 2`` from its start), whose peak
    deceleration ``1.5 |v0| / T`` is half the flight limits' acceleration. A stop is
    never refused: it only ever asks less of the vehicle than the motion it ends."""
    ref = base.reference()
    speed = float(np.linalg.norm(ref.velocity))
    duration = max(1.5 * speed / (0.5 * limits.flight.max_accel_m_s2), 0.2)
    target = ref.position + ref.velocity * duration / 2.0
    p0, v0, a0 = _state4(ref)
    move = QuinticMove.between(base.start, duration, p0, v0, a0,
                               np.append(target, ref.yaw + ref.yaw_rate * duration / 2.0))
    end = move.sample(move.end)
    motion = Motion(0, "hold", end.position, None, base.start, move.end, math.nan)
    return Planned(base, (move, Rest(move.end, end.position, end.yaw)), motion)


def plan_follow(base: PlanBase, trajectory: Trajectory, duration: float,
                limits: MotionLimits, start_at: float | None = None) -> Planned:
    """Go to the start of ``trajectory`` (already shaped and checked from its time 0), fly it
    for ``duration`` [s] from trajectory time ``start_at`` (None: as soon as it is there;
    it must be late enough for the approach), then rest at its end. A free-heading
    trajectory keeps the heading the vehicle has; an absolute one turns to its start
    heading on the way."""
    ref = base.reference()
    first = trajectory.sample(0.0)
    # the start heading on the mission's scale: the vehicle's for a free heading
    start_yaw = ref.yaw if trajectory.free_heading else first.yaw - base.offset
    approach = plan_go_to(base, first.position, start_yaw + base.offset, None, limits,
                          kind="follow")
    move = approach.pieces[0]
    assert isinstance(move, QuinticMove)
    yaw_offset = move.sample(move.end).yaw - first.yaw  # the turn went the short way
    begin = move.end
    if start_at is not None:
        if start_at < move.end:
            raise CommandRefusedError("infeasible", f"the trajectory's start is "
                                      f"{move.end - base.start:.1f} s away, more than the "
                                      f"{start_at - base.start:.1f} s until start_at")
        begin = start_at
    length = begin + duration - base.start
    if not length <= MAX_MOTION_S:
        raise CommandRefusedError(
            "infeasible", f"the motion would last {length:.1f} s (to the start "
            f"{begin - base.start:.1f} s, then the trajectory {duration:.1f} s), longer than "
            f"a motion may be ({MAX_MOTION_S:g} s): give a shorter duration")
    end_ref = trajectory.sample(duration)
    end_yaw = end_ref.yaw + yaw_offset
    pieces: Plan = (move, Rest(move.end, first.position.copy(), move.sample(move.end).yaw),
                    FollowPiece(begin, trajectory, duration, yaw_offset),
                    Rest(begin + duration, end_ref.position.copy(), end_yaw))
    motion = Motion(0, "follow", end_ref.position.copy(), end_yaw + base.offset, base.start,
                    begin + duration, math.nan)
    return Planned(base, pieces, motion)


# --------------------------------------------------------------------------- the loop's side
@dataclass(frozen=True, slots=True)
class CommanderParams:
    """The commanded flight (``trajectory.name: none``): the ``home`` it takes off to and
    holds at, NED [m], its heading ``yaw`` [rad] (None: the heading at take-off),
    ``arrival_tolerance_m`` [m] and ``idle_land_s`` [s] (see :class:`Commander`)."""

    home: tuple[float, float, float]
    yaw: float | None
    arrival_tolerance_m: float
    idle_land_s: float


class Commander:
    """The commanded trajectory and the book of motions (loop thread only).

    home : the hover point the take-off goes to, NED [m]; yaw : its heading [rad] (None:
    free heading, the heading at take-off); arrival_tolerance_m : how close the estimate
    must be to a motion's target for it to have arrived [m]; idle_land_s : land after
    this long at rest without a motion command [s].
    """

    name = "none"
    duration = math.inf
    periodic = False

    @classmethod
    def from_params(cls, params: CommanderParams) -> Commander:
        """The commander ``params`` describe, holding at its home."""
        return cls(np.asarray(params.home, dtype=float), params.yaw,
                   arrival_tolerance_m=params.arrival_tolerance_m,
                   idle_land_s=params.idle_land_s)

    def __init__(self, home: FloatArray, yaw: float | None, *, arrival_tolerance_m: float,
                 idle_land_s: float) -> None:
        self.free_heading = yaw is None
        self._plan: Plan = (Rest(0.0, np.asarray(home, dtype=float).copy(),
                                 0.0 if yaw is None else yaw),)
        self.version = 0
        self._tolerance = arrival_tolerance_m
        self._idle_land_s = idle_land_s
        self.motions: list[Motion] = []
        """Every motion accepted, oldest first."""
        self._idle_since: float | None = None

    @property
    def plan(self) -> Plan:
        """The plan in force."""
        return self._plan

    @property
    def current(self) -> Motion | None:
        """The latest motion, if any."""
        return self.motions[-1] if self.motions else None

    def sample(self, t: float) -> Reference:
        """The reference at trajectory time ``t`` [s]."""
        return sample_plan(self._plan, t)

    def base(self, tau: float, offset: float, state: str, ground: FloatArray,
             lead: float = PLAN_LEAD_S) -> PlanBase:
        """What a motion requested now is planned from (the loop's trajectory time ``tau``)."""
        return PlanBase(self._plan, self.version, tau + lead, offset, state, ground.copy(), tau)

    def install(self, planned: Planned, tau: float) -> Motion:
        """Fly ``planned`` from its start; returns its motion with its id. Raises
        CommandRefusedError('busy') if the plan changed since it was planned or its start has
        passed (loop trajectory time ``tau`` [s])."""
        base = planned.base
        if base.version != self.version:
            raise CommandRefusedError("busy", "another motion was accepted meanwhile")
        if tau > base.start:
            raise CommandRefusedError("busy", "planning took longer than the lead")
        self._plan = self._prune(splice(self._plan, planned.pieces), tau)
        self.version += 1
        for motion in self.motions:
            if motion.state == "moving":
                motion.state, motion.reason = "superseded", f"by motion {len(self.motions) + 1}"
        motion = dataclasses.replace(planned.motion, id=len(self.motions) + 1)
        self.motions.append(motion)
        self._idle_since = None
        return motion

    @staticmethod
    def _prune(pieces: Plan, tau: float) -> Plan:
        """``pieces`` without those a later piece replaced before ``tau``."""
        keep = [p for i, p in enumerate(pieces)
                if i + 1 >= len(pieces) or pieces[i + 1].start > tau]
        return tuple(keep) or pieces[-1:]

    def preempt(self, tau: float, reason: str) -> None:
        """A failsafe took over at trajectory time ``tau``: the motion in progress ends
        (``preempted``) and the plan rests where the reference was."""
        ref = self.sample(tau)
        self._plan = (Rest(tau, ref.position.copy(), ref.yaw),)
        self.version += 1
        motion = self.current
        if motion is not None and motion.state == "moving":
            motion.state, motion.reason = "preempted", reason

    def update(self, t: float, tau: float, tracking: bool, position: FloatArray) -> str:
        """Each tick: note motions starting and arriving; returns why to land ("" for no):
        at rest without a motion command for ``idle_land_s``. ``t`` monotonic [s], ``tau``
        trajectory time [s], ``tracking`` the supervisor is in TRACK, ``position`` the
        estimate NED [m]."""
        motion = self.current
        if motion is not None and motion.state == "moving":
            if motion.started is None and tau >= motion.start:
                motion.started = t
            if tau >= motion.end and \
                    float(np.linalg.norm(position - motion.target)) < self._tolerance:
                motion.state, motion.arrived = "arrived", t
        # idle once the plan is at rest, arrived within the tolerance or not
        at_rest = motion is None or motion.state != "moving" or tau >= motion.end
        if not (tracking and at_rest):
            self._idle_since = None
        elif self._idle_since is None:
            self._idle_since = t
        elif t - self._idle_since >= self._idle_land_s:
            return f"idle for {self._idle_land_s:g} s without a motion command"
        return ""

    def idle_land_in(self, t: float) -> float | None:
        """Seconds until an idle landing [s], None while a motion is under way."""
        if self._idle_since is None:
            return None
        return max(0.0, self._idle_land_s - (t - self._idle_since))
