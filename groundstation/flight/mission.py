"""The reference the controller tracks in each supervisor phase.

Pure and clock-free: the flight core passes the time, the supervisor state and
the vehicle's position and heading when a phase begins. Every reference carries
exact position, velocity, acceleration, jerk, heading and heading rate; every
move is a rest-to-rest minimum-jerk segment
(:class:`~groundstation.control.minjerk.MinJerkSegment`) whose duration follows
from a speed and an acceleration limit, so the acceleration never steps.

* TAKEOFF: stay on the ground for ``spool_s`` (the thrust channel is still
  blending from the pilot's stick, so a climbing reference would only build up
  error), climb vertically from the ground position to the trajectory's start
  height at ``climb_speed``, then move horizontally to the trajectory's start
  point at the same speed (a mean speed: each move lasts as long as it would at
  that constant speed, or longer if the acceleration limit asks for it; the peak
  is 15/8 of it, so a landing takes as long as ``distance / land_speed``).
  From the top of the climb the heading turns the shortest way to the
  trajectory's start heading (an absolute heading) within ``max_yaw_rate``
  (a peak rate); a free-heading trajectory keeps the heading at take-off,
  which is added to its yaw from then on. Take-off is done when both moves are
  complete and the vehicle is within ``tolerance`` of the start point.
  Re-entered after a HOLD, it goes on from where the vehicle is, without spool.
* TRACK: the trajectory, on its own time axis, paused while in HOLD.
* HOLD: the position where the hold began, the heading the vehicle had then.
* LAND: descend from where landing began at ``land_speed`` (same profile) to just
  below the ground height (so the vehicle really touches down), then creep on down at
  ``creep_speed`` (its velocity eased in over ``creep_ramp_s``): a landing flown on a
  drifting dead-reckoned height keeps pushing down until the vehicle feels the floor,
  instead of hovering where the estimate says the floor is; the heading the vehicle had
  when the landing began.
* DISARM and after: where the vehicle was when the phase began (it is on the
  floor; before take-off, the origin), with its heading then.

All positions NED [m], velocities [m/s], headings [rad] (continuous: they may pass
+-pi; the controllers wrap the heading error).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from groundstation.control.minjerk import (
    MinJerkSegment,
    min_jerk_duration,
    smoothstep,
    smoothstep_integral,
)
from groundstation.control.trajectory import Trajectory
from groundstation.flight.supervisor import State
from groundstation.types import FloatArray, Reference


def wrap_angle(angle: float) -> float:
    """``angle`` [rad] wrapped to ``[-pi, pi)``."""
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


CREEP_RAMP_S = 1.0
"""Time over which the landing's creep below the floor eases in [s]."""

MOVE_JERK_PER_S = 4.0
"""Peak jerk of a take-off or landing move per m/s^2 of its acceleration limit [1/s]
(2 m/s^3 at the default 0.5 m/s^2): a horizontal jerk j turns the thrust at j / g, 0.2
rad/s there and 0.4 at 1 m/s^2, far inside the rate limits whatever the move's length."""


@dataclasses.dataclass(frozen=True, slots=True)
class MissionParams:
    """How the mission flies the phases around the trajectory: ``climb_speed`` and
    ``land_speed`` [m/s], ``spool_s`` on the ground at the start of take-off [s] (the
    handover blend), ``max_yaw_rate`` of the take-off's heading turn [rad/s], ``accel``
    the moves' acceleration limit [m/s^2]."""

    climb_speed: float
    land_speed: float
    spool_s: float
    max_yaw_rate: float
    accel: float


