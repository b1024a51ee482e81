"""Build the flight's components from the configuration.

One place maps the validated configuration onto the pure packages' plain
parameters, so ``model/``, ``estimation/`` and ``control/`` stay free of
configuration types and the real-time daemon, the in-process runner and the
evaluation build identical flights.
"""

from __future__ import annotations

from groundstation.config import GroundStationConfig
from groundstation.control.base import Controller
from groundstation.control.lqr import LqrController
from groundstation.control.lqr_ff import FeedforwardLqr
from groundstation.control.pid import PidController
from groundstation.errors import ConfigError
from groundstation.loop.inputs import quadrotor_params


def controller_from_config(config: GroundStationConfig) -> Controller:
    """The controller ``config.controller.type`` names, tuned as configured and designed
    at the command period (it steps once per COMMAND)."""
    c = config.controller
    params = quadrotor_params(config)
    dt = 1.0 / config.serial.command_rate_hz
    if c.type == "lqr-ff":
        ff = c.lqr_ff
        return FeedforwardLqr(params=params, period=dt, q_error=ff.q_error, r_input=ff.r_input,
                              q_integral=ff.q_integral, integral_limit=ff.integral_limit)
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
        return HinfController(load_hinf_gain(path), params=params)
    raise ConfigError(f"controller.type: {c.type!r}: unknown controller")
