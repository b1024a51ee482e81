"""The one function that builds the controller a parameter record names.

Adding a controller: its module (a :class:`~groundstation.control.base.Controller`), its
record in :mod:`groundstation.control.params`, a case here, its section in the
configuration (:mod:`groundstation.config.controller`) and its line in the assembly
(:mod:`groundstation.flight.assembly`); docs/architecture.md walks through it.
"""

from __future__ import annotations

from groundstation.control.base import Controller
from groundstation.control.external_force import ExternalForceObserver
from groundstation.control.lqr import LqrController
from groundstation.control.lqr_ff import FeedforwardLqr
from groundstation.control.params import (
    ControllerParams,
    ExternalForceParams,
    HinfParams,
    LqrFfParams,
    LqrParams,
    PidParams,
)
from groundstation.control.pid import PidController
from groundstation.errors import ControlError
from groundstation.model.quadrotor import QuadrotorParams


def make_controller(params: ControllerParams, vehicle: QuadrotorParams,
                    period_s: float) -> Controller:
    """The controller ``params`` describe, for ``vehicle``, designed at the command period
    ``period_s`` [s] (it steps once per COMMAND)."""
    if isinstance(params, LqrFfParams):
        observer = None if params.external_force is None else \
            make_external_force(params.external_force, vehicle, period_s)
        return FeedforwardLqr(params=vehicle, period=period_s, q_error=params.q_error,
                              r_input=params.r_input, q_integral=params.q_integral,
                              integral_limit=params.integral_limit, external_force=observer)
    if isinstance(params, LqrParams):
        return LqrController(
            params=vehicle, dt=period_s, reference_model=params.reference_model,
            q_error=params.q_error, r_input=params.r_input, q_integral=params.q_integral,
            integral_limit=params.integral_limit, disturbance_tau=params.disturbance_tau,
            velocity_source=params.velocity_source, velocity_filter=params.velocity_filter,
            design_model=params.design_model)
    if isinstance(params, PidParams):
        return PidController(
            params=vehicle, dt=period_s, position_kp=params.position_kp,
            velocity_kp=params.velocity_kp, velocity_ki=params.velocity_ki,
            velocity_kd=params.velocity_kd, attitude_kp=params.attitude_kp,
            max_tilt_deg=params.max_tilt_deg)
    if isinstance(params, HinfParams):
        from groundstation.control.hinf import HinfController, load_hinf_gain

        return HinfController(load_hinf_gain(params.gain_file), params=vehicle, dt=period_s,
                              integral_limit=params.integral_limit)
    raise ControlError(f"no controller for {type(params).__name__}")


def make_external_force(params: ExternalForceParams, vehicle: QuadrotorParams,
                        period_s: float) -> ExternalForceObserver:
    """The accelerometer's external-force observer ``params`` describe, for ``vehicle``,
    stepped at the command period ``period_s`` [s]."""
    return ExternalForceObserver(
        vehicle, period_s, fast_jerk=params.fast_jerk,
        horizontal_jerk=params.horizontal_jerk, quiet_tau_s=params.quiet_tau_s,
        detect_sigmas=params.detect_sigmas, hold_s=params.hold_s,
        vertical_lead_s=params.vertical_lead_s, motor_tau_s=params.motor_tau_s,
        effectiveness_tau_s=params.effectiveness_tau_s, min_height_m=params.min_height_m,
        acc_variance=params.acc_variance, limit_m_s2=params.limit_m_s2,
        acc_saturation=params.acc_saturation)
