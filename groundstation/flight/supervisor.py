"""The safety supervisor: one state machine that decides who flies and how.

Pure logic, no clock and no I/O: the flight core hands in a :class:`Observation`
each tick and reads back the state. Every transition is recorded with its
time and reason and logged.

States and transitions::

    PREFLIGHT --checks pass--> TAKEOFF --at height--> TRACK --done/stop--> LAND
                                                                          |
    LAND --on the floor--> DISARM (thrust to idle, 0.5 s) --> DONE (hand back)

    airborne (TAKEOFF, TRACK, HOLD, LAND):
      the estimate, the newest Vicon pose or a Vicon sighting outside the volume
                                               -> HANDBACK at once (on_geofence: handback,
                                                  the default) or LAND; an error-level alarm
      a second Vicon pose stream for the object -> LAND (on_second_stream: land) or HOLD
                                                  until it stops
      Vicon poses overruled the estimate (it was wrong and was re-anchored on them)
                                               -> HANDBACK (on_overruled: handback, the
                                                  default) or LAND; while landing, the
                                                  landing goes on re-anchored
      the reference asks more than the feasibility check allowed -> LAND
      a fleet's peer closer than separation_m / 2 -> LAND; closer than separation_m
                                               -> HOLD (TAKEOFF, TRACK)
      HOLD for a peer and the gap open again (1.1 x separation_m) -> the state interrupted
      HOLD for a peer longer than separation_hold_s -> LAND
      Vicon silent > vicon_loss_hold_s         -> HOLD (hold position on the IMU estimate)
      HOLD and Vicon back                      -> the state HOLD interrupted
      HOLD and Vicon silent > vicon_loss_land_s -> LAND
      tilt > max                               -> LAND
      battery below battery_land_v for battery_grace_s -> LAND
      TAKEOFF not done after takeoff_timeout_s -> LAND
      LAND and tilt > handback tilt            -> HANDBACK (the landing lost the attitude)
      LAND: on the floor only with evidence (the estimate at the floor while Vicon is
      fused, or the accelerometer's floor contact near it) -> DISARM; the estimate at
      the floor on dead reckoning alone for landing_confirm_s -> HANDBACK (the pilot
      takes the vehicle with the thrust it had: never thrust 0 in the air)
    any state:
      estimator diverged                       -> HANDBACK (mask 0 at once)
      no DATA for link_loss_s (after PREFLIGHT) -> LINK_LOST (log and stop)
      pilot switch off                         -> PILOT (respected at once)
      X-3D not applying us for pilot_grace_s   -> PILOT; shorter (a watchdog expiry): an event
      second stop request                      -> HANDBACK
      first stop request: airborne -> LAND (or HANDBACK if configured); on the ground -> DONE
    PREFLIGHT longer than preflight_timeout_s  -> ABORTED
    from outside (:meth:`Supervisor.force`): serial link failed -> LINK_LOST, a bug -> ABORTED

Terminal states: DONE, HANDBACK, PILOT, LINK_LOST, ABORTED. In every terminal state
and in PREFLIGHT the ground station sends ctrl mask 0: the pilot has the vehicle.

Every transition a failsafe makes is marked (``Transition.failsafe``) and logged as a
warning, as is every :class:`FailsafeEvent` (the vehicle applied none of our commands
for a while in the air and came back: its watchdog expired). :attr:`Supervisor.outcome`
says how the flight ended; its value is ``gs fly``'s exit code.
"""

from __future__ import annotations

import enum
import math
from collections.abc import Callable
from dataclasses import dataclass, field

import structlog

log = structlog.get_logger(__name__)


