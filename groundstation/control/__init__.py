"""Control: LQR with reference models, PID baseline, H-infinity, trajectories (thesis Ch. 8-11).

Pure numpy/scipy. The loop hands every controller the time, the state estimate
and the trajectory reference and converts its output to sticks with
:func:`to_sticks`:

>>> from groundstation.control import LqrController, make_trajectory, to_sticks, StickParams
>>> ctrl = LqrController(reference_model="velocity")          # doctest: +SKIP
>>> out = ctrl.step(t, estimate, trajectory.sample(t))       # doctest: +SKIP
>>> sticks, flags = to_sticks(out, StickParams.from_quadrotor(params))  # doctest: +SKIP
"""

from groundstation.control.base import Controller, NullController
from groundstation.control.disturbance import DisturbanceObserver
from groundstation.control.feasibility import (
    FeasibilityReport,
    FlightLimits,
    LimitNames,
    Volume,
    check_feasibility,
)
from groundstation.control.lqr import LqrController
from groundstation.control.lqr_design import (
    TrackingGains,
    design_tracking_lqr,
    discretise,
    dlqr,
    riccati_iteration,
)
from groundstation.control.pid import PidController
from groundstation.control.shaping import MinJerkPath, TimeWarp, shape_for_flight
from groundstation.control.sticks import (
    CommandLimits,
    SaturationFlags,
    StickParams,
    to_sticks,
)
from groundstation.control.trajectories import (
    load_waypoints,
    make_trajectory,
    square,
    trajectory_from_config,
    yz_rectangle,
)
from groundstation.control.trajectory import (
    FigureEight,
    Hover,
    PiecewiseLinear,
    Trajectory,
    YawTurn,
)

__all__ = [
    "CommandLimits",
    "Controller",
    "DisturbanceObserver",
    "FeasibilityReport",
    "FigureEight",
    "FlightLimits",
    "Hover",
    "LimitNames",
    "LqrController",
    "MinJerkPath",
    "NullController",
    "PidController",
    "PiecewiseLinear",
    "SaturationFlags",
    "StickParams",
    "TimeWarp",
    "TrackingGains",
    "Trajectory",
    "Volume",
    "YawTurn",
    "check_feasibility",
    "design_tracking_lqr",
    "discretise",
    "dlqr",
    "load_waypoints",
    "make_trajectory",
    "riccati_iteration",
    "shape_for_flight",
    "square",
    "to_sticks",
    "trajectory_from_config",
    "yz_rectangle",
]
