"""Control: LQR with reference models, PID baseline, H-infinity, trajectories (thesis Ch. 8-11).

Pure numpy/scipy. The flight core hands every controller the time, the state estimate
and the trajectory reference and converts its output to sticks with
:func:`to_sticks`. The controllers: :class:`FeedforwardLqr` (lqr-ff, the default),
:class:`LqrController` (the thesis's lqr-cv and lqr-cp), :class:`PidController` and
:class:`HinfController`; each has a plain parameter record (:mod:`.params`) and
:func:`make_controller` builds the one a record names:

>>> from groundstation.control import LqrController, make_trajectory, to_sticks, StickParams
>>> ctrl = LqrController(reference_model="velocity")          # doctest: +SKIP
>>> out = ctrl.step(t, estimate, trajectory.sample(t))       # doctest: +SKIP
>>> sticks, flags = to_sticks(out, StickParams.from_quadrotor(params))  # doctest: +SKIP
"""

from typing import TYPE_CHECKING

from groundstation.lazy import reexports

if TYPE_CHECKING:  # the names, imported from their modules on first use (groundstation.lazy)
    from groundstation.control.base import Controller, NullController
    from groundstation.control.disturbance import DisturbanceObserver
    from groundstation.control.external_force import ExternalForceObserver
    from groundstation.control.factory import make_controller
    from groundstation.control.feasibility import (
        FeasibilityReport,
        FlightLimits,
        LimitNames,
        Volume,
        check_feasibility,
    )
    from groundstation.control.hinf import HinfController, HinfGain, load_hinf_gain
    from groundstation.control.lqr import LqrController
    from groundstation.control.lqr_design import (
        TrackingGains,
        design_tracking_lqr,
        discretise,
        dlqr,
        riccati_iteration,
    )
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
    from groundstation.control.shaping import MinJerkPath, TimeWarp, shape_for_flight
    from groundstation.control.sticks import (
        CommandLimits,
        SaturationFlags,
        StickParams,
        to_sticks,
    )
    from groundstation.control.trajectories import (
        TrajectorySpec,
        build_trajectory,
        load_trajectory_file,
        load_waypoints,
        make_trajectory,
        square,
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
    "ControllerParams",
    "DisturbanceObserver",
    "ExternalForceObserver",
    "ExternalForceParams",
    "FeasibilityReport",
    "FeedforwardLqr",
    "FigureEight",
    "FlightLimits",
    "HinfController",
    "HinfGain",
    "HinfParams",
    "Hover",
    "LimitNames",
    "LqrController",
    "LqrFfParams",
    "LqrParams",
    "MinJerkPath",
    "NullController",
    "PidController",
    "PidParams",
    "PiecewiseLinear",
    "SaturationFlags",
    "StickParams",
    "TimeWarp",
    "TrackingGains",
    "Trajectory",
    "TrajectorySpec",
    "Volume",
    "YawTurn",
    "build_trajectory",
    "check_feasibility",
    "design_tracking_lqr",
    "discretise",
    "dlqr",
    "load_hinf_gain",
    "load_trajectory_file",
    "load_waypoints",
    "make_controller",
    "make_trajectory",
    "riccati_iteration",
    "shape_for_flight",
    "square",
    "to_sticks",
    "yz_rectangle",
]

if not TYPE_CHECKING:
    __getattr__ = reexports(__name__)