class Outcome(enum.IntEnum):
    """How a flight ended; the value is the exit code of ``gs fly``.

    COMPLETED : the mission was flown, the vehicle landed and was handed back, and no
        failsafe acted
    FAILSAFE : a failsafe acted (a failsafe landing or handback, the pilot took over,
        the link was lost, the vehicle's watchdog expired in the air) or the flight was
        aborted (preflight failed, an internal error)
    STOPPED : stopped on request (SIGINT/SIGTERM, a stop event) without a failsafe: landed,
        or handed back at a second request or as ``safety.on_signal`` configures
    """

    COMPLETED = 0
    FAILSAFE = 1
    STOPPED = 4


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
    battery_land_v: float | None = None
    """Land when the reported battery voltage stays below this [V] (None: no check) ..."""
    battery_grace_s: float = 10.0
    """... for this long [s]; below it at preflight refuses the take-off."""
    on_geofence: str = "handback"
    """What leaving the volume does: "handback" (at once) or "land"."""
    on_overruled: str = "handback"
    """What an estimate proven wrong by Vicon does: "handback" or "land" (on it, re-anchored:
    right if the poses are the truth, wrong if they are a forgery that outlived the real
    stream, which is why the pilot gets the vehicle by default)."""
    on_second_stream: str = "land"
    """What a second Vicon pose stream for the object does: "land" or "hold"."""
    landing_confirm_s: float = 5.0
    """A landing whose estimate sits at the floor without evidence for this long (after
    ``landed_time_s``) hands back [s]."""
    separation_m: float | None = None
    """A fleet's least distance to a peer [m] (``fleet.separation_m``; None: alone or off):
    closer, hold; closer than half of it, land."""
    separation_hold_s: float = 3.0
    """A hold for a peer that lasts this long without the gap opening lands [s]."""
    contact_height_m: float = 0.5
    """Floor contact counts only below this estimated height [m] (what dead reckoning may
    drift during a landing without Vicon), and with Vicon fused only below
    ``landed_height_m`` plus 0.15 m: a thrust fault that lifts a vehicle commanded to
    descend reads like contact, anywhere."""


@dataclass(frozen=True, slots=True)
class Observation:
    """What the supervisor sees at one tick. Times in seconds, positions NED [m].

    data_age_s : time since the last DATA frame
    data_rate_hz : measured DATA rate
    vicon_age_s : time since the last accepted Vicon pose (inf if none yet)
    vicon_rate_hz : measured Vicon pose rate
    estimator_ok : estimator initialised and its covariance converged
    estimator_diverged : covariance trace over its limit or non-finite state
    gravity_ok : accelerometer gravity agrees with the Vicon attitude (frame check; None
        before the estimator has started, when nothing could be checked)
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
    battery_v : battery voltage the X-3D reports [V] (NaN: no STATUS block)
    land_request : why to land now ("" for no): a client asked, or the commanded flight
        was idle too long (:mod:`groundstation.flight.commander`); a nominal landing
    vicon_position : NED [m] of the newest pose the pose filter passed, if it is at most
        ``vicon_loss_hold_s`` old (None otherwise): the truth the geofence checks besides
        the estimate, which may be wrong
    vicon_outside : NED [m] of a confirmed Vicon sighting beyond the plausible volume, newer
        than any pose passed (the vehicle left the volume; None if not)
    vicon_rivals : confirmed pose streams of the object besides the one followed, now
    overruled : why the estimate was re-anchored on Vicon poses it could not explain this
        tick ("" if it was not): the estimate was wrong
    reference_fault : why the reference is beyond what the feasibility check allowed ("")
    vicon_diagnosis : what the pose filter saw, for a preflight failure (called only then)
    peer_distance_m, peer_name : a fleet's nearest peer: its distance from the estimate [m]
        and its name (inf: none)
    """

    t: float
    data_age_s: float
    data_rate_hz: float
    vicon_age_s: float
    vicon_rate_hz: float
    estimator_ok: bool
    estimator_diverged: bool
    gravity_ok: bool | None
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
    battery_v: float = math.nan
    land_request: str = ""
    vicon_position: tuple[float, float, float] | None = None
    vicon_outside: tuple[float, float, float] | None = None
    vicon_rivals: int = 0
    overruled: str = ""
    reference_fault: str = ""
    vicon_diagnosis: Callable[[], str] | None = None
    peer_distance_m: float = math.inf
    peer_name: str = ""


@dataclass(frozen=True, slots=True)
class Transition:
    """One state change: when, from, to, why, and what kind of change it is.

    failsafe : a failsafe made it (the flight's outcome is then FAILSAFE)
    nominal : a step every normal flight takes (preflight passed, take-off height
        reached, trajectory complete, on the floor, disarmed); a report shows the
        reason only of the other transitions (failsafes, a stop on request, Vicon back)
    """

    t: float
    old: State
    new: State
    reason: str
    failsafe: bool = False
    nominal: bool = False


