"""Feasibility check of trajectories against the command limits, before flight."""

from __future__ import annotations

import math

import pytest

from groundstation.control import FigureEight, FlightLimits, check_feasibility, make_trajectory
from groundstation.errors import TrajectoryError
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
    with pytest.raises(TrajectoryError, match=r"needs \d+\.\d deg tilt .* slow it down"):
        check_feasibility(fast, FlightLimits(max_tilt_rad=math.radians(20), max_speed_m_s=10))


def test_sharp_corners_are_measured_and_smoothing_cures_them() -> None:
    sharp = make_trajectory("square")
    report = check_feasibility(sharp, FlightLimits())
    # a 90 degree turn at 0.15 m/s is a velocity jump of 0.15 * sqrt(2)
    sizes = [size for _, size in report.velocity_jumps]
    assert len(sizes) == 4
    assert sizes == pytest.approx([0.15 * math.sqrt(2)] * 4, rel=1e-6)
    with pytest.raises(TrajectoryError, match=r"velocity jumps by 0\.21 m/s .* corner smoothing"):
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
    with pytest.raises(TrajectoryError, match="needs lift between"):
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
