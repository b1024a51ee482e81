"""The safety supervisor: one state machine that decides who flies and how.

Pure logic, no clock and no I/O: the flight core hands in a :class:`Observation`
each tick and reads back the state. Every transition is recorded with its
time and reason and logged.

States and transitions::

    PREFLIGHT --checks pass--> TAKEOFF --at height--> TRACK --done/stop--> LAND
                                                                          |
    LAND --on the floor--> DISARM (thrust to idle, 0.5 s) --> DONE (hand back)

    airborne (TAKEOFF, TRACK, HOLD, LAND):
      Vicon silent > vicon_loss_hold_s         -> HOLD (hold position on the IMU estimate)
      HOLD and Vicon back                      -> the state HOLD interrupted
      HOLD and Vicon silent > vicon_loss_land_s -> LAND
      outside the volume or tilt > max         -> LAND
      TAKEOFF not done after takeoff_timeout_s -> LAND
      LAND and tilt > handback tilt            -> HANDBACK (the landing lost the attitude)
    any state:
      estimator diverged                       -> HANDBACK (mask 0 at once)
      no DATA for link_loss_s (after PREFLIGHT) -> LINK_LOST (log and stop)
      pilot switch off / X-3D not applying us  -> PILOT (respected at once)
      second stop request                      -> HANDBACK
      first stop request: airborne -> LAND (or HANDBACK if configured); on the ground -> DONE
    PREFLIGHT longer than preflight_timeout_s  -> ABORTED

Terminal states: DONE, HANDBACK, PILOT, LINK_LOST, ABORTED. In every terminal state
and in PREFLIGHT the ground station sends ctrl mask 0: the pilot has the vehicle.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass, field

import structlog

log = structlog.get_logger(__name__)


class State(enum.IntEnum):
    """Supervisor states; the integer is what the flight recorder stores."""

    PREFLIGHT = 0
    TAKEOFF = 1
    TRACK = 2
    HOLD = 3
    LAND = 4
    DISARM = 5
    DONE = 6
    HANDBACK = 7
    PILOT = 8
    LINK_LOST = 9
    ABORTED = 10


AIRBORNE = frozenset({State.TAKEOFF, State.TRACK, State.HOLD, State.LAND})
TERMINAL = frozenset({State.DONE, State.HANDBACK, State.PILOT, State.LINK_LOST, State.ABORTED})
FLYING = AIRBORNE | {State.DISARM}
"""States in which the ground station commands the vehicle (ctrl mask set)."""


@dataclass(frozen=True, slots=True)
class SupervisorLimits:
    """Limits and times (see :class:`groundstation.config.SafetyConfig`)."""

    volume_x: tuple[float, float] = (-1.5, 1.5)
    volume_y: tuple[float, float] = (-1.5, 1.5)
    volume_z: tuple[float, float] = (-2.0, 0.05)
    max_tilt_rad: float = math.radians(35.0)
    handback_tilt_rad: float = math.radians(60.0)
    """Tilt at which a landing is abandoned to the pilot: the controller that is landing
    has lost the attitude (the one that tripped the tilt limit, typically)."""
    vicon_loss_hold_s: float = 0.5
    vicon_loss_land_s: float = 2.0
    link_loss_s: float = 0.3
    preflight_timeout_s: float = 10.0
    takeoff_timeout_s: float = 20.0
    """A take-off that has not reached the trajectory's start in this time lands."""
    min_data_rate_hz: float = 80.0
    min_vicon_rate_hz: float = 8.0
    takeoff_tolerance_m: float = 0.1
    landed_height_m: float = 0.05
    landed_time_s: float = 0.5
    """Landed: below landed_height_m or in ground contact, for this long."""
    contact_lift_fraction: float = 0.6
    """Ground contact: commanded lift below this fraction of the weight ..."""
    contact_accel_tolerance: float = 0.2
    """... while the specific force is within this fraction of g of 1 g."""
    disarm_time_s: float = 0.5
    pilot_grace_s: float = 0.2
    """The X-3D may report 'not applying' briefly (a watchdog blip); longer is the pilot."""
    on_signal: str = "land"


@dataclass(frozen=True, slots=True)
class Observation:
    """What the supervisor sees at one tick. Times in seconds, positions NED [m].

    data_age_s : time since the last DATA frame
    data_rate_hz : measured DATA rate
    vicon_age_s : time since the last accepted Vicon pose (inf if none yet)
    vicon_rate_hz : measured Vicon pose rate
    estimator_ok : estimator initialised and its covariance converged
    estimator_diverged : covariance trace over its limit or non-finite state
    gravity_ok : accelerometer gravity agrees with the Vicon attitude (frame check)
    position : (x, y, z) estimate
    tilt_rad : angle between body z and earth z
    height_above_ground_m : ground z minus z (positive when airborne)
    takeoff_done : the take-off reference has reached its height
    trajectory_done : the trajectory has run its duration
    pilot_enabled : RC serial-enable switch on
    vehicle_applying : STATUS bit0, the X-3D applies our commands
    stop_requests : number of SIGINT/SIGTERM received so far
    lift_fraction : the lift last commanded, as a fraction of the weight (1 in hover)
    specific_force_g : magnitude of the bias-corrected accelerometer reading [g]
        (1 at rest or in hover). Little lift while still feeling 1 g means the floor
        holds the vehicle up: a vehicle in the air with that little lift would be
        falling and feel less. This landing check does not use the height
        estimate, which drifts when a landing is flown without Vicon.
    """

    t: float
    data_age_s: float
    data_rate_hz: float
    vicon_age_s: float
    vicon_rate_hz: float
    estimator_ok: bool
    estimator_diverged: bool
    gravity_ok: bool
    position: tuple[float, float, float]
    tilt_rad: float
    height_above_ground_m: float
    takeoff_done: bool
    trajectory_done: bool
    pilot_enabled: bool
    vehicle_applying: bool
    stop_requests: int = 0
    lift_fraction: float = 1.0
    specific_force_g: float = 1.0