@dataclass(frozen=True, slots=True)
class FailsafeEvent:
    """Something a failsafe noticed that did not change the state.

    t : when it began [s]; duration_s : how long it lasted [s]
    kind : "watchdog": the X-3D applied none of our commands while we commanded it (its
        100 ms watchdog expired: no valid COMMAND reached it) and then applied them again
    reason : one line for the log and the summary
    """

    t: float
    kind: str
    duration_s: float
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
    _unconfirmed_since: float | None = None
    _hold_for_rival = False
    _hold_for_peer = False
    _not_applying_since: float | None = None
    _applied: bool = False
    _battery_low_since: float | None = None
    _handled_stops: int = 0
    _stopped: bool = False
    preflight_failures: list[str] = field(default_factory=list)
    events: list[FailsafeEvent] = field(default_factory=list)
    """Failsafe events that did not change the state (see :class:`FailsafeEvent`)."""

    @property
    def terminal(self) -> bool:
        """True once the flight is over (the pilot has the vehicle)."""
        return self.state in TERMINAL

    @property
    def commanding(self) -> bool:
        """True while the ground station should send its ctrl mask (not mask 0)."""
        return self.state in FLYING

    @property
    def outcome(self) -> Outcome:
        """How the flight ended (FAILSAFE while it has not: it did not finish)."""
        if not self.terminal or self.state in (State.PILOT, State.LINK_LOST, State.ABORTED) \
                or self.events or any(tr.failsafe for tr in self.transitions):
            return Outcome.FAILSAFE
        if self._stopped:
            return Outcome.STOPPED
        return Outcome.COMPLETED if self.state is State.DONE else Outcome.FAILSAFE

    @property
    def success(self) -> bool:
        """A normal end: the mission completed, or stopped on request, without a failsafe."""
        return self.outcome is not Outcome.FAILSAFE

    def time_in_state(self, t: float) -> float:
        """Seconds since the last transition."""
        return t - self._t_state

    def _go(self, t: float, new: State, reason: str, *, failsafe: bool = False,
            nominal: bool = False) -> State:
        """Change state; a failsafe (and every state that takes the plan away) is logged
        as a warning. ``nominal``: a step of every normal flight (:class:`Transition`)."""
        old = self.state
        self.transitions.append(Transition(t, old, new, reason, failsafe, nominal))
        self.state = new
        self._t_state = t
        level = "warning" if failsafe or new in (State.HOLD, State.HANDBACK, State.PILOT,
                                                 State.LINK_LOST, State.ABORTED) else "info"
        if failsafe and reason.startswith(GEOFENCE):
            level = "error"  # the loud alarm: the vehicle is beyond where it was trusted
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
        self._watch_battery(obs)
        change = self._global_failsafe(obs)
        if change is not None:
            state, reason, failsafe = change
            return self._go(obs.t, state, reason, failsafe=failsafe)
        handler = _HANDLERS[self.state]
        return handler(self, obs)

    def force(self, t: float, state: State, reason: str) -> State:
        """End the flight from outside the state machine (the serial link failed, an
        internal error): a failsafe transition to the terminal ``state``."""
        if not self.terminal:
            self._go(t, state, reason, failsafe=True)
        return self.state

    # ------------------------------------------------------------------ failsafes
    def _global_failsafe(self, obs: Observation) -> tuple[State, str, bool] | None:
        """(new state, reason, made by a failsafe) or None."""
        lim = self.limits
        if obs.data_age_s > lim.link_loss_s and self.state is not State.PREFLIGHT:
            return State.LINK_LOST, f"no DATA for {obs.data_age_s:.2f} s", True
        if not obs.pilot_enabled:
            return State.PILOT, "pilot switched serial control off", True
        lapse = self._watch_applying(obs)
        if lapse is not None:
            return State.PILOT, f"X-3D stopped applying ground-station commands ({lapse})", True
        if obs.estimator_diverged and self.state is not State.PREFLIGHT:
            return State.HANDBACK, "estimator diverged", True
        if obs.stop_requests > self._handled_stops:
            self._handled_stops = obs.stop_requests
            stop = self._stop(obs.stop_requests)
            if stop is not None:
                self._stopped = True
                return (*stop, False)
        return None

    def _stop(self, requests: int) -> tuple[State, str] | None:
        if requests >= 2:
            return State.HANDBACK, "stop requested twice: immediate handback"
        if self.state not in AIRBORNE:
            return (State.DONE, "stop requested on the ground") if self.state is \
                State.DISARM else (State.HANDBACK, "stop requested before take-off")
        if self.limits.on_signal == "handback":
            return State.HANDBACK, "stop requested: handback configured"
        if self.state is not State.LAND:
            return State.LAND, "stop requested: landing"
        return None

    def _watch_applying(self, obs: Observation) -> str | None:
        """Follow STATUS bit0 while commanding. A lapse longer than ``pilot_grace_s`` is
        the pilot's (returns its description); a shorter one, once the vehicle had applied
        our commands, was its watchdog expiring: a :class:`FailsafeEvent` when it ends."""
        if self.commanding and not obs.vehicle_applying:
            if self._not_applying_since is None:
                self._not_applying_since = obs.t
            elif obs.t - self._not_applying_since > self.limits.pilot_grace_s:
                return f"none applied for {obs.t - self._not_applying_since:.2f} s"
            return None
        since, self._not_applying_since = self._not_applying_since, None
        if not self.commanding:
            return None
        if since is not None and self._applied:
            duration = obs.t - since
            reason = (f"the X-3D applied none of our commands for {1e3 * duration:.0f} ms "
                      "(its watchdog expired: no COMMAND reached it for 100 ms)")
            self.events.append(FailsafeEvent(since, "watchdog", duration, reason))
            log.warning("failsafe event", kind="watchdog", duration_s=round(duration, 3),
                        t=round(since, 3), state=self.state.name, reason=reason, failsafe=True)
        self._applied = True
        return None

    def _watch_battery(self, obs: Observation) -> None:
        """Track how long the battery has been below ``battery_land_v``."""
        limit = self.limits.battery_land_v
        if limit is not None and obs.battery_v < limit:  # NaN (no STATUS) compares False
            if self._battery_low_since is None:
                self._battery_low_since = obs.t
        else:
            self._battery_low_since = None

    def _airborne_failsafe(self, obs: Observation) -> tuple[State, str] | None:
        """The failsafes of every airborne state, most urgent first (LAND takes only the
        ones that would hand back, see :meth:`_land`)."""
        lim = self.limits
        fence = self._geofence(obs)
        if fence is not None and (lim.on_geofence == "handback" or self.state is not State.LAND):
            return (State.HANDBACK if lim.on_geofence == "handback" else State.LAND), fence
        if self.state is State.LAND:
            return None
        if obs.overruled:
            return (State.HANDBACK if lim.on_overruled == "handback" else State.LAND), \
                f"estimate was wrong: {obs.overruled}"
        if obs.reference_fault:
            return State.LAND, f"reference fault: {obs.reference_fault}"
        if obs.vicon_rivals > 0:
            what = (f"a second Vicon pose stream for the object ({obs.vicon_rivals} besides "
                    "the one followed)")
            if lim.on_second_stream == "land":
                return State.LAND, what
            if self.state is not State.HOLD:
                self._held, self._hold_for_rival = self.state, True
                self._hold_for_peer = False
                return State.HOLD, f"{what}: holding"
        peer = self._separation(obs)
        if peer is not None:
            return peer
        if obs.tilt_rad > lim.max_tilt_rad:
            return State.LAND, f"tilt {math.degrees(obs.tilt_rad):.0f} deg over the limit"
        low = self._battery_low_since
        if low is not None and obs.t - low >= lim.battery_grace_s:
            return State.LAND, (f"battery {obs.battery_v:.2f} V below {lim.battery_land_v:.2f} V "
                                f"for {obs.t - low:.1f} s")
        if obs.vicon_age_s > lim.vicon_loss_land_s:
            return State.LAND, f"Vicon lost for {obs.vicon_age_s:.2f} s"
        if obs.vicon_age_s > lim.vicon_loss_hold_s and self.state in (State.TAKEOFF, State.TRACK):
            self._held, self._hold_for_rival = self.state, False
            self._hold_for_peer = False
            return State.HOLD, f"Vicon lost for {obs.vicon_age_s:.2f} s: holding on IMU"
        return None

    def _separation(self, obs: Observation) -> tuple[State, str] | None:
        """A fleet's peer too close (groundstation/fleet): closer than half the separation,
        land; closer than it, hold (from TAKEOFF or TRACK). None otherwise."""
        sep = self.limits.separation_m
        if sep is None or not obs.peer_distance_m < sep:
            return None
        what = f"{obs.peer_name} {obs.peer_distance_m:.2f} m away"
        if obs.peer_distance_m < 0.5 * sep:
            return State.LAND, (f"too close to a peer: {what}, less than half the "
                                f"separation ({sep:.2f} m)")
        if self.state in (State.TAKEOFF, State.TRACK):
            self._held, self._hold_for_rival, self._hold_for_peer = self.state, False, True
            return State.HOLD, f"too close to a peer: {what} (separation {sep:.2f} m): holding"
        return None

    def _geofence(self, obs: Observation) -> str | None:
        """Why the vehicle is outside the volume (None if it is not): the estimate there, or
        the truth there (the newest Vicon pose, or a Vicon sighting beyond the plausible
        volume) whatever the estimate says: an estimate can be wrong. The floor is no
        fence: nothing flies through it, so a point below it is an estimate (or a Vicon
        origin) that is off, which the other failsafes and the landing handle."""
        if obs.vicon_outside is not None and not self._inside(obs.vicon_outside, floor=False):
            return f"{GEOFENCE}: Vicon sees the vehicle at {_point(obs.vicon_outside)}"
        for what, where in (("Vicon", obs.vicon_position), ("estimate", obs.position)):
            if where is not None and not self._inside(where, floor=False):
                return f"{GEOFENCE} at {_point(where)} ({what})"
        return None

    def _inside(self, point: tuple[float, float, float], *, floor: bool = True) -> bool:
        """``point`` (NED [m]) is inside the volume; with ``floor=False`` below it counts too."""
        lim = self.limits
        x, y, z = point
        return (lim.volume_x[0] <= x <= lim.volume_x[1] and lim.volume_y[0] <= y <= lim.volume_y[1]
                and lim.volume_z[0] <= z and (z <= lim.volume_z[1] or not floor))

    # ------------------------------------------------------------------ per state
    def _preflight(self, obs: Observation) -> State:
        lim = self.limits
        failures = []
        if obs.data_age_s > lim.link_loss_s:
            failures.append("no DATA from the X-3D (check serial.port and the radio)")
        elif obs.data_rate_hz < lim.min_data_rate_hz:
            failures.append(f"DATA at {obs.data_rate_hz:.0f} Hz < {lim.min_data_rate_hz:.0f} Hz")
        if obs.vicon_rate_hz < lim.min_vicon_rate_hz or obs.vicon_age_s > lim.vicon_loss_hold_s:
            failures.append(f"Vicon at {obs.vicon_rate_hz:.0f} Hz (at least "
                            f"{lim.min_vicon_rate_hz:.0f} needed)")
        if not obs.estimator_ok:
            failures.append("estimator not converged")
        if obs.gravity_ok is False:
            failures.append("accelerometer gravity disagrees with the Vicon attitude "
                            "(check vicon.world_to_ned / body_to_object)")
        if not self._inside(obs.position):
            failures.append(f"the vehicle is at {_point(obs.position)}, outside the volume "
                            "(safety.volume_x/y/z)")
        if obs.vicon_rivals > 0:
            failures.append("a second Vicon pose stream for the object")
        if lim.battery_land_v is not None and obs.battery_v < lim.battery_land_v:
            failures.append(f"battery {obs.battery_v:.2f} V < {lim.battery_land_v:.2f} V")
        self.preflight_failures = failures
        if not failures:
            return self._go(obs.t, State.TAKEOFF, "preflight checks passed", nominal=True)
        if obs.t - self._t_state > lim.preflight_timeout_s:
            if obs.vicon_diagnosis is not None and any(f.startswith("Vicon") for f in failures):
                failures.append(f"Vicon: {obs.vicon_diagnosis()}")
            return self._go(obs.t, State.ABORTED, "preflight failed: " + "; ".join(failures))
        return self.state

    def _takeoff(self, obs: Observation) -> State:
        failsafe = self._airborne_failsafe(obs)
        if failsafe is not None:
            return self._go(obs.t, *failsafe, failsafe=True)
        if obs.land_request:
            return self._go(obs.t, State.LAND, obs.land_request, nominal=True)
        if obs.takeoff_done:
            return self._go(obs.t, State.TRACK, "take-off height reached", nominal=True)
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
        if obs.land_request:
            return self._go(obs.t, State.LAND, obs.land_request, nominal=True)
        if obs.trajectory_done:
            return self._go(obs.t, State.LAND, "trajectory complete", nominal=True)
        return self.state

    def _hold(self, obs: Observation) -> State:
        failsafe = self._airborne_failsafe(obs)
        if failsafe is not None:
            return self._go(obs.t, *failsafe, failsafe=True)
        lim = self.limits
        if self._hold_for_peer:
            sep = lim.separation_m if lim.separation_m is not None else 0.0
            fixed = obs.vicon_age_s <= lim.vicon_loss_hold_s
            if obs.peer_distance_m >= PEER_RESUME * sep and fixed:
                self._hold_for_peer = False
                return self._go(obs.t, self._held, "the gap to the peers is open again")
            if obs.t - self._t_state > lim.separation_hold_s:
                return self._go(obs.t, State.LAND, f"held beside a peer for "
                                f"{obs.t - self._t_state:.1f} s ({obs.peer_name} "
                                f"{obs.peer_distance_m:.2f} m away)", failsafe=True)
            return self.state
        if self._hold_for_rival:
            if obs.vicon_rivals == 0 and obs.vicon_age_s <= lim.vicon_loss_hold_s:
                return self._go(obs.t, self._held, "the second Vicon stream stopped")
            if obs.t - self._t_state > lim.vicon_loss_land_s:
                return self._go(obs.t, State.LAND, "a second Vicon pose stream for the object "
                                f"for {obs.t - self._t_state:.1f} s", failsafe=True)
            return self.state
        if obs.vicon_age_s <= lim.vicon_loss_hold_s:
            return self._go(obs.t, self._held, "Vicon back")
        return self.state

    def _land(self, obs: Observation) -> State:
        lim = self.limits
        if obs.tilt_rad > lim.handback_tilt_rad:
            return self._go(obs.t, State.HANDBACK, f"landing failed: tilt "
                            f"{math.degrees(obs.tilt_rad):.0f} deg, the pilot takes over",
                            failsafe=True)
        failsafe = self._airborne_failsafe(obs)
        if failsafe is not None:
            return self._go(obs.t, *failsafe, failsafe=True)
        height = obs.height_above_ground_m
        fixed = obs.vicon_age_s <= lim.vicon_loss_hold_s  # the estimate is Vicon's
        contact = (obs.lift_fraction < lim.contact_lift_fraction
                   and abs(obs.specific_force_g - 1.0) < lim.contact_accel_tolerance
                   and height < (lim.landed_height_m + 0.15 if fixed else lim.contact_height_m))
        low = height < lim.landed_height_m
        if (low and fixed) or contact:
            self._unconfirmed_since = None
            if self._landed_since is None:
                self._landed_since = obs.t
            elif obs.t - self._landed_since >= lim.landed_time_s:
                if low and fixed:
                    return self._go(obs.t, State.DISARM, "on the floor", nominal=True)
                return self._go(obs.t, State.DISARM, "on the floor: ground contact felt at "
                                f"estimated height {height:.2f} m", nominal=True)
            return self.state
        self._landed_since = None
        if not low:
            self._unconfirmed_since = None
        elif self._unconfirmed_since is None:
            self._unconfirmed_since = obs.t
        elif obs.t - self._unconfirmed_since >= lim.landed_time_s + lim.landing_confirm_s:
            return self._go(obs.t, State.HANDBACK, "landing not confirmed: the estimate reached "
                            f"the floor on the IMU alone (no Vicon for {obs.vicon_age_s:.1f} s) "
                            "and no floor contact was felt; handed back with the thrust it had",
                            failsafe=True)
        return self.state

    def _disarm(self, obs: Observation) -> State:
        if obs.t - self._t_state >= self.limits.disarm_time_s:
            return self._go(obs.t, State.DONE, "landed and disarmed: vehicle handed back",
                            nominal=True)
        return self.state


PEER_RESUME = 1.1
"""A hold for a peer ends once the gap is this many separations again (hysteresis)."""

GEOFENCE = "left the volume"
"""How every geofence reason starts (the supervisor logs those as errors)."""


def _point(p: tuple[float, float, float]) -> str:
    return f"({p[0]:.2f}, {p[1]:.2f}, {p[2]:.2f})"


_HANDLERS = {
    State.PREFLIGHT: Supervisor._preflight,
    State.TAKEOFF: Supervisor._takeoff,
    State.TRACK: Supervisor._track,
    State.HOLD: Supervisor._hold,
    State.LAND: Supervisor._land,
    State.DISARM: Supervisor._disarm,
}
