"""Vehicle model: quaternions and frames, nonlinear and linear quadrotor models,
the thrust map and its identification, and IMU sensor scaling (thesis Ch. 2-4, 6, App. C).

Pure numpy/scipy: no I/O except the identification CSV readers, no clock, no threads.
"""

from typing import TYPE_CHECKING

from groundstation.lazy import reexports
from groundstation.model.quadrotor import (
    HOVER_STATE,
    QuadrotorModel,
    QuadrotorParams,
    inputs_from_sticks,
)
from groundstation.model.sensors import AxisScaling, ImuScaling, scale_imu
from groundstation.model.thrust import STICK_MAX, THRUST_POLY_EQ37, ThrustMap

if TYPE_CHECKING:  # the names, imported from their modules on first use (groundstation.lazy)
    from groundstation.model.identify import (
        InflowFit,
        ThrustFit,
        fit_induced_inflow,
        fit_thrust_polynomial,
        identify_inflow_csv,
        identify_thrust_csv,
    )
    from groundstation.model.linear import (
        LinearModel,
        hover_model,
        hover_model_rate_lag,
        hover_model_reduced,
        stick_input_gain,
    )

__all__ = [
    "HOVER_STATE",
    "STICK_MAX",
    "THRUST_POLY_EQ37",
    "AxisScaling",
    "ImuScaling",
    "InflowFit",
    "LinearModel",
    "QuadrotorModel",
    "QuadrotorParams",
    "ThrustFit",
    "ThrustMap",
    "fit_induced_inflow",
    "fit_thrust_polynomial",
    "hover_model",
    "hover_model_rate_lag",
    "hover_model_reduced",
    "identify_inflow_csv",
    "identify_thrust_csv",
    "inputs_from_sticks",
    "scale_imu",
    "stick_input_gain",
]

if not TYPE_CHECKING:
    __getattr__ = reexports(__name__)