@dataclass(frozen=True, slots=True)
class Transition:
    """One state change: when, from, to and why."""

    t: float
    old: State
    new: State
    reason: str


@dataclass
class Supervisor:
    """The state machine. Call :meth:`update` once per tick."""

    limits: SupervisorLimits = field(default_factory=SupervisorLimits)
    state: State = State.PREFLIGHT
    transitions: list[Transition] = field(default_factory=list)
    _t_start: float | None = None
    _t_state: float = 0.0
    _held: State = State.TRACK
    _landed_since: float | None = None
    _not_applying_since: float | None = None
    _handled_stops: int = 0
    preflight_failures: list[str] = field(default_factory=list)

    @property
    def terminal(self) -> bool:
        """True once the flight is over (the pilot has the vehicle)."""
        return self.state in TERMINAL

    @property
    def commanding(self) -> bool:
        """True while the ground station should send its ctrl mask (not mask 0)."""
        return self.state in FLYING

    @property
    def success(self) -> bool:
        """A terminal state that counts as a normal end (exit code 0)."""
        if self.state is State.DONE:
            return True
        return self.state is State.HANDBACK and self.transitions[-1].reason.startswith("stop")

    def time_in_state(self, t: float) -> float:
        """Seconds since the last transition."""
        return t - self._t_state

    def _go(self, t: float, new: State, reason: str, *, failsafe: bool = False) -> State:
        """Change state; a failsafe (and every state that takes the plan away) is logged
        as a warning."""
        old = self.state
        self.transitions.append(Transition(t, old, new, reason))
        self.state = new
        self._t_state = t
        level = "warning" if failsafe or new in (State.HOLD, State.HANDBACK, State.PILOT,
                                                 State.LINK_LOST, State.ABORTED) else "info"
        getattr(log, level)("supervisor", old=old.name, new=new.name, reason=reason, t=round(t, 3),
                            failsafe=failsafe)
        return new

    def update(self, obs: Observation) -> State:
        """Advance the state machine by one observation; return the new state."""
        if self._t_start is None:
            self._t_start = obs.t
            self._t_state = obs.t
        if self.terminal:
            return self.state
        reason = self._global_failsafe(obs)
        if reason is not None:
            return self._go(obs.t, *reason)
        handler = _HANDLERS[self.state]
        return handler(self, obs)

    # ------------------------------------------------------------------ failsafes
    def _global_failsafe(self, obs: Observation) -> tuple[State, str] | None:
        lim = self.limits
        if obs.data_age_s > lim.link_loss_s and self.state is not State.PREFLIGHT:
            return State.LINK_LOST, f"no DATA for {obs.data_age_s:.2f} s"
        if not obs.pilot_enabled:
            return State.PILOT, "pilot switched serial control off"
        if self.commanding and not obs.vehicle_applying:
            if self._not_applying_since is None:
                self._not_applying_since = obs.t
            elif obs.t - self._not_applying_since > lim.pilot_grace_s:
                return State.PILOT, "X-3D stopped applying ground-station commands"
        else:
            self._not_applying_since = None
        if obs.estimator_diverged and self.state is not State.PREFLIGHT:
            return State.HANDBACK, "estimator diverged"
        if obs.stop_requests > self._handled_stops:
            self._handled_stops = obs.stop_requests
            if obs.stop_requests >= 2:
                return State.HANDBACK, "stop requested twice: immediate handback"
            if self.state not in AIRBORNE:
                return (State.DONE, "stop requested on the ground") if self.state is \
                    State.DISARM else (State.HANDBACK, "stop requested before take-off")
            if self.limits.on_signal == "handback":
                return State.HANDBACK, "stop requested: handback configured"
            if self.state is not State.LAND:
                return State.LAND, "stop requested: landing"
        return None

    def _airborne_failsafe(self, obs: Observation) -> tuple[State, str] | None:
        lim = self.limits
        x, y, z = obs.position
        outside = not (lim.volume_x[0] <= x <= lim.volume_x[1]
                       and lim.volume_y[0] <= y <= lim.volume_y[1]
                       and lim.volume_z[0] <= z <= lim.volume_z[1])
        if outside and self.state is not State.LAND:
            return State.LAND, f"left the volume at ({x:.2f}, {y:.2f}, {z:.2f})"
        if obs.tilt_rad > lim.max_tilt_rad and self.state is not State.LAND:
            return State.LAND, f"tilt {math.degrees(obs.tilt_rad):.0f} deg over the limit"
        if obs.vicon_age_s > lim.vicon_loss_land_s and self.state is not State.LAND:
            return State.LAND, f"Vicon lost for {obs.vicon_age_s:.2f} s"
        if obs.vicon_age_s > lim.vicon_loss_hold_s and self.state in (State.TAKEOFF, State.TRACK):
            self._held = self.state
            return State.HOLD, f"Vicon lost for {obs.vicon_age_s:.2f} s: holding on IMU"
        return None

    # ------------------------------------------------------------------ per state
    def _preflight(self, obs: Observation) -> State:
        lim = self.limits
        failures = []
        if obs.data_age_s > lim.link_loss_s:
            failures.append("no DATA from the X-3D (check serial.port and the radio)")
        elif obs.data_rate_hz < lim.min_data_rate_hz:
            failures.append(f"DATA at {obs.data_rate_hz:.0f} Hz < {lim.min_data_rate_hz:.0f} Hz")
        if obs.vicon_rate_hz < lim.min_vicon_rate_hz or obs.vicon_age_s > lim.vicon_loss_hold_s:
            failures.append(f"Vicon at {obs.vicon_rate_hz:.0f} Hz")
        if not obs.estimator_ok:
            failures.append("estimator not converged")
        if not obs.gravity_ok:
            failures.append("accelerometer gravity disagrees with the Vicon attitude "
                            "(check vicon.world_to_ned / body_to_object)")
        self.preflight_failures = failures
        if not failures:
            return self._go(obs.t, State.TAKEOFF, "preflight checks passed")
        if obs.t - self._t_state > lim.preflight_timeout_s:
            return self._go(obs.t, State.ABORTED, "preflight failed: " + "; ".join(failures))
        return self.state

    def _takeoff(self, obs: Observation) -> State:
        failsafe = self._airborne_failsafe(obs)
        if failsafe is not None:
            return self._go(obs.t, *failsafe, failsafe=True)
        if obs.takeoff_done:
            return self._go(obs.t, State.TRACK, "take-off height reached")
        timeout = self.limits.takeoff_timeout_s
        if obs.t - self._t_state > timeout:
            x, y, z = obs.position
            return self._go(obs.t, State.LAND, f"take-off timeout: the trajectory's start not "
                            f"reached in {timeout:.1f} s (at ({x:.2f}, {y:.2f}, {z:.2f}))",
                            failsafe=True)
        return self.state

    def _track(self, obs: Observation) -> State:
        failsafe = self._airborne_failsafe(obs)
        if failsafe is not None:
            return self._go(obs.t, *failsafe, failsafe=True)
        if obs.trajectory_done:
            return self._go(obs.t, State.LAND, "trajectory complete")
        return self.state

    def _hold(self, obs: Observation) -> State:
        failsafe = self._airborne_failsafe(obs)
        if failsafe is not None:
            return self._go(obs.t, *failsafe, failsafe=True)
        if obs.vicon_age_s <= self.limits.vicon_loss_hold_s:
            return self._go(obs.t, self._held, "Vicon back")
        return self.state

    def _land(self, obs: Observation) -> State:
        if obs.tilt_rad > self.limits.handback_tilt_rad:
            return self._go(obs.t, State.HANDBACK, f"landing failed: tilt "
                            f"{math.degrees(obs.tilt_rad):.0f} deg, the pilot takes over")
        failsafe = self._airborne_failsafe(obs)
        if failsafe is not None:
            return self._go(obs.t, *failsafe, failsafe=True)
        lim = self.limits
        contact = (obs.lift_fraction < lim.contact_lift_fraction
                   and abs(obs.specific_force_g - 1.0) < lim.contact_accel_tolerance)
        if obs.height_above_ground_m < lim.landed_height_m or contact:
            if self._landed_since is None:
                self._landed_since = obs.t
            elif obs.t - self._landed_since >= self.limits.landed_time_s:
                if obs.height_above_ground_m < self.limits.landed_height_m:
                    return self._go(obs.t, State.DISARM, "on the floor")
                return self._go(obs.t, State.DISARM, "on the floor: ground contact felt at "
                                f"estimated height {obs.height_above_ground_m:.2f} m")
        else:
            self._landed_since = None
        return self.state

    def _disarm(self, obs: Observation) -> State:
        if obs.t - self._t_state >= self.limits.disarm_time_s:
            return self._go(obs.t, State.DONE, "landed and disarmed: vehicle handed back")
        return self.state


_HANDLERS = {
    State.PREFLIGHT: Supervisor._preflight,
    State.TAKEOFF: Supervisor._takeoff,
    State.TRACK: Supervisor._track,
    State.HOLD: Supervisor._hold,
    State.LAND: Supervisor._land,
    State.DISARM: Supervisor._disarm,
}
