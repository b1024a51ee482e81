"""Feasibility check of trajectories against the command limits and the volume, before
flight; the config-aware entry point the flight core and `gs check-config` use."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from groundstation.config import GroundStationConfig, validate_config
from groundstation.control import (
    FigureEight,
    FlightLimits,
    PiecewiseLinear,
    check_feasibility,
    make_trajectory,
)
from groundstation.control.shaping import TimeWarp
from groundstation.errors import TrajectoryError
from groundstation.flight.assembly import assemble
from groundstation.flight.prepare import trajectory_for_flight
from groundstation.model import QuadrotorParams, ThrustMap


def test_thesis_trajectories_are_feasible() -> None:
    for name in ("hover", "step-x", "step-z", "square", "yz-rectangle", "low-hover",
                 "figure-eight"):
        report = check_feasibility(make_trajectory(name), FlightLimits())
        assert report.feasible, (name, report.problems)


def test_figure_eight_tilt_matches_the_closed_form() -> None:
    # y = a sin(wt) has peak acceleration a w^2 and x = a/2 sin(2wt) has 2 a w^2;
    # at the centre crossing x'' = 0 and y'' = 0, at the lobes |a| peaks. The largest
    # horizontal acceleration of the lemniscate over a lap, found by dense sampling of
    # the closed form, gives the tilt atan(a_max / g).
    width, period = 1.0, 8.0
    a, w = width / 2, 2 * math.pi / period
    acc = max(math.hypot(-2 * a * w * w * math.sin(2 * w * t), -a * w * w * math.sin(w * t))
              for t in [k * period / 20000 for k in range(20000)])
    report = check_feasibility(FigureEight([0, 0, -1], width_m=width, period_s=period),
                               FlightLimits(), dt=0.001)
    assert report.max_tilt_rad == pytest.approx(math.atan(acc / 9.82), rel=1e-4)


def test_too_fast_figure_eight_is_refused_with_advice() -> None:
    fast = FigureEight([0, 0, -1], width_m=1.5, period_s=2.0)
    with pytest.raises(TrajectoryError, match=r"at t = \d+\.\d\d s, \(-?\d\.\d\d, -?\d\.\d\d, "
                       r"-1\.00\) m: needs \d+\.\d deg tilt, the tilt limit = 20\.0 deg "
                       r"\(closed form\): slow it down by k = 2\.10"):
        check_feasibility(fast, FlightLimits(max_tilt_rad=math.radians(20), max_speed_m_s=10))


def test_sharp_corners_are_measured_and_smoothing_cures_them() -> None:
    sharp = make_trajectory("square")
    report = check_feasibility(sharp, FlightLimits())
    # a 90 degree turn at 0.15 m/s is a velocity jump of 0.15 * sqrt(2)
    sizes = [size for _, size in report.velocity_jumps]
    assert len(sizes) == 4
    assert sizes == pytest.approx([0.15 * math.sqrt(2)] * 4, rel=1e-6)
    with pytest.raises(TrajectoryError, match=r"at t = 5\.00 s, \(0\.38, 0\.38, -1\.00\) m: "
                       r"velocity jumps by 0\.21 m/s, .* corner smoothing"):
        check_feasibility(sharp, FlightLimits(max_velocity_jump_m_s=0.1))
    smooth = make_trajectory("square", corner_smoothing_s=1.0)
    report = check_feasibility(smooth, FlightLimits(max_velocity_jump_m_s=0.1))
    assert report.velocity_jumps == []


def test_large_step_and_fast_climb_are_refused() -> None:
    with pytest.raises(TrajectoryError, match=r"position jumps by 1\.50 m"):
        check_feasibility(make_trajectory("step-x", step_m=1.5), FlightLimits())
    # climbing at v costs the induced-inflow force |I_i| v (eq. 3.9) on top of the weight
    climb = make_trajectory("yz-rectangle", size_m=1.5, period_s=2.0)
    report = check_feasibility(climb, FlightLimits(max_speed_m_s=10, max_tilt_rad=1.5,
                                                   max_rate_rad_s=100,
                                                   max_velocity_jump_m_s=10),
                               raise_on_error=False)
    speed = 2 * (1.5 + 1.0) / 2.0
    assert report.max_lift_n == pytest.approx(0.6 * 9.82 + 0.423 * speed, rel=1e-6)
    lift = f"{0.6 * 9.82 + 0.423 * speed:.2f}"
    with pytest.raises(TrajectoryError, match=f"needs {lift} N of lift, the rotors give "
                       r"0\.90 to 6\.50 N"):
        check_feasibility(climb, FlightLimits(max_speed_m_s=10, max_tilt_rad=1.5,
                                              max_rate_rad_s=100, max_velocity_jump_m_s=10,
                                              lift_max_n=6.5))


def test_limits_from_the_vehicle_model() -> None:
    lim = FlightLimits.from_params(QuadrotorParams(), max_tilt_deg=25.0)
    # eq. 3.7 at stick 0 gives -0.903 N (the least lift); the most at its monotonic end
    assert lim.lift_min_n == pytest.approx(0.903)
    assert lim.lift_max_n == pytest.approx(-ThrustMap().force(ThrustMap().u_max))
    assert lim.max_rate_rad_s == pytest.approx(2047 * 1.1e-3)  # ~2.25 rad/s, Ch. 3.3.1
    assert lim.max_tilt_rad == pytest.approx(math.radians(25.0))
    assert check_feasibility(make_trajectory("square"), lim).feasible


# ------------------------------------------------- the check before flight (config-aware)
def config(**trajectory: object) -> GroundStationConfig:
    return validate_config({"trajectory": trajectory})


def refusal(cfg: GroundStationConfig) -> str:
    with pytest.raises(TrajectoryError) as info:
        trajectory_for_flight(assemble(cfg))
    return str(info.value)


@pytest.mark.slow
def test_every_named_trajectory_is_shaped_and_passes_with_the_defaults() -> None:
    for name in ("hover", "step-x", "step-y", "step-z", "square", "yz-rectangle", "low-hover",
                 "figure-eight", "yaw-turn"):
        traj, duration = trajectory_for_flight(assemble(config(name=name)))
        report = check_feasibility(traj, FlightLimits(), horizon_s=duration)
        if name not in ("step-x", "step-y", "step-z"):  # a step is the test: left alone
            assert report.velocity_jumps == [] and report.position_jumps == [], name
    # shaping none keeps the thesis's raw square (sharp corners)
    raw, duration = trajectory_for_flight(assemble(config(name="square", shaping="none")))
    assert isinstance(raw, PiecewiseLinear) and duration == 20.0
    assert len(check_feasibility(raw, FlightLimits()).velocity_jumps) == 4


def test_the_issues_fast_eight_is_eased_and_flyable() -> None:
    fast = config(name="figure-eight", size_m=1.2, period_s=8.0)
    traj, duration = trajectory_for_flight(assemble(fast))
    assert isinstance(traj, TimeWarp) and duration == pytest.approx(8.0 + traj.ramp_s)
    report = check_feasibility(traj, FlightLimits(), horizon_s=duration)
    assert report.feasible and report.velocity_jumps == []


def test_a_point_outside_the_volume_less_the_margin_is_refused_by_name() -> None:
    # square of 0.75 m centred at y = 1.2: the east edge at y = 1.575 > 1.5 - 0.1
    msg = refusal(config(name="square", center=[0.0, 1.2, -1.0]))
    assert ("at t = 5.00 s, (0.38, 1.57, -1.00) m: y = 1.57 m is outside safety.volume_y "
            "[-1.50, 1.50] less the 0.10 m margin") in msg
    assert msg.count("\n") == 1  # one line: the east side only
    # 1.45 m is inside the volume but not inside the margin
    msg = refusal(validate_config({"trajectory": {"name": "hover", "center": [0.0, 0.0, -1.0]},
                                   "safety": {"volume_x": [-1.5, 0.05]}}))
    assert "x = 0.00 m is outside safety.volume_x [-1.50, 0.05] less the 0.10 m margin" in msg


def test_a_start_above_the_ceiling_is_refused_and_the_floor_has_no_margin() -> None:
    msg = refusal(config(name="hover", center=[0.0, 0.0, -1.95]))
    assert ("at t = 0.00 s, (0.00, 0.00, -1.95) m: the start height 1.95 m is above the "
            "ceiling: z = -1.95 m is outside safety.volume_z [-2.00, 0.05] less the 0.10 m "
            "margin") in msg
    trajectory_for_flight(assemble(config(name="low-hover")))  # 2 cm above the floor is allowed


def test_too_much_tilt_and_too_fast_a_turn_are_refused_by_name() -> None:
    msg = refusal(config(name="figure-eight", size_m=1.5, period_s=3.0))
    assert "deg tilt, safety.trajectory_tilt_deg = 20.0 deg" in msg
    assert "exceeds safety.max_speed_m_s = 1.50 m/s" in msg
    # a min-jerk turn peaks at 15/8 of the mean rate: 1.875 * 360 deg / 5 s = 135 deg/s,
    # at mid-turn, holding the centre
    msg = refusal(config(name="yaw-turn", yaw_turn_deg=360.0, period_s=5.0))
    assert ("at t = 2.50 s, (0.00, 0.00, -1.00) m: needs a yaw rate of 135.0 deg/s, "
            "safety.max_yaw_rate_deg_s = 90.0 deg/s") in msg
    trajectory_for_flight(assemble(config(name="yaw-turn", yaw_turn_deg=360.0, period_s=8.0)))  # 84


def test_a_missing_waypoint_file_is_refused(tmp_path: Path) -> None:
    msg = refusal(config(name="waypoints", file=str(tmp_path / "absent.csv")))
    assert "absent.csv: cannot read waypoints" in msg
