"""Which controller flies and how it is tuned: one plain record per controller type.

Like PX4's ekf2 keeps its settings in one ``struct parameters``, the controllers never see
the configuration: its ``controller`` section becomes one of these records in one place,
:mod:`groundstation.flight.assembly`, and :func:`~groundstation.control.factory.
make_controller` builds the controller a record names. Weights are on the error
``e = x - x_ref`` (Q) and on the inputs ``[omega_x, omega_y, omega_z, F_z]`` (R).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Literal

Weights4 = tuple[float, float, float, float]
"""Four diagonal entries of a weight matrix, on ``[x, y, z, q3]`` or on the inputs."""

Gains3 = tuple[float, float, float]
"""One gain per axis ``x, y, z``."""


@dataclass(frozen=True, slots=True)
class ExternalForceParams:
    """The accelerometer's external-force estimate (:class:`~groundstation.control.
    external_force.ExternalForceObserver`, where each is described).

    fast_jerk, horizontal_jerk : the filters' rate noise [m/s^4]
    quiet_tau_s : the horizontal estimate's time constant while nothing moves [s]
    detect_sigmas : a change is detected beyond this many noise deviations [-]
    hold_s : the fast filter stays on this long after a detection [s]
    vertical_lead_s : how far ahead the thrust takes the vertical estimate [s]
    motor_tau_s : the lift's lag behind the command [s]
    effectiveness_tau_s : time constant of the lift-per-newton estimate [s] (0: none)
    min_height_m : it learns only this far above the take-off point [m]
    limit_m_s2 : clamp per axis [m/s^2]
    acc_variance : the accelerometer's noise per sample, per body axis [(m/s^2)^2]
    acc_saturation : the accelerometer's range [m/s^2]
    """

    fast_jerk: float
    horizontal_jerk: float
    quiet_tau_s: float
    detect_sigmas: float
    hold_s: float
    vertical_lead_s: float
    motor_tau_s: float
    effectiveness_tau_s: float
    min_height_m: float
    limit_m_s2: float
    acc_variance: tuple[float, float, float]
    acc_saturation: float


@dataclass(frozen=True, slots=True)
class LqrFfParams:
    """The LQR with the feed-forward reference model (:class:`~groundstation.control.
    lqr_ff.FeedforwardLqr`): ``q_error`` [1/m^2, -], ``r_input`` [1/(rad/s)^2, 1/N^2],
    ``q_integral`` on the integrated errors (0 turns one off), ``integral_limit`` the
    anti-windup clamp [m s], ``external_force`` the estimate it cancels (None: off)."""

    q_error: Weights4
    r_input: Weights4
    q_integral: Weights4
    integral_limit: float
    external_force: ExternalForceParams | None


@dataclass(frozen=True, slots=True)
class LqrParams:
    """The thesis's LQR with a reference model (:class:`~groundstation.control.lqr.
    LqrController`): ``reference_model`` constant velocity (lqr-cv) or constant position
    (lqr-cp); weights as :class:`LqrFfParams` (``q_integral`` None: no integrators);
    ``disturbance_tau`` the constant-disturbance observer's time constant [s] (None: off);
    ``velocity_source`` and ``velocity_filter`` the constant-velocity model's velocity;
    ``design_model`` with the rate loop and delay, or the thesis's ideal one."""

    reference_model: Literal["velocity", "position"]
    q_error: Weights4
    r_input: Weights4
    q_integral: Weights4 | None
    integral_limit: float
    disturbance_tau: float | None
    velocity_source: Literal["reference", "samples"]
    velocity_filter: float
    design_model: Literal["rate-loop", "thesis"]


@dataclass(frozen=True, slots=True)
class PidParams:
    """The cascaded PID baseline (:class:`~groundstation.control.pid.PidController`):
    ``position_kp`` [1/s]; ``velocity_kp``, ``velocity_ki``, ``velocity_kd`` (x/y: rad of
    tilt, z: N, per m/s, m, m/s^2); ``attitude_kp`` [1/s]; ``max_tilt_deg`` [deg]."""

    position_kp: Gains3
    velocity_kp: Gains3
    velocity_ki: Gains3
    velocity_kd: Gains3
    attitude_kp: Gains3
    max_tilt_deg: float


@dataclass(frozen=True, slots=True)
class HinfParams:
    """The H-infinity controller (:class:`~groundstation.control.hinf.HinfController`):
    the stored ``gain_file`` it flies and the anti-windup ``integral_limit`` [m s]."""

    gain_file: Path
    integral_limit: float


ControllerParams = LqrFfParams | LqrParams | PidParams | HinfParams
"""The parameters of one controller; their type says which one flies."""
