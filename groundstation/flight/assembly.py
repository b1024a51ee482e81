"""Build the flight's components from the configuration.

One place maps the validated configuration onto the pure packages' plain
parameters, so ``model/``, ``estimation/`` and ``control/`` stay free of
configuration types and the real-time daemon, the in-process runner and the
evaluation build identical flights.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import structlog
from pydantic import BaseModel, ValidationError

from groundstation.config import (
    GroundStationConfig,
    Problem,
    TelemetryConfig,
    file_problems,
    raise_problems,
    validation_problems,
)
from groundstation.control.base import Controller
from groundstation.control.external_force import ExternalForceObserver
from groundstation.control.feasibility import (
    FeasibilityReport,
    FlightLimits,
    LimitNames,
    Volume,
    check_feasibility,
)
from groundstation.control.lqr import LqrController
from groundstation.control.lqr_ff import FeedforwardLqr
from groundstation.control.pid import PidController
from groundstation.control.polynomial import PiecewisePolynomial
from groundstation.control.shaping import describe, shape_for_flight
from groundstation.control.trajectories import trajectory_from_config
from groundstation.control.trajectory import PiecewiseLinear, Trajectory
from groundstation.errors import ConfigError, TrajectoryError
from groundstation.flight.commander import DEFAULT_MOVE_ACCEL_M_S2, Commander, MotionLimits
from groundstation.flight.inputs import quadrotor_params

_log = structlog.get_logger(__name__)


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


def controller_from_config(config: GroundStationConfig) -> Controller:
    """The controller ``config.controller.type`` names, tuned as configured and designed
    at the command period (it steps once per COMMAND)."""
    c = config.controller
    params = quadrotor_params(config)
    dt = 1.0 / config.serial.command_rate_hz
    if c.type == "lqr-ff":
        ff = c.lqr_ff
        return FeedforwardLqr(params=params, period=dt, q_error=ff.q_error, r_input=ff.r_input,
                              q_integral=ff.q_integral, integral_limit=ff.integral_limit,
                              external_force=external_force_from_config(config))
    if c.type in ("lqr-cv", "lqr-cp"):
        lqr = c.lqr
        return LqrController(
            params=params, dt=dt,
            reference_model="velocity" if c.type == "lqr-cv" else "position",
            q_error=lqr.q_error, r_input=lqr.r_input,
            q_integral=lqr.q_integral, integral_limit=lqr.integral_limit,
            disturbance_tau=lqr.disturbance_tau_s, velocity_source=lqr.velocity_source,
            velocity_filter=lqr.velocity_filter, design_model=lqr.design_model,
        )
    if c.type == "pid":
        p = c.pid
        return PidController(
            params=params, dt=dt, position_kp=p.position_kp, velocity_kp=p.velocity_kp,
            velocity_ki=p.velocity_ki, velocity_kd=p.velocity_kd, attitude_kp=p.attitude_kp,
            max_tilt_deg=p.max_tilt_deg,
        )
    if c.type == "hinf":
        from groundstation.control.hinf import HinfController, default_gain_path, load_hinf_gain

        path = c.hinf.gain_file or default_gain_path(c.hinf.include_rate_loop)
        return HinfController(load_hinf_gain(path), params=params, dt=dt,
                              integral_limit=c.hinf.integral_limit)
    raise ConfigError(f"controller.type: {c.type!r}: unknown controller")


def external_force_from_config(config: GroundStationConfig) -> ExternalForceObserver | None:
    """The accelerometer's external-force observer of ``controller.lqr_ff.external_force``
    (None when disabled), at the command period, with the accelerometer's range."""
    x = config.controller.lqr_ff.external_force
    v = config.vehicle.acc_variance
    if not x.enabled:
        return None
    return ExternalForceObserver(
        quadrotor_params(config), 1.0 / config.serial.command_rate_hz,
        fast_jerk=x.fast_jerk_m_s4, horizontal_jerk=x.horizontal_jerk_m_s4,
        quiet_tau_s=x.quiet_tau_s,
        detect_sigmas=x.detect_sigmas, hold_s=x.hold_s, vertical_lead_s=x.vertical_lead_s,
        motor_tau_s=x.motor_tau_s, min_height_m=x.min_height_m,
        acc_variance=(v[0], v[1], v[2]),
        limit_m_s2=x.limit_m_s2, acc_saturation=config.vehicle.acc_saturation)


