"""Trajectory shapes: geometry of Ch. 11, exact derivatives, smoothing, waypoint files."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from groundstation.config import TrajectoryConfig
from groundstation.control import (
    FigureEight,
    PiecewiseLinear,
    make_trajectory,
    square,
    trajectory_from_config,
)
from groundstation.control.trajectories import TRAJECTORY_NAMES, load_waypoints
from groundstation.errors import TrajectoryError


def _fd(traj, t: float, h: float = 1e-5) -> tuple[np.ndarray, np.ndarray]:
    """Central finite differences of position and velocity at t."""
    a, b = traj.sample(t - h), traj.sample(t + h)
    return (b.position - a.position) / (2 * h), (b.velocity - a.velocity) / (2 * h)


def test_square_is_the_thesis_square_clockwise_from_above() -> None:
    # Ch. 11.3: 0.75 m x 0.75 m centred on (0, 0) at 1 m height (z = -1), 20 s per lap.
    sq = make_trajectory("square")
    corners = np.array([sq.sample(t).position for t in (0.0, 5.0, 10.0, 15.0)])
    np.testing.assert_allclose(corners, [[0.375, -0.375, -1], [0.375, 0.375, -1],
                                         [-0.375, 0.375, -1], [-0.375, -0.375, -1]])
    # clockwise seen from above (x north up, y east right): N edge flown eastwards,
    # i.e. the signed area in the (y, x) screen plane is negative (clockwise)
    xy = np.array([sq.sample(t).position[:2] for t in np.linspace(0, 20, 401)])
    east, north = xy[:, 1], xy[:, 0]
    signed_area = 0.5 * np.sum(east[:-1] * north[1:] - east[1:] * north[:-1])
    assert signed_area == pytest.approx(-0.75**2, rel=1e-3)
    # constant speed 4 * 0.75 / 20 = 0.15 m/s on every edge, periodic in 20 s
    speeds = [np.linalg.norm(sq.sample(t).velocity) for t in np.linspace(0.1, 19.9, 50)]
    np.testing.assert_allclose(speeds, 0.15)
    np.testing.assert_allclose(sq.sample(3.3).position, sq.sample(43.3).position, atol=1e-12)


@pytest.mark.parametrize("t", [0.7, 4.99, 7.5, 13.2, 19.3, 23.4])
def test_smoothed_square_derivatives_match_finite_differences(t: float) -> None:
    sq = square(smoothing_s=1.0)
    ref = sq.sample(t)
    dp, dv = _fd(sq, t)
    np.testing.assert_allclose(ref.velocity, dp, atol=1e-6)
    np.testing.assert_allclose(ref.acceleration, dv, atol=1e-4)


def test_smoothing_blends_corners_with_bounded_acceleration_only() -> None:
    sharp, smooth = square(), square(smoothing_s=1.0)
    # away from the corners (more than T/2) the paths coincide
    for t in (1.0, 2.5, 4.4, 6.0, 12.0):
        np.testing.assert_allclose(smooth.sample(t).position, sharp.sample(t).position, atol=1e-12)
    # at a corner: |a| = |dv| / T = 0.15 * sqrt(2) / 1 s (moving-average closed form)
    acc = np.linalg.norm(smooth.sample(5.0).acceleration)
    assert acc == pytest.approx(0.15 * math.sqrt(2), rel=1e-9)
    # the velocity is continuous across the corner
    v = np.array([smooth.sample(t).velocity for t in np.linspace(4.0, 6.0, 2001)])
    assert np.max(np.linalg.norm(np.diff(v, axis=0), axis=1)) < 1e-3


def test_yz_rectangle_stays_in_its_plane_at_constant_speed() -> None:
    rect = make_trajectory("yz-rectangle", size_m=0.75)
    pts = np.array([rect.sample(t).position for t in np.linspace(0, 20, 201)])
    np.testing.assert_allclose(pts[:, 0], 0.0)
    assert pts[:, 1].min() == pytest.approx(-0.375) and pts[:, 1].max() == pytest.approx(0.375)
    assert pts[:, 2].min() == pytest.approx(-1.25) and pts[:, 2].max() == pytest.approx(-0.75)
    speed = 2 * (0.75 + 0.5) / 20.0
    for t in (1.0, 7.0, 12.0, 18.0):
        assert np.linalg.norm(rect.sample(t).velocity) == pytest.approx(speed)


@pytest.mark.parametrize("t", [0.0, 1.3, 6.1, 12.7])
def test_figure_eight_derivatives_are_exact(t: float) -> None:
    fig = FigureEight([0, 0, -1], width_m=1.0, period_s=10.0)
    ref = fig.sample(t)
    dp, dv = _fd(fig, t)
    np.testing.assert_allclose(ref.velocity, dp, atol=1e-7)
    np.testing.assert_allclose(ref.acceleration, dv, atol=1e-6)
    # it crosses its centre twice per lap (t = 0 and T/2): a figure eight
    np.testing.assert_allclose(fig.sample(5.0).position, [0, 0, -1], atol=1e-12)


def test_steps_and_hovers() -> None:
    step = make_trajectory("step-z", step_m=0.5, step_time_s=2.0)
    np.testing.assert_allclose(step.sample(1.99).position, [0, 0, -1])
    np.testing.assert_allclose(step.sample(2.0).position, [0, 0, -1.5])  # up = -z
    np.testing.assert_allclose(make_trajectory("step-x").sample(5).position, [0.5, 0, -1])
    np.testing.assert_allclose(make_trajectory("step-y").sample(5).position, [0, 0.5, -1])
    np.testing.assert_allclose(make_trajectory("low-hover").sample(3).position, [0, 0, -0.02])
    np.testing.assert_allclose(make_trajectory("hover").sample(3).velocity, 0.0)


def test_every_config_name_builds(tmp_path: Path) -> None:
    csv = tmp_path / "w.csv"
    csv.write_text("t,x,y,z\n0,0,0,-1\n2,1,0,-1\n")
    for name in TRAJECTORY_NAMES:
        traj = make_trajectory(name, file=csv)
        assert traj.sample(1.0).position.shape == (3,)
    cfg = TrajectoryConfig(name="square", size_m=0.5, period_s=10.0)
    sq = trajectory_from_config(cfg)
    assert sq.duration == 10.0
    np.testing.assert_allclose(sq.sample(0).position, [0.25, -0.25, -1])
    with pytest.raises(TrajectoryError, match="unknown trajectory 'circle'"):
        make_trajectory("circle")


def test_waypoints_from_csv_interpolate_and_hold(tmp_path: Path) -> None:
    path = tmp_path / "wp.csv"
    path.write_text("# t, x, y, z, yaw\nt,x,y,z,yaw\n10,0,0,-1,0\n12,1,0,-1,1.0\n\n14,1,2,-1,1.0\n")
    wp = load_waypoints(path)
    assert wp.duration == 4.0  # times relative to the first row
    np.testing.assert_allclose(wp.sample(1.0).position, [0.5, 0, -1])
    np.testing.assert_allclose(wp.sample(1.0).velocity, [0.5, 0, 0])
    assert wp.sample(1.0).yaw == pytest.approx(0.5)
    np.testing.assert_allclose(wp.sample(99.0).position, [1, 2, -1])  # holds the last point
    np.testing.assert_allclose(wp.sample(99.0).velocity, 0.0)


@pytest.mark.parametrize(("text", "message"), [
    ("0,0,0,-1\n1,0,0\n", r"wp.csv:2: expected 4 or 5"),
    ("0,0,0,-1\n0,1,0,-1\n", "increase strictly"),
    ("0,0,0,-1\n1,a,0,-1\n", r"wp.csv:2: not a number"),
    ("0,0,0,-1\n", "at least 2 waypoints"),
    ("0,0,0,-1\n1,nan,0,-1\n", "finite"),
])
def test_bad_waypoint_files_are_refused_with_the_line(tmp_path: Path, text: str,
                                                      message: str) -> None:
    path = tmp_path / "wp.csv"
    path.write_text(text)
    with pytest.raises(TrajectoryError, match=message):
        load_waypoints(path)
    with pytest.raises(TrajectoryError, match="cannot read"):
        load_waypoints(tmp_path / "missing.csv")


def test_path_validation() -> None:
    with pytest.raises(TrajectoryError, match="closed loop"):
        PiecewiseLinear([0, 1], [[0, 0, 0], [1, 0, 0]], periodic=True)
    with pytest.raises(TrajectoryError, match="shorter than the shortest segment"):
        square(smoothing_s=6.0)
