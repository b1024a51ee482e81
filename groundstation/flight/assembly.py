"""The assembly: the configuration becomes the flight's parameter records, here and only
here.

Each package keeps its parameters in plain records (as PX4's ekf2 keeps ``struct
parameters``): the serial link's :class:`~groundstation.asctec.params.LinkParams`, the
estimator's :class:`~groundstation.estimation.records.EkfParams`, a controller's record
in :mod:`groundstation.control.params`, the supervisor's
:class:`~groundstation.flight.supervisor.SupervisorLimits`... None of them knows the
configuration. Each function below maps one section (or the few it combines) onto one
record, a line per field; :func:`assemble` calls each once and returns the frozen
:class:`~groundstation.flight.params.FlightParams` the flight core, the real-time daemon
and the in-process runner take. So a parameter's way from the YAML file to its use is
one hop: its key, its line here, the record field it becomes. A fleet's records are
mapped here too: a vehicle's ``fleet:`` section (:func:`fleet_params`, in the bundle) and
the relay of a fleet file (:func:`relay_params`).

:func:`check_config` runs the checks the configuration layer cannot make alone (it
knows no module that uses it): the files the configuration names, the CURVE key files,
and the virtual lab's ``sim:`` section, which the installed lab validates.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from pydantic import BaseModel, ValidationError

from groundstation.asctec.blocks import sensor_mask
from groundstation.asctec.dialect import wire_time_s
from groundstation.asctec.params import LinkParams, LlParams
from groundstation.config import (
    ApiConfig,
    ControllerConfig,
    ExternalForceConfig,
    FleetConfig,
    GroundStationConfig,
    HinfConfig,
    LoggingConfig,
    Problem,
    RealtimeConfig,
    SafetyConfig,
    SerialConfig,
    TelemetryConfig,
    TrajectoryConfig,
    VehicleConfig,
    ViconConfig,
    ZenohConfig,
    dump_config,
    file_problems,
    raise_problems,
    validation_problems,
)
from groundstation.config.fleetfile import FleetFile
from groundstation.control.feasibility import FlightLimits, LimitNames, Volume
from groundstation.control.hinf import default_gain_path
from groundstation.control.hinf_design import HinfDesign, HinfWeights
from groundstation.control.params import (
    ControllerParams,
    ExternalForceParams,
    HinfParams,
    LqrFfParams,
    LqrParams,
    PidParams,
)
from groundstation.control.trajectories import TrajectorySpec
from groundstation.errors import ConfigError
from groundstation.estimation.records import EkfParams
from groundstation.flight.commander import DEFAULT_MOVE_ACCEL_M_S2, CommanderParams, MotionLimits
from groundstation.flight.mission import MissionParams
from groundstation.flight.params import (
    DaemonParams,
    FleetParams,
    FlightParams,
    RelayParams,
    ZenohParams,
)
from groundstation.flight.planner import PlannerSettings
from groundstation.flight.supervisor import SupervisorLimits
from groundstation.model.quadrotor import QuadrotorParams
from groundstation.model.sensors import AxisScaling, ImuScaling
from groundstation.telemetry.publisher import PublisherParams
from groundstation.telemetry.requests import RequestServerParams
from groundstation.vicon.frames import rotation_from_euler_deg
from groundstation.vicon.plausibility import Box, grown
from groundstation.vicon.posefilter import MAX_RATE_FACTOR, Matrix3, PoseFilterParams
from groundstation.vicon.receiver import ViconParams


def assemble(config: GroundStationConfig) -> FlightParams:
    """The flight's parameters, each record built once from ``config`` (validated; checked
    by :func:`check_config` where files and the lab matter)."""
    link = link_params(config.serial)
    vehicle = vehicle_model(config.vehicle, link)
    limits = flight_limits(config.safety, vehicle)
    volume = flight_volume(config.safety)
    return FlightParams(
        link=link,
        vicon=vicon_params(config.vicon, config.safety),
        imu=imu_scaling(config.vehicle),
        vehicle=vehicle,
        ekf=ekf_params(config),
        settle_time_s=config.estimator.settle_time_s,
        controller=controller_params(config.controller, config.vehicle),
        controller_type=config.controller.type,
        command_period_s=1.0 / config.serial.command_rate_hz,
        trajectory=trajectory_spec(config.trajectory),
        shaping=config.trajectory.shaping,
        limits=limits,
        volume=volume,
        mission=mission_params(config.safety, config.serial),
        commander=commander_params(config.trajectory, config.api),
        planner=planner_settings(config.trajectory, config.api, limits, volume),
        supervisor=supervisor_limits(config),
        channels=tuple(config.channels.auto),
        handover_blend_s=config.serial.handover_blend_s,
        telemetry=publisher_params(config.telemetry),
        requests=request_server_params(config.telemetry),
        daemon=daemon_params(config.logging, config.realtime, config.safety, config.api),
        fleet=None if config.fleet is None else fleet_params(config.fleet),
        source=config,
    )


# --------------------------------------------------------------------------- the link
def link_params(s: SerialConfig) -> LinkParams:
    """The serial link of the ``serial`` section (``serial.ll`` for the LL dialect)."""
    ll = s.ll
    return LinkParams(
        protocol=s.protocol, port=s.port, baud=s.baud, crc_profile=s.crc_profile,
        sensor_mask=sensor_mask(s.sensors), data_period_ms=s.data_period_ms,
        command_rate_hz=s.command_rate_hz, stale_command_s=s.stale_command_s,
        ll=LlParams(status_every=ll.status_every, rc_every=ll.rc_every,
                    answer_timeout_s=ll.answer_timeout_ms / 1000.0,
                    ack_timeout_s=ll.ack_timeout_ms / 1000.0,
                    fallback_s=ll.fallback_ms / 1000.0, rc_channels=ll.rc_channels,
                    motor_start_yaw=ll.motor_start_yaw, motor_gesture_s=ll.motor_gesture_s))


# --------------------------------------------------------------------------- Vicon
def plausible_volume(vicon: ViconConfig, safety: SafetyConfig) -> Box:
    """Where a pose can be: ``safety.volume_x/y/z`` (NED [m]) grown by
    ``vicon.plausibility_margin_m`` on every side."""
    return grown((safety.volume_x, safety.volume_y, safety.volume_z),
                 vicon.plausibility_margin_m)


def rotation(euler_xyz_deg: list[float]) -> Matrix3:
    """A configured rotation (``vicon.world_to_ned``, ``vicon.body_to_object``) as rows."""
    m = rotation_from_euler_deg(euler_xyz_deg)
    return (_row(m[0]), _row(m[1]), _row(m[2]))


def vicon_params(v: ViconConfig, safety: SafetyConfig) -> ViconParams:
    """The Vicon stream of the ``vicon`` section (``vicon.source``: this daemon's socket or
    a fleet's relay); the pose filter's plausible volume is the
    flight volume of ``safety`` grown by the margin, its rate band's top
    ``MAX_RATE_FACTOR`` times the expected rate."""
    return ViconParams(
        bind_address=v.bind_address, port=v.port, source=v.source,
        filter=PoseFilterParams(
            object_name=v.object_name, world_to_ned=rotation(v.world_to_ned.euler_xyz_deg),
            body_to_object=rotation(v.body_to_object.euler_xyz_deg), latency_s=v.latency_s,
            restart_silence_s=v.restart_silence_s,
            restart_backjump_frames=v.restart_backjump_frames, max_speed=v.max_speed_m_s,
            max_rotation_rate=v.max_rotation_rate_rad_s, reanchor_poses=v.reanchor_poses,
            plausible_volume=plausible_volume(v, safety), min_rate_hz=v.min_rate_hz,
            max_rate_hz=MAX_RATE_FACTOR * v.expected_rate_hz))


# --------------------------------------------------------------------------- the vehicle
def imu_scaling(v: VehicleConfig) -> ImuScaling:
    """Per-axis scale and zero offset of the gyro and accelerometer (Table 6.2)."""
    return ImuScaling(gyro=AxisScaling(_vec3(v.gyro_scale), _vec3(v.gyro_zero)),
                      acc=AxisScaling(_vec3(v.acc_scale), _vec3(v.acc_zero)))


def vehicle_model(v: VehicleConfig, link: LinkParams) -> QuadrotorParams:
    """The vehicle model of the ``vehicle`` section; its input delay is the command delay
    plus the frames' time on the wire (:func:`~groundstation.asctec.dialect.wire_time_s`)."""
    a3, a2, a1, a0 = v.thrust_poly
    return QuadrotorParams(mass=v.mass_kg, g=v.gravity, k_rate=_vec3(v.k_rate),
                           inflow=v.induced_inflow, thrust_poly=(a3, a2, a1, a0),
                           rate_tau=v.rate_loop_tau_s,
                           input_delay=v.command_delay_s + wire_time_s(link))


# --------------------------------------------------------------------------- the estimator
def ekf_params(config: GroundStationConfig) -> EkfParams:
    """The EKF of the ``vehicle`` (sensor variances) and ``estimator`` sections, with the
    gate reset's consistency figures and the plausible volume of ``vicon`` and ``safety``,
    the gravity check ``safety.gravity_check_deg`` and the IMU period
    ``serial.data_period_ms`` (the vehicle's IMU variances are per sample at that period).

    ``estimator.r_override`` (7x7 or diagonal 7 over ``[P, q0..q3]``) replaces
    Table 6.1; only its diagonal is used (``q0`` dropped: see :class:`EkfParams`).
    """
    vehicle, estimator, vicon = config.vehicle, config.estimator, config.vicon
    pos_var = tuple(vehicle.vicon_position_variance)
    q_var = tuple(vehicle.vicon_quaternion_variance)
    if estimator.r_override is not None:
        r = np.asarray(estimator.r_override, dtype=float)
        d = np.diag(r) if r.ndim == 2 else r
        pos_var, q_var = tuple(d[0:3]), tuple(d[3:7])
    p0 = np.asarray(estimator.initial_covariance, dtype=float)
    p0d = np.diag(p0) if p0.ndim == 2 else p0
    return EkfParams(
        g=vehicle.gravity,
        gyro_var=_vec3(vehicle.gyro_variance),
        acc_var=_vec3(vehicle.acc_variance),
        imu_period=config.serial.data_period_ms / 1000.0,
        gyro_bias_walk=estimator.gyro_bias_walk,
        acc_bias_walk=estimator.acc_bias_walk,
        process_noise_scale=estimator.process_noise_scale,
        vicon_position_var=_vec3(pos_var),
        vicon_quaternion_var=(float(q_var[0]), float(q_var[1]), float(q_var[2]),
                              float(q_var[3])),
        initial_variance=tuple(float(v) for v in p0d),
        gate_probability=estimator.gate_probability,
        max_vicon_delay=estimator.max_vicon_delay_s,
        gate_reset_count=vicon.reanchor_poses,
        max_speed=vicon.max_speed_m_s,
        max_rotation_rate=vicon.max_rotation_rate_rad_s,
        plausible_volume=plausible_volume(vicon, config.safety),
        divergence_trace=estimator.divergence_trace,
        gravity_check_deg=config.safety.gravity_check_deg,
    )


# --------------------------------------------------------------------------- the controller
def controller_params(c: ControllerConfig, vehicle: VehicleConfig) -> ControllerParams:
    """The record of the controller ``controller.type`` names, tuned as configured (the
    external-force estimate with the accelerometer of the ``vehicle`` section)."""
    if c.type == "lqr-ff":
        ff = c.lqr_ff
        return LqrFfParams(q_error=_vec4(ff.q_error), r_input=_vec4(ff.r_input),
                           q_integral=_vec4(ff.q_integral), integral_limit=ff.integral_limit,
                           external_force=external_force_params(ff.external_force, vehicle)
                           if ff.external_force.enabled else None)
    if c.type in ("lqr-cv", "lqr-cp"):
        lqr = c.lqr
        return LqrParams(
            reference_model="velocity" if c.type == "lqr-cv" else "position",
            q_error=_vec4(lqr.q_error), r_input=_vec4(lqr.r_input),
            q_integral=None if lqr.q_integral is None else _vec4(lqr.q_integral),
            integral_limit=lqr.integral_limit, disturbance_tau=lqr.disturbance_tau_s,
            velocity_source=lqr.velocity_source, velocity_filter=lqr.velocity_filter,
            design_model=lqr.design_model)
    if c.type == "pid":
        p = c.pid
        return PidParams(position_kp=_vec3(p.position_kp), velocity_kp=_vec3(p.velocity_kp),
                         velocity_ki=_vec3(p.velocity_ki), velocity_kd=_vec3(p.velocity_kd),
                         attitude_kp=_vec3(p.attitude_kp), max_tilt_deg=p.max_tilt_deg)
    if c.type == "hinf":
        h = c.hinf
        return HinfParams(gain_file=h.gain_file or default_gain_path(h.include_rate_loop),
                          integral_limit=h.integral_limit)
    raise ConfigError(f"controller.type: {c.type!r}: unknown controller")


def external_force_params(x: ExternalForceConfig, vehicle: VehicleConfig) -> ExternalForceParams:
    """The accelerometer's external-force estimate of ``controller.lqr_ff.external_force``,
    with the accelerometer's noise and range of the ``vehicle`` section."""
    v = vehicle.acc_variance
    return ExternalForceParams(
        fast_jerk=x.fast_jerk_m_s4, horizontal_jerk=x.horizontal_jerk_m_s4,
        quiet_tau_s=x.quiet_tau_s, detect_sigmas=x.detect_sigmas, hold_s=x.hold_s,
        vertical_lead_s=x.vertical_lead_s, motor_tau_s=x.motor_tau_s,
        effectiveness_tau_s=x.effectiveness_tau_s, min_height_m=x.min_height_m,
        limit_m_s2=x.limit_m_s2, acc_variance=(v[0], v[1], v[2]),
        acc_saturation=vehicle.acc_saturation)


def hinf_design(h: HinfConfig, include_rate_loop: bool) -> HinfDesign:
    """How ``gs synth hinf`` designs a gain (``controller.hinf``) on the model with the
    rate-loop lag or without it (the thesis's: then nominal and unconstrained)."""
    integral = None if h.integral_scale is None else _vec4(h.integral_scale)
    return HinfDesign(
        weights=HinfWeights(eps=h.epsilon, reference_pole=h.reference_pole,
                            noise_gain=h.noise_gain, integral_scale=integral),
        include_rate_loop=include_rate_loop,
        robust_range=h.robust_range if include_rate_loop else 0.0,
        pole_radius=h.pole_radius_rad_s if include_rate_loop else None,
        min_decay=h.min_decay_per_s if include_rate_loop else None)


# --------------------------------------------------------------------------- the trajectory
def trajectory_spec(t: TrajectoryConfig) -> TrajectorySpec:
    """The trajectory of a ``trajectory`` section (the configuration's, or a client's
    ``follow`` request), angles in radians."""
    return TrajectorySpec(
        name=t.name, center=_vec3(t.center), size_m=t.size_m, period_s=t.period_s,
        step_m=t.step_m, low_height_m=t.low_height_m, corner_smoothing_s=t.corner_smoothing_s,
        file=t.file, yaw=None if t.yaw_deg is None else math.radians(t.yaw_deg),
        yaw_turn=math.radians(t.yaw_turn_deg), relative=t.polynomial_positions == "relative")


def flight_limits(s: SafetyConfig, vehicle: QuadrotorParams) -> FlightLimits:
    """What a reference may ask of the vehicle: the vehicle model's lift and rate range,
    ``safety.trajectory_tilt_deg``, ``safety.max_speed_m_s`` and
    ``safety.max_yaw_rate_deg_s``; refusals name those keys."""
    safety_yaw = math.radians(s.max_yaw_rate_deg_s)
    vehicle_yaw = abs(vehicle.k_rate[2]) * 2047
    names = LimitNames(
        speed="safety.max_speed_m_s", tilt="safety.trajectory_tilt_deg",
        tilt_rate="the roll/pitch rate limit (vehicle.k_rate x 2047)",
        yaw_rate="safety.max_yaw_rate_deg_s" if safety_yaw <= vehicle_yaw
        else "the yaw rate limit (vehicle.k_rate x 2047)",
        lift="vehicle.thrust_poly", position_jump="the position-jump limit",
        velocity_jump="the velocity-jump limit")
    return FlightLimits.from_params(vehicle, max_tilt_deg=s.trajectory_tilt_deg,
                                    max_speed_m_s=s.max_speed_m_s,
                                    max_yaw_rate_rad_s=safety_yaw, names=names)


def flight_volume(s: SafetyConfig) -> Volume:
    """``safety.volume_x/y/z`` less ``safety.volume_margin_m`` (the floor excepted)."""
    return Volume(x=s.volume_x, y=s.volume_y, z=s.volume_z, margin_m=s.volume_margin_m,
                  name="safety.volume")


def mission_params(s: SafetyConfig, serial: SerialConfig) -> MissionParams:
    """The phases around the trajectory: take-off and landing speeds and acceleration
    limit, the heading turn's rate (``safety``), the spool-up on the ground
    (``serial.handover_blend_s``)."""
    return MissionParams(climb_speed=s.takeoff_speed_m_s, land_speed=s.land_speed_m_s,
                         spool_s=serial.handover_blend_s,
                         max_yaw_rate=math.radians(s.max_yaw_rate_deg_s),
                         accel=s.takeoff_land_accel_m_s2)


def commander_params(t: TrajectoryConfig, api: ApiConfig) -> CommanderParams:
    """The commanded flight (``trajectory.name: none``): it holds at ``trajectory.center``
    (heading ``trajectory.yaw_deg``) until a client asks for more (``api``)."""
    return CommanderParams(home=_vec3(t.center),
                           yaw=None if t.yaw_deg is None else math.radians(t.yaw_deg),
                           arrival_tolerance_m=api.arrival_tolerance_m,
                           idle_land_s=api.idle_land_s)


def planner_settings(t: TrajectoryConfig, api: ApiConfig, limits: FlightLimits,
                     volume: Volume) -> PlannerSettings:
    """How run-time motions are sized, shaped and checked: the flight's limits and volume,
    ``api.speed_m_s``, ``trajectory.shaping`` and ``trajectory.corner_smoothing_s``."""
    return PlannerSettings(MotionLimits(limits, volume, speed=api.speed_m_s,
                                        accel=DEFAULT_MOVE_ACCEL_M_S2),
                           t.shaping, t.corner_smoothing_s)


# --------------------------------------------------------------------------- the supervisor
def supervisor_limits(config: GroundStationConfig) -> SupervisorLimits:
    """The supervisor's limits and failsafes: the ``safety`` section, the DATA rate it
    requires (80 % of ``serial.data_period_ms``'s), ``vicon.min_rate_hz``,
    :func:`pilot_grace_s` and, in a fleet, the separation from its peers
    (``fleet.separation_m``, ``fleet.separation_hold_s``)."""
    s, fleet = config.safety, config.fleet
    return SupervisorLimits(
        volume_x=s.volume_x, volume_y=s.volume_y, volume_z=s.volume_z,
        max_tilt_rad=math.radians(s.max_tilt_deg),
        handback_tilt_rad=math.radians(s.handback_tilt_deg), vicon_loss_hold_s=s.vicon_loss_hold_s,
        vicon_loss_land_s=s.vicon_loss_land_s, link_loss_s=s.link_loss_s,
        preflight_timeout_s=s.preflight_timeout_s, takeoff_timeout_s=s.takeoff_timeout_s,
        min_data_rate_hz=0.8 * 1000.0 / config.serial.data_period_ms,
        min_vicon_rate_hz=config.vicon.min_rate_hz, on_signal=s.on_signal,
        battery_land_v=s.battery_land_v, battery_grace_s=s.battery_grace_s,
        pilot_grace_s=pilot_grace_s(config.serial), on_geofence=s.on_geofence,
        on_overruled=s.on_overruled,
        on_second_stream=s.on_second_stream, landing_confirm_s=s.landing_confirm_s,
        # a fleet's peers (``fleet``): closer than separation_m, hold; alone, no rule
        separation_m=fleet.separation_m if fleet is not None else None,
        separation_hold_s=fleet.separation_hold_s if fleet is not None
        else SupervisorLimits().separation_hold_s,
    )


def pilot_grace_s(serial: SerialConfig) -> float:
    """How long the vehicle may report not applying our commands before it is the pilot's
    [s]: the supervisor's 0.2 s, or, in the AscTec LL dialect, whose status is polled only
    every ``serial.ll.status_every`` IMU periods, two of those periods plus a round trip
    (the first report after a command may be one period old when it is sent)."""
    grace = SupervisorLimits().pilot_grace_s
    if serial.protocol == "asctec-ll":
        ll = serial.ll
        status_period = ll.status_every * serial.data_period_ms / 1000.0
        grace = max(grace, 2.0 * status_period + ll.answer_timeout_ms / 1000.0)
    return grace


# --------------------------------------------------------------------------- beside the flight
def publisher_params(t: TelemetryConfig) -> PublisherParams:
    """The telemetry publisher (no endpoint when ``telemetry.enabled`` is false)."""
    return PublisherParams(endpoint=t.endpoint if t.enabled else None, rate_hz=t.rate_hz)


def request_server_params(t: TelemetryConfig) -> RequestServerParams:
    """The request socket on ``telemetry.control_endpoint`` (null: none), with CURVE when
    ``telemetry.control_server_key`` and ``control_client_keys`` are set."""
    return RequestServerParams(endpoint=t.control_endpoint, server_key=t.control_server_key,
                               client_keys=t.control_client_keys)


def daemon_params(log: LoggingConfig, rt: RealtimeConfig, safety: SafetyConfig,
                  api: ApiConfig) -> DaemonParams:
    """What the real-time daemon does beside the flight: where it logs, what it asks of
    the OS, how it takes a second stop signal, how long a motion may plan."""
    return DaemonParams(
        log_dir=log.flight_log_dir, mcap=log.mcap, fifo_priority=rt.fifo_priority,
        cpu_dma_latency_us=rt.cpu_dma_latency_us,
        switch_interval_s=rt.switch_interval_ms / 1000.0, paced_gc=rt.paced_gc,
        second_signal_after_s=safety.second_signal_after_s,
        plan_timeout_s=api.plan_timeout_s, start_horizon_s=api.start_horizon_s)


# --------------------------------------------------------------------------- a fleet
def fleet_params(f: FleetConfig) -> FleetParams:
    """This vehicle in its fleet (the ``fleet`` section): its node's keys, peers, rates and
    network, and the separation its motions are checked against at planning (the
    in-flight rule's is the supervisor's: :func:`supervisor_limits`)."""
    return FleetParams(name=f.name, vehicle=f.vehicle, peers=tuple(f.peers),
                       separation_m=f.separation_m, peer_timeout_s=f.peer_timeout_s,
                       pose_rate_hz=f.pose_rate_hz, zenoh=zenoh_params(f.zenoh))


def zenoh_params(z: ZenohConfig) -> ZenohParams:
    """How a fleet member joins the fleet's Zenoh network (``fleet.zenoh``, or what a fleet
    file gives the relay and its clients: :meth:`~groundstation.config.fleetfile.FleetFile.
    zenoh_for`)."""
    return ZenohParams(listen=tuple(z.listen), connect=tuple(z.connect),
                       tls_root_ca=z.tls_root_ca, tls_certificate=z.tls_certificate,
                       tls_private_key=z.tls_private_key, operators=tuple(z.operators))


def relay_params(spec: FleetFile, base: GroundStationConfig) -> RelayParams:
    """``gs vicon-relay`` of a fleet file with a ``relay:``: Tracker's stream where the base
    configuration receives it (``vicon.bind_address``, ``vicon.port``), every object
    plausible within all the vehicles' volumes together grown by
    ``vicon.plausibility_margin_m``, and the relay's Zenoh endpoint (``relay.listen``)."""
    if spec.relay is None:
        raise ConfigError("relay: null: this fleet's daemons read the UDP stream "
                          "themselves, there is no relay to run")
    boxes = [spec.volume_of(base, v) for v in spec.vehicles]
    union = ((min(b[0][0] for b in boxes), max(b[0][1] for b in boxes)),
             (min(b[1][0] for b in boxes), max(b[1][1] for b in boxes)),
             (min(b[2][0] for b in boxes), max(b[2][1] for b in boxes)))
    return RelayParams(
        fleet=spec.fleet, vehicles=tuple(spec.names), bind_address=base.vicon.bind_address,
        port=base.vicon.port, plausible_volume=grown(union, base.vicon.plausibility_margin_m),
        zenoh=zenoh_params(spec.zenoh_for("relay", [spec.relay.listen])))


def config_text(params: FlightParams) -> str:
    """The configuration the flight was assembled from, as YAML (the flight log's copy)."""
    return dump_config(params.source)


# --------------------------------------------------------------------------- checks
def check_config(config: GroundStationConfig, source: str = "<config>",
                 lines: dict[str, int] | None = None) -> GroundStationConfig:
    """What the configuration layer cannot check alone, before anything is connected: the
    files it names (waypoints, H-infinity gain), the request socket's CURVE key files
    (read as the socket will read them), and the ``sim:`` section, validated by the
    installed virtual lab. Returns the configuration with that section as the lab's
    model; raises ConfigError naming every problem (and its line: ``lines`` as
    :func:`groundstation.config.key_lines` gives them)."""
    problems = file_problems(config) + _curve_problems(config.telemetry)
    sim = _lab_section(config.sim, problems)
    if problems:
        raise_problems(problems, source, lines)
    return config if sim is None else config.model_copy(update={"sim": sim})


def _curve_problems(t: TelemetryConfig) -> list[Problem]:
    """The CURVE key files of ``telemetry.control_server_key`` and
    ``telemetry.control_client_keys`` that cannot be read as keys."""
    if t.control_endpoint is None or t.control_server_key is None:
        return []
    from groundstation.telemetry.curve import read_key_pair, read_public_keys

    problems: list[Problem] = []
    try:
        read_key_pair(t.control_server_key)
    except ValueError as exc:
        problems.append(("telemetry.control_server_key", str(t.control_server_key), str(exc)))
    try:
        read_public_keys(t.control_client_keys or Path())  # set: the validator pairs them
    except ValueError as exc:
        problems.append(("telemetry.control_client_keys", str(t.control_client_keys),
                         str(exc)))
    return problems


def _lab_section(section: object, problems: list[Problem]) -> BaseModel | None:
    """The ``sim:`` section validated by the installed virtual lab (None without one); its
    problems are added to ``problems`` with paths under ``sim``."""
    if section is None:
        return None
    from groundstation.lab import LabNotInstalledError, virtual_lab

    try:
        return virtual_lab().validate_section(section)
    except ValidationError as exc:
        problems += validation_problems(exc, "sim")
    except LabNotInstalledError as exc:
        problems.append(("sim", "...", f"a virtual lab's section, but {exc}"))
    return None


def _vec3(values: list[float] | tuple[float, ...]) -> tuple[float, float, float]:
    return (float(values[0]), float(values[1]), float(values[2]))


def _vec4(values: list[float] | tuple[float, ...]) -> tuple[float, float, float, float]:
    return (float(values[0]), float(values[1]), float(values[2]), float(values[3]))


def _row(values: np.ndarray) -> tuple[float, float, float]:
    return (float(values[0]), float(values[1]), float(values[2]))