def flight_limits_from_config(config: GroundStationConfig) -> FlightLimits:
    """What a reference may ask of the vehicle: the vehicle model's lift and rate range,
    ``safety.trajectory_tilt_deg``, ``safety.max_speed_m_s`` and
    ``safety.max_yaw_rate_deg_s``; refusals name those keys."""
    s = config.safety
    params = quadrotor_params(config)
    safety_yaw = math.radians(s.max_yaw_rate_deg_s)
    vehicle_yaw = abs(params.k_rate[2]) * 2047
    names = LimitNames(
        speed="safety.max_speed_m_s", tilt="safety.trajectory_tilt_deg",
        tilt_rate="the roll/pitch rate limit (vehicle.k_rate x 2047)",
        yaw_rate="safety.max_yaw_rate_deg_s" if safety_yaw <= vehicle_yaw
        else "the yaw rate limit (vehicle.k_rate x 2047)",
        lift="vehicle.thrust_poly", position_jump="the position-jump limit",
        velocity_jump="the velocity-jump limit")
    return FlightLimits.from_params(params, max_tilt_deg=s.trajectory_tilt_deg,
                                    max_speed_m_s=s.max_speed_m_s,
                                    max_yaw_rate_rad_s=safety_yaw, names=names)


def volume_from_config(config: GroundStationConfig) -> Volume:
    """``safety.volume_x/y/z`` less ``safety.volume_margin_m`` (the floor excepted)."""
    s = config.safety
    return Volume(x=s.volume_x, y=s.volume_y, z=s.volume_z, margin_m=s.volume_margin_m,
                  name="safety.volume")


def motion_limits_from_config(config: GroundStationConfig) -> MotionLimits:
    """How run-time motions are sized and checked (:mod:`groundstation.flight.commander`):
    the trajectory's limits and volume, ``api.speed_m_s``."""
    return MotionLimits(flight_limits_from_config(config), volume_from_config(config),
                        speed=config.api.speed_m_s, accel=DEFAULT_MOVE_ACCEL_M_S2)


def commander_from_config(config: GroundStationConfig) -> Commander:
    """The commanded trajectory of ``trajectory.name: none``: hover at ``trajectory.center``
    (heading ``trajectory.yaw_deg``, or the one at take-off) until a client asks for more;
    TrajectoryError if the hover point is outside the volume."""
    t, api = config.trajectory, config.api
    commander = Commander(np.asarray(t.center, dtype=float),
                          None if t.yaw_deg is None else math.radians(t.yaw_deg),
                          arrival_tolerance_m=api.arrival_tolerance_m,
                          idle_land_s=api.idle_land_s)
    check_feasibility(commander, flight_limits_from_config(config),
                      volume=volume_from_config(config), horizon_s=1.0)
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


def prepare_trajectory(config: GroundStationConfig, trajectory: Trajectory | None = None,
                       duration_s: float | None = None) -> PreparedTrajectory:
    """:func:`trajectory_for_flight` without raising on broken limits: the shaped
    trajectory, its duration, its feasibility report and what it was taken to be.
    TrajectoryError only if it cannot be built (a file that cannot be read)."""
    # the identification flight sizes its doublets from the limits and the volume
    sysid = {"limits": flight_limits_from_config(config), "volume": volume_from_config(config),
             "rate_tau_s": config.vehicle.rate_loop_tau_s} \
        if config.trajectory.name == "sysid" else {}
    traj = trajectory if trajectory is not None else trajectory_from_config(config.trajectory,
                                                                            **sysid)
    if duration_s is None:
        lap = traj.periodic and traj.duration > 0.0
        if lap or isinstance(traj, PiecewiseLinear | PiecewisePolynomial):  # a file: once
            duration_s = traj.duration
        else:
            duration_s = max(traj.duration, config.trajectory.period_s)
    limits = flight_limits_from_config(config)
    traj, duration_s = shape_for_flight(traj, duration_s, limits.max_accel_m_s2, limits=limits,
                                        shaping=config.trajectory.shaping)
    report = check_feasibility(traj, limits, volume=volume_from_config(config),
                               horizon_s=duration_s, raise_on_error=False)
    return PreparedTrajectory(traj, duration_s, report, describe(traj))


def trajectory_for_flight(config: GroundStationConfig, trajectory: Trajectory | None = None,
                          duration_s: float | None = None) -> tuple[Trajectory, float]:
    """The trajectory to fly and how long to fly it [s], checked before flight.

    Builds ``config.trajectory`` unless ``trajectory`` is given; the default duration
    is one lap of a periodic trajectory, a file's (or a path's) own length, else the
    longer of the trajectory and ``trajectory.period_s``. Dense samples are fitted with
    a smooth curve, corners shaped with ``trajectory.shaping: min-jerk``, and a path
    that starts or ends moving is eased in and out (an eased start and end lengthen the
    flight by the ramp; :func:`~groundstation.control.shaping.shape_for_flight`). Then
    the curve to be flown is checked against the limits and the volume
    (:func:`flight_limits_from_config`, :func:`volume_from_config`). What it was taken
    to be and its peaks are logged. Raises TrajectoryError (a file that cannot be read,
    one line per broken limit) before anything is connected.
    ``trajectory.name: none`` is the :func:`commander_from_config`, flown until it lands.
    """
    if trajectory is None and config.trajectory.name == "none":  # flown by run-time commands
        return commander_from_config(config), math.inf
    prepared = prepare_trajectory(config, trajectory, duration_s)
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
