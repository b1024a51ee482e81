"""The flight core: one tick in, one COMMAND out. No threads, sockets or clocks.

The same :class:`FlightCore` runs inside the real-time daemon
(:mod:`groundstation.app.daemon`) and in-process against the virtual lab's
simulated clock (:mod:`groundstation.app.inprocess`), so what is tested fast
is what flies.

Per tick (one DATA sample, 100 Hz):

1. estimator: initialise from the first Vicon fix and a few IMU samples, then
   fuse every Vicon pose at its own time stamp; the filter runs one IMU sample
   behind and the estimate handed on is predicted to the newest sample (see
   :meth:`FlightCore.estimate_step`);
2. supervisor: observe link, Vicon, estimator, pilot and position; change state. The
   supervisor sees the truth beside the estimate: the newest Vicon pose and sightings
   outside the volume (the geofence acts on either), rival pose streams, and when the
   estimator had to be re-anchored on poses it could not explain (it was wrong);
3. mission: the reference for the current phase; while tracking, a reference beyond
   what the feasibility check allows (:mod:`groundstation.control.envelope`) is a
   fault: its acceleration and jerk are not fed forward and the supervisor lands;
4. when a COMMAND is due (at the configured command rate, and at once on a
   change between commanding and not commanding): controller (with the mission's
   preview of the reference when it asks for one) -> body rates and F_z -> stick
   units -> channel handover -> CommandMsg; the controller is told what went out
   (ctrl mask 0 whenever the supervisor is not commanding). The controllers are
   designed at the command period, so they step once per COMMAND; between
   COMMANDs the last one stands.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from groundstation.asctec.channels import ChannelHandover
from groundstation.asctec.messages import ALL_CHANNELS_MASK, CommandMsg
from groundstation.control.base import Controller, heading_of
from groundstation.control.envelope import ReferenceEnvelope
from groundstation.control.factory import make_controller
from groundstation.control.sticks import StickParams, to_sticks
from groundstation.control.trajectory import Trajectory
from groundstation.estimation.base import Estimator
from groundstation.estimation.ekf import Ekf
from groundstation.estimation.records import InitReport
from groundstation.flight.commander import Commander
from groundstation.flight.inputs import InputHealth, VehicleStatus
from groundstation.flight.mission import Mission
from groundstation.flight.params import FlightParams
from groundstation.flight.prepare import trajectory_for_flight
from groundstation.flight.supervisor import Observation, State, Supervisor
from groundstation.flight.touchdown import TouchdownProbe
from groundstation.model import inputs_from_sticks
from groundstation.types import (
    Channel,
    ControlOutput,
    ImuSample,
    Pose,
    Reference,
    StateEstimate,
    Sticks,
)

INIT_IMU_SAMPLES = 20
"""IMU samples (0.2 s at 100 Hz) averaged with the first Vicon fix to initialise."""


@dataclass(frozen=True, slots=True)
class TickResult:
    """One tick's outcome.

    command : the COMMAND to send (always valid; mask 0 when not commanding)
    due : send it now (command-rate decimation)
    state : supervisor state after this tick
    reference : the reference tracked this tick
    estimate : the estimate (None until the estimator is initialised)
    sticks : the controller's sticks before handover (None when not commanding)
    preview : the look-ahead reference the controller stepped with this tick (None when
        it did not step or asked for none)
    automatic : the controller was told the COMMAND it stepped for went out with every
        channel under its own control, no handover blend (see ``Controller.sent``)
    vicon_nis : the estimator's normalised innovation squared of the last pose it judged
        this tick (NaN: it judged none); vicon_refused : poses it refused this tick
    """

    command: CommandMsg
    due: bool
    state: State
    reference: Reference
    estimate: StateEstimate | None
    sticks: Sticks | None
    preview: Reference | None = None
    automatic: bool = False
    vicon_nis: float = math.nan
    vicon_refused: int = 0


class FlightCore:
    """Estimator, supervisor, mission, controller and handover for one flight.

    params : the flight's parameters (:func:`groundstation.flight.assembly.assemble`)
    controller, trajectory, estimator : replace the ones the parameters name
        (tests and the evaluation inject their own)
    duration_s : trajectory time flown before landing (default: see
        :func:`~groundstation.flight.prepare.trajectory_for_flight`, which also shapes
        and checks the trajectory: TrajectoryError if it cannot be flown)
    """

    def __init__(self, params: FlightParams, *, controller: Controller | None = None,
                 trajectory: Trajectory | None = None, estimator: Estimator | None = None,
                 duration_s: float | None = None) -> None:
        self.params = params
        quad = params.vehicle
        self.ekf: Estimator = estimator or Ekf(params.ekf)
        self.controller = controller or make_controller(params.controller, quad,
                                                        params.command_period_s)
        # built from the parameters unless given, shaped, and refused (TrajectoryError)
        # unless it is feasible and inside the volume
        self.trajectory, duration = trajectory_for_flight(params, trajectory, duration_s)
        self.mission = Mission.from_params(self.trajectory, duration, params.mission)
        self.commander = self.trajectory if isinstance(self.trajectory, Commander) else None
        """The run-time commands' trajectory (``trajectory.name: none``), else None."""
        self.supervisor = Supervisor(params.supervisor)
        self.handover = ChannelHandover(blend_time=params.handover_blend_s)
        self._auto = params.channels
        self._quad = quad
        self._stick_params = StickParams.from_quadrotor(quad)
        self._sticks: Sticks | None = None  # the controller's sticks of the last COMMAND
        self._command = CommandMsg.release()
        self._preview: Reference | None = None
        self._automatic = False
        self._weight = quad.mass * quad.g  # [N]
        self._lift_fraction = 1.0  # last commanded lift / weight, for the landing check
        self._touchdown = TouchdownProbe(params.supervisor.contact_accel_tolerance)
        self._lift_cap: float | None = None  # the probe's cap on the lift / weight
        self._command_period = params.command_period_s
        self._next_command = -math.inf
        self._was_commanding = False
        self._imu_buffer: deque[ImuSample] = deque(maxlen=INIT_IMU_SAMPLES)
        self._t_init: float | None = None
        self.init_report: InitReport | None = None
        self._settle_s = params.settle_time_s
        self._last_pose: Pose | None = None
        self._standing_pose: Pose | None = None  # the newest pose before take-off
        self._exact_sender = False  # repeated the standing vehicle's pose exactly
        self._floor_z = math.nan  # height of the standing vehicle's pose [m], NED
        self._held: ImuSample | None = None
        self._estimate: StateEstimate | None = None
        self._judged = self._refused = 0  # the estimator's pose counts at the last tick
        self._overruled = 0  # the estimator's re-anchorings on unexplained poses, so far
        self._land_request = ""
        self._envelope = ReferenceEnvelope.from_limits(params.limits)
        self._reference_fault = ""  # found on the last tick's reference, for this one

    # ------------------------------------------------------------------ public
    @property
    def state(self) -> State:
        """The supervisor's state."""
        return self.supervisor.state

    @property
    def auto_channels(self) -> tuple[Channel, ...]:
        """The channels the ground station controls while it commands the vehicle."""
        return self._auto

    @property
    def last_estimate(self) -> StateEstimate | None:
        """The estimate of the last tick (None before the estimator runs)."""
        return self._estimate

    @property
    def land_request_reason(self) -> str:
        """Why the flight is to land at once ("" when it is not): a client asked, or the
        commanded flight was idle too long."""
        return self._land_request

    def request_land(self, reason: str) -> None:
        """Land as soon as the supervisor can (from TAKEOFF or TRACK; a nominal end)."""
        self._land_request = self._land_request or reason

    def set_auto_channels(self, channels: Sequence[Channel]) -> None:
        """Change at run time which channels the ground station controls (bumpless:
        a channel taken from the pilot blends in from the pilot's stick)."""
        self._auto = tuple(channels)
        if self.supervisor.commanding:
            self.handover.set_auto(self._auto)

    def tick(self, t: float, imu: ImuSample | None, poses: Sequence[Pose],
             vehicle: VehicleStatus, health: InputHealth, stop_requests: int = 0) -> TickResult:
        """Advance the flight by one tick at monotonic time ``t`` [s]."""
        old = self.supervisor.state
        self._estimate = self.estimate_step(imu, poses, still=self.standing(old, poses))
        obs = self._observe(t, vehicle, health, stop_requests)
        state = self.supervisor.update(obs)
        lim = self.supervisor.limits
        self._lift_cap = self._touchdown.update(
            t, state is State.LAND and obs.vicon_age_s > lim.vicon_loss_hold_s,
            obs.height_above_ground_m < lim.landed_height_m, obs.specific_force_g,
            self._lift_fraction)
        position = self._position()
        if state is not old:
            self._enter(state, old, t, position)
        reference = self.mission.reference(t)
        if state is State.TRACK:
            reference = self._guard(reference)
        if self.commander is not None:
            if old is State.TRACK and state is not State.TRACK:
                self.commander.preempt(self.mission.trajectory_time,
                                       f"{state.name}: {self.supervisor.transitions[-1].reason}")
            idle = self.commander.update(t, self.mission.trajectory_time,
                                         state is State.TRACK, position)
            if idle:
                self.request_land(idle)
        commanding = self.supervisor.commanding
        due = t >= self._next_command or commanding != self._was_commanding
        if due:
            self._next_command = max(self._next_command + self._command_period, t)
            if self._next_command <= t:
                self._next_command = t + self._command_period
        self._was_commanding = commanding
        self._preview = None
        self._automatic = False
        if not (commanding and self._estimate is not None):
            self._sticks = None
            self._command = CommandMsg.release()
        elif due or self._sticks is None:
            # The controllers are designed at the command period: one step per COMMAND.
            self._sticks = self._control(t, state, self._estimate, reference)
            self._command = self.handover.compose(t, self._sticks, vehicle.pilot)
            if state is not State.DISARM:
                self._report_sent(self._command, t)
        return TickResult(self._command, due, state, reference, self._estimate, self._sticks,
                          self._preview, self._automatic, *self._verdicts())

    def abort(self, t: float, state: State, reason: str) -> TickResult:
        """End the flight at ``t`` from outside the tick (the serial link failed: state
        LINK_LOST; an internal error: ABORTED): a failsafe transition to the terminal
        ``state``. The result carries ctrl mask 0 and is not due: whoever owns the link
        sends the final mask-0 COMMAND if it still can."""
        self.supervisor.force(t, state, reason)
        self._was_commanding = False
        self._sticks = None
        self._preview = None
        self._automatic = False
        self._command = CommandMsg.release()
        return TickResult(self._command, False, self.supervisor.state, self.mission.reference(t),
                          self._estimate, None)

    def standing(self, state: State, poses: Sequence[Pose]) -> bool:
        """Whether ``poses`` (this tick's, in ``state``) show the vehicle standing on the
        floor, so that one repeating the previous pose exactly is fused as a still
        vehicle's (:meth:`Ekf.update <groundstation.estimation.ekf.Ekf.update>`); public
        for replay.

        Before take-off (PREFLIGHT) always: the vehicle stands still there whatever
        sends its poses. Later only for a sender seen to repeat the standing vehicle's
        pose exactly before take-off (one without noise: a simulator's; Vicon's noise
        never repeats a pose) and only for poses at the floor's height then (within
        ``landed_height_m``): the vehicle on the floor in take-off before it lifts off,
        or landed. A pose repeated in the air is skipped, so a stream frozen there reads
        as a Vicon loss.
        """
        if state is State.PREFLIGHT:
            for pose in poses:
                last, self._standing_pose = self._standing_pose, pose
                if (last is not None and pose.position.tolist() == last.position.tolist()
                        and pose.quaternion.tolist() == last.quaternion.tolist()):
                    self._exact_sender = True
            if self._standing_pose is not None:
                self._floor_z = float(self._standing_pose.position[2])
            return True
        tolerance = self.supervisor.limits.landed_height_m
        return self._exact_sender and all(abs(float(p.position[2]) - self._floor_z) < tolerance
                                          for p in poses)

    # ------------------------------------------------------------------ steps
    def estimate_step(self, imu: ImuSample | None, poses: Sequence[Pose], *,
                      still: bool = False) -> StateEstimate | None:
        """The estimator part of a tick (initialise, fuse poses, predict); public for replay.
        ``still``: the poses show the vehicle standing on the floor (:meth:`standing`).

        The filter runs one IMU sample behind: this tick's sample is held, the filter
        advances to the previous one, and the estimate returned is the filter state
        predicted to this sample with the nominal model (:meth:`Ekf.estimate_ahead`).
        A Vicon pose is stamped a few ms before it arrives, so with the filter at the
        newest sample nearly every pose would be older than the filter time and cost
        a checkpoint restore and re-propagation (measured: every pose in a real-time
        flight); one sample behind, it is newer and is fused in order inside the next
        prediction. The estimate carries the same information either way, except a
        pose stamped after the previous sample waits one tick.
        """
        if poses:
            self._last_pose = poses[-1]
        if self.init_report is None:
            if imu is not None:
                self._imu_buffer.append(imu)
            if self._last_pose is not None and len(self._imu_buffer) == INIT_IMU_SAMPLES:
                self.init_report = self.ekf.initialise(self._last_pose, list(self._imu_buffer))
                self._t_init = self._last_pose.t
            return None
        # Poses first: one newer than the filter time is deferred and fused inside the
        # prediction step at its own time stamp; fusing it after the prediction would
        # make the EKF restore a checkpoint and re-propagate (same result, ~2x cost).
        for pose in poses:
            self.ekf.update(pose, still=still)
        if imu is not None:
            if self._held is not None:
                self.ekf.predict(self._held)
            self._held = imu
        if self._held is None:
            return self.ekf.estimate()
        return self.ekf.estimate_ahead(self._held)

    def _guard(self, reference: Reference) -> Reference:
        """``reference`` if it is inside the envelope; else the fault is kept for the
        supervisor (it lands on the next tick) and the reference's acceleration and jerk
        are not fed forward: a fault is not an input."""
        fault = self._envelope.fault(reference)
        if not fault:
            return reference
        if not self._reference_fault:
            self._reference_fault = f"at trajectory time {self.mission.trajectory_time:.2f} s " \
                f"{fault}"
        zero = np.zeros(3)
        position = reference.position if np.isfinite(reference.position).all() \
            else self._position().copy()
        velocity = reference.velocity if np.isfinite(reference.velocity).all() else zero
        return Reference(t=reference.t, position=position, velocity=velocity,
                         acceleration=zero, jerk=zero, yaw=reference.yaw if math.isfinite(
                             reference.yaw) else 0.0)

    def _overruled_now(self) -> str:
        """Why the estimator was re-anchored on Vicon poses it could not explain since the
        last tick ("" if it was not)."""
        count, reason = self.ekf.overruled
        if count == self._overruled:
            return ""
        self._overruled = count
        return reason

    def _verdicts(self) -> tuple[float, int]:
        """(NIS of the last pose judged this tick or NaN, poses refused this tick) from the
        estimator's running counts (a pose newer than the filter is judged a tick later,
        inside the prediction, so the counts, not the update calls, tell)."""
        judged, refused, nis = self.ekf.verdicts
        new_judged, new_refused = judged - self._judged, refused - self._refused
        self._judged, self._refused = judged, refused
        return (nis if new_judged > 0 else math.nan), new_refused

    def _observe(self, t: float, vehicle: VehicleStatus, health: InputHealth,
                 stop_requests: int) -> Observation:
        est = self._estimate
        diverged = est is not None and self.ekf.diverged
        settled = (self._t_init is not None and est is not None
                   and est.t - self._t_init >= self._settle_s)
        gravity_ok = None if self.init_report is None else bool(self.init_report.gravity_ok)
        position = self._position()
        tilt = 0.0
        if est is not None:
            q = est.quaternion  # body z in earth: third column of R(q); cos tilt = R[2, 2]
            cos_tilt = q[0] * q[0] - q[1] * q[1] - q[2] * q[2] + q[3] * q[3]
            tilt = math.acos(min(max(cos_tilt, -1.0), 1.0))
        airborne = self.supervisor.state not in (State.PREFLIGHT,)
        height = float(self.mission.ground[2] - position[2]) if airborne else 0.0
        force_g = 1.0
        if est is not None and self._held is not None:
            a1, a2, a3 = (self._held.acc - est.acc_bias).tolist()
            force_g = math.sqrt(a1 * a1 + a2 * a2 + a3 * a3) / self._quad.g
        return Observation(
            t=t, data_age_s=health.data_age_s, data_rate_hz=health.data_rate_hz,
            vicon_age_s=self._vicon_age(health), vicon_rate_hz=health.vicon_rate_hz,
            estimator_ok=settled and not diverged, estimator_diverged=diverged,
            gravity_ok=gravity_ok, position=(position[0], position[1], position[2]),
            tilt_rad=tilt, height_above_ground_m=height,
            takeoff_done=self.mission.takeoff_done(t, position),
            trajectory_done=self.mission.trajectory_done(),
            pilot_enabled=vehicle.pilot_enabled, vehicle_applying=vehicle.applying,
            stop_requests=stop_requests, lift_fraction=self._lift_fraction,
            specific_force_g=force_g, battery_v=vehicle.battery_v,
            land_request=self._land_request, vicon_position=self._fresh_vicon(health),
            vicon_outside=health.vicon_outside, vicon_rivals=health.vicon_rivals,
            overruled=self._overruled_now() if self.init_report is not None else "",
            reference_fault=self._reference_fault, vicon_diagnosis=health.vicon_diagnosis,
            peer_distance_m=health.peer_distance_m, peer_name=health.peer_name,
        )

    def _fresh_vicon(self, health: InputHealth) -> tuple[float, float, float] | None:
        """The newest pose the pose filter passed, if Vicon has not been silent longer than
        the loss-hold time (an older one says nothing about where the vehicle is now)."""
        if health.vicon_age_s > self.supervisor.limits.vicon_loss_hold_s:
            return None
        return health.vicon_last

    def _vicon_age(self, health: InputHealth) -> float:
        """Time since the last pose the pose filter passed or, once the estimator runs,
        since the last one it fused, whichever is longer [s]: poses the estimator refuses
        (a sender it cannot believe) are no Vicon to the failsafes."""
        if self.init_report is None:
            return health.vicon_age_s
        return max(health.vicon_age_s, self.ekf.time_since_fix)

    def _position(self) -> np.ndarray:
        if self._estimate is not None:
            return self._estimate.position
        if self._last_pose is not None:
            return self._last_pose.position
        return np.zeros(3)

    def _enter(self, state: State, old: State, t: float, position: np.ndarray) -> None:
        yaw = heading_of(self._estimate.quaternion) if self._estimate is not None else 0.0
        self.mission.enter(state, t, position, yaw)
        if state is State.TAKEOFF and old is State.PREFLIGHT:
            # a fresh start on the floor; a take-off resumed after a HOLD keeps the
            # controller's integrators and input history (the vehicle is in the air)
            self.controller.reset()
            self.handover.set_auto(self._auto)
        elif not self.supervisor.commanding:
            self.handover.set_auto(())

    def _control(self, t: float, state: State, est: StateEstimate,
                 reference: Reference) -> Sticks:
        if state is State.DISARM:
            return Sticks(0, 0, 0, 0)  # motors to idle on the floor before handing back
        lead = self.controller.lead_s
        preview = self.mission.preview(t, lead) if lead > 0.0 else None
        self._preview = preview
        output = self.controller.step(t, est, reference, preview)
        if self._lift_cap is not None:  # a landing on the IMU alone feels for the floor
            least_f_z = (1.0 - self._lift_cap) * self._weight
            if output.f_z < least_f_z:
                output = ControlOutput(omega=output.omega, f_z=least_f_z)
        self._lift_fraction = 1.0 - output.f_z / self._weight  # f_z = F_lift + m g, lift < 0
        sticks, _flags = to_sticks(output, self._stick_params)
        return sticks

    def _report_sent(self, command: CommandMsg, t: float) -> None:
        """Tell the controller what the vehicle was sent, in physical units: the pilot's
        sticks on manual channels, the blend during a handover, the saturation."""
        sticks = Sticks(roll=command.roll, pitch=command.pitch, yaw=command.yaw,
                        thrust=command.thrust)
        u = inputs_from_sticks(sticks, self._quad)
        automatic = (command.ctrl == ALL_CHANNELS_MASK
                     and not self.handover.blending(t))
        self._automatic = automatic
        self.controller.sent(ControlOutput(omega=u[0:3], f_z=float(u[3])), automatic)