class Mission:
    """Reference generator across take-off, tracking, hold and landing.

    trajectory : the (shaped) trajectory, sampled at its own time [s] since its start
    duration_s : how long the trajectory is flown before landing [s]
    climb_speed, land_speed : [m/s]; accel : acceleration limit of the take-off and
        landing moves [m/s^2]; max_yaw_rate [rad/s], yaw_accel [rad/s^2] : of the
        take-off's heading turn
    tolerance : distance [m] to the start point within which take-off is done
    touchdown_depth : how far below the ground the landing aims [m]
    creep_speed : how fast the landing reference goes on down after that [m/s]
    spool_s : time on the ground at the start of take-off [s]
    """

    def __init__(self, trajectory: Trajectory, duration_s: float, climb_speed: float = 0.5,
                 land_speed: float = 0.3, tolerance: float = 0.1,
                 touchdown_depth: float = 0.1, spool_s: float = 0.0, *, accel: float = 0.5,
                 max_yaw_rate: float = math.radians(90.0), yaw_accel: float = 1.0,
                 creep_speed: float = 0.15) -> None:
        self._trajectory = trajectory
        self.duration_s = duration_s
        self._climb = climb_speed
        self._land = land_speed
        self._accel = accel
        self._yaw_rate = max_yaw_rate
        self._yaw_accel = yaw_accel
        self._tol = tolerance
        self._depth = touchdown_depth
        self._creep = creep_speed
        self._spool = spool_s
        self._state = State.PREFLIGHT
        self._ground = np.zeros(3)
        self._path: list[MinJerkSegment] = []
        self._turn: MinJerkSegment | None = None
        self._heading = 0.0  # held in HOLD, LAND and on the ground [rad]
        self._offset = 0.0  # added to the trajectory's yaw [rad]
        self._rest_point = np.zeros(3)
        self._track_clock = 0.0
        self._last_t: float | None = None

    @classmethod
    def from_params(cls, trajectory: Trajectory, duration_s: float,
                    params: MissionParams) -> Mission:
        """A mission flying ``trajectory`` for ``duration_s`` [s] as ``params`` describe."""
        return cls(trajectory, duration_s, climb_speed=params.climb_speed,
                   land_speed=params.land_speed, spool_s=params.spool_s,
                   max_yaw_rate=params.max_yaw_rate, accel=params.accel)

    @property
    def ground(self) -> FloatArray:
        """Where the vehicle stood at take-off, NED [m]."""
        return self._ground

    @property
    def heading_offset(self) -> float:
        """What is added to the trajectory's yaw [rad]: the heading at take-off for a
        free-heading trajectory, else the whole turns that make the heading continuous."""
        return self._offset

    @property
    def trajectory_time(self) -> float:
        """Seconds of trajectory flown so far (HOLD pauses it)."""
        return self._track_clock

    def enter(self, state: State, t: float, position: FloatArray, yaw: float = 0.0) -> None:
        """Tell the mission the supervisor entered ``state`` at ``t`` with the vehicle at
        ``position`` (NED [m]) and heading ``yaw`` [rad]."""
        if state is State.TAKEOFF:
            resumed = self._state is State.HOLD
            if not resumed:
                self._ground = position.copy()
            self._plan_takeoff(t if resumed else t + self._spool, position, yaw, resumed)
        elif state is State.LAND:
            end = np.array([position[0], position[1], self._ground[2] + self._depth])
            self._path = [self._move(t, position, end, self._land)]
            self._turn = None
        elif state is not State.TRACK:  # HOLD, DISARM and the terminal states: stay
            self._rest_point = position.copy()
        if state is not State.TAKEOFF and state is not State.TRACK:
            self._heading = yaw
        self._state = state
        self._last_t = t  # time before this phase never advances the trajectory clock

    def _move(self, t0: float, start: FloatArray, end: FloatArray,
              speed: float) -> MinJerkSegment:
        """A move at the mean ``speed`` (as long as at constant speed; the peak is 15/8 of
        it) unless the acceleration limit asks for longer."""
        length = float(np.linalg.norm(end - start))
        duration = max(length / speed,
                       min_jerk_duration(length, math.inf, self._accel,
                                         MOVE_JERK_PER_S * self._accel))
        return MinJerkSegment(t0, start.copy(), end.copy(), duration)

    def _plan_takeoff(self, t0: float, position: FloatArray, yaw: float, resumed: bool) -> None:
        """Climb, then move to the start; turn to the start heading from the top of the climb."""
        start = self._trajectory.sample(0.0)
        above = np.array([position[0], position[1], start.position[2]])
        climb = self._move(t0, position, above, self._climb)
        self._path = [climb, self._move(climb.end_time, above, start.position, self._climb)]
        if not resumed:
            self._heading = yaw
            self._offset = yaw if self._trajectory.free_heading else 0.0
        target = start.yaw + self._offset
        target = yaw + wrap_angle(target - yaw)  # the shortest way from where it points
        self._offset = target - start.yaw  # so TRACK continues the heading without a jump
        turn = min_jerk_duration(target - yaw, self._yaw_rate, self._yaw_accel)
        self._turn = MinJerkSegment(climb.end_time, np.array([yaw]), np.array([target]), turn)

    def _creep_below(self, dt: float, end: FloatArray
                     ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """The landing's creep ``dt`` [s] after its descent ended at ``end``: straight down,
        its speed eased from 0 to ``creep_speed`` over :data:`CREEP_RAMP_S`."""
        r, c = CREEP_RAMP_S, self._creep
        if dt < r:
            s, ds, dds, _ = smoothstep(dt / r)
            depth, speed, accel, jerk = c * r * smoothstep_integral(dt / r), c * s, c * ds / r, \
                c * dds / (r * r)
        else:
            depth, speed, accel, jerk = c * (dt - 0.5 * r), c, 0.0, 0.0
        down = np.array([0.0, 0.0, 1.0])
        return end + depth * down, speed * down, accel * down, jerk * down

    def takeoff_done(self, t: float, position: FloatArray) -> bool:
        """True when the take-off moves are complete and the vehicle is at the start."""
        if self._state is not State.TAKEOFF or not self._path:
            return False
        last = self._path[-1]
        finished = t >= last.end_time and (self._turn is None or t >= self._turn.end_time)
        return finished and float(np.linalg.norm(position - last.end)) < self._tol

    def trajectory_done(self) -> bool:
        """True once the trajectory has been flown for its duration."""
        return self._track_clock >= self.duration_s

    def preview(self, t: float, lead: float) -> Reference:
        """What :meth:`reference` would return at ``t + lead`` in the current phase, without
        advancing the trajectory clock (no side effects)."""
        ahead = t + lead
        return self._at(ahead, self._track_clock + self._elapsed(ahead))

    def reference(self, t: float) -> Reference:
        """The reference at time ``t`` for the current phase."""
        self._track_clock += self._elapsed(t) if self._state is State.TRACK else 0.0
        self._last_t = t
        return self._at(t, self._track_clock)

    def _elapsed(self, t: float) -> float:
        """Seconds since the last reference, none in a phase other than TRACK."""
        if self._state is not State.TRACK or self._last_t is None:
            return 0.0
        return max(t - self._last_t, 0.0)

    def _at(self, t: float, clock: float) -> Reference:
        """The reference at ``t`` with the trajectory clock at ``clock``."""
        state = self._state
        if state is State.TRACK:
            ref = self._trajectory.sample(clock)
            return dataclasses.replace(ref, yaw=ref.yaw + self._offset)
        if state in (State.TAKEOFF, State.LAND) and self._path:
            # before the first segment starts, at() clamps to its start: the ground
            seg = next((s for s in self._path if t < s.end_time), self._path[-1])
            p, v, a, j = seg.at(t)
            if state is State.LAND and t > seg.end_time:
                p, v, a, j = self._creep_below(t - seg.end_time, p)
            yaw, yaw_rate = self._heading, 0.0
            if self._turn is not None:
                y, dy, _, _ = self._turn.at(t)
                yaw, yaw_rate = float(y[0]), float(dy[0])
            return Reference(t=t, position=p, velocity=v, acceleration=a, jerk=j, yaw=yaw,
                             yaw_rate=yaw_rate)
        # HOLD, the ground phases and a TAKEOFF or LAND without a path: stay where it was
        return Reference(t=t, position=self._rest_point.copy(), velocity=np.zeros(3),
                         yaw=self._heading)
