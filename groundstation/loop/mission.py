"""The reference the controller tracks in each supervisor phase.

Pure and clock-free: the flight core passes the time and the supervisor state.

* TAKEOFF: stay on the ground for ``spool_s`` (the thrust channel is still
  blending from the pilot's stick, so a climbing reference would only build up
  error), climb vertically from the ground position to the trajectory's start
  height at ``climb_speed``, then move horizontally to the trajectory's start
  point at the same speed. Take-off is done when the path is complete and the
  vehicle is within ``tolerance`` of the start point.
* TRACK: the trajectory, on its own time axis, paused while in HOLD.
* HOLD: the position where the hold began, zero velocity.
* LAND: descend from where landing began at ``land_speed`` (same profile) to just below the
  ground height (so the vehicle really touches down), then stay there.
* DISARM and after: where the vehicle was when the phase began (it is on the
  floor; before take-off, the origin).

All positions NED [m], velocities [m/s].
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from groundstation.loop.supervisor import State
from groundstation.types import FloatArray, Reference

TrajectoryFn = Callable[[float], Reference]


@dataclass(frozen=True, slots=True)
class _Segment:
    """Straight line from ``start`` to ``end`` beginning at ``t0``, trapezoidal speed.

    Accelerates at ``accel`` to ``speed``, cruises, and decelerates to rest, so the
    reference never asks for an infinite acceleration (a velocity step makes a
    controller that feeds the reference velocity forward overshoot, Ch. 11.3).
    Short segments never reach ``speed`` (triangular profile).
    """

    t0: float
    start: FloatArray
    end: FloatArray
    speed: float
    accel: float = 0.5

    @property
    def length(self) -> float:
        return float(np.linalg.norm(self.end - self.start))

    @property
    def _peak(self) -> float:
        return min(self.speed, math.sqrt(self.accel * self.length))

    @property
    def duration(self) -> float:
        if self.length == 0.0:
            return 0.0
        v = self._peak
        return 2.0 * v / self.accel + (self.length - v * v / self.accel) / v

    def at(self, t: float) -> tuple[FloatArray, FloatArray]:
        """Position and velocity at time t (clamped to the segment)."""
        length = self.length
        if length == 0.0:
            return self.end.copy(), np.zeros(3)
        v, a, T = self._peak, self.accel, self.duration
        tau = min(max(t - self.t0, 0.0), T)
        t_acc = v / a
        if tau < t_acc:
            s, ds = 0.5 * a * tau * tau, a * tau
        elif tau > T - t_acc:
            rest = T - tau
            s, ds = length - 0.5 * a * rest * rest, a * rest
        else:
            s, ds = 0.5 * v * t_acc + v * (tau - t_acc), v
        direction = (self.end - self.start) / length
        return self.start + s * direction, direction * ds


class Mission:
    """Reference generator across take-off, tracking, hold and landing.

    trajectory : reference of the trajectory at its own time [s] since its start
    duration_s : how long the trajectory is flown before landing
    climb_speed, land_speed : [m/s]
    """

    def __init__(self, trajectory: TrajectoryFn, duration_s: float, climb_speed: float = 0.5,
                 land_speed: float = 0.3, tolerance: float = 0.1,
                 touchdown_depth: float = 0.1, spool_s: float = 0.0) -> None:
        self._trajectory = trajectory
        self.duration_s = duration_s
        self._climb = climb_speed
        self._land = land_speed
        self._tol = tolerance
        self._depth = touchdown_depth
        self._spool = spool_s
        self._state = State.PREFLIGHT
        self._ground = np.zeros(3)
        self._path: list[_Segment] = []
        self._hold_point = np.zeros(3)
        self._rest_point = np.zeros(3)
        self._track_clock = 0.0
        self._last_t: float | None = None

    @property
    def ground(self) -> FloatArray:
        """Where the vehicle stood at take-off, NED [m]."""
        return self._ground

    @property
    def trajectory_time(self) -> float:
        """Seconds of trajectory flown so far (HOLD pauses it)."""
        return self._track_clock

    def enter(self, state: State, t: float, position: FloatArray) -> None:
        """Tell the mission the supervisor entered ``state`` at ``t`` with the vehicle at
        ``position``."""
        if state is State.TAKEOFF:
            self._ground = position.copy()
            start = self._trajectory(0.0).position
            above = np.array([position[0], position[1], start[2]])
            first = _Segment(t + self._spool, position.copy(), above, self._climb)
            second = _Segment(first.t0 + first.duration, above, start.copy(), self._climb)
            self._path = [first, second]
        elif state is State.HOLD:
            self._hold_point = position.copy()
        elif state is State.LAND:
            end = np.array([position[0], position[1], self._ground[2] + self._depth])
            self._path = [_Segment(t, position.copy(), end, self._land)]
        elif state is not State.TRACK:
            self._rest_point = position.copy()
        self._state = state
        self._last_t = t  # time before this phase never advances the trajectory clock

    def takeoff_done(self, t: float, position: FloatArray) -> bool:
        """True when the take-off path is complete and the vehicle is at its end."""
        if self._state is not State.TAKEOFF or not self._path:
            return False
        last = self._path[-1]
        finished = t >= last.t0 + last.duration
        return finished and float(np.linalg.norm(position - last.end)) < self._tol

    def trajectory_done(self) -> bool:
        """True once the trajectory has been flown for its duration."""
        return self._track_clock >= self.duration_s

    def preview(self, t: float, lead: float) -> Reference:
        """The reference ``lead`` seconds after ``t`` in the current phase, without advancing
        the trajectory clock (call after :meth:`reference` for the same ``t``)."""
        state = self._state
        if state is State.TRACK:
            return self._trajectory(self._track_clock + lead)
        if state in (State.TAKEOFF, State.LAND) and self._path:
            ahead = t + lead
            seg = next((s for s in self._path if ahead < s.t0 + s.duration), self._path[-1])
            pos, vel = seg.at(ahead)
            return Reference(ahead, pos, vel)
        if state is State.HOLD:
            return Reference(t + lead, self._hold_point.copy(), np.zeros(3))
        return Reference(t + lead, self._rest_point.copy(), np.zeros(3))

    def reference(self, t: float) -> Reference:
        """The reference at time ``t`` for the current phase."""
        dt = 0.0 if self._last_t is None else max(t - self._last_t, 0.0)
        self._last_t = t
        state = self._state
        if state is State.TRACK:
            self._track_clock += dt
            return self._trajectory(self._track_clock)
        if state in (State.TAKEOFF, State.LAND) and self._path:
            seg = next((s for s in self._path if t < s.t0 + s.duration), self._path[-1])
            # before the first segment starts, at() clamps to its start: the ground
            pos, vel = seg.at(t)
            return Reference(t, pos, vel)
        if state is State.HOLD:
            return Reference(t, self._hold_point.copy(), np.zeros(3))
        return Reference(t, self._rest_point.copy(), np.zeros(3))
