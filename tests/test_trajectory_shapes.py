"""Trajectory shapes: geometry of Ch. 11, exact derivatives, smoothing, min-jerk shaping,
easing, headings, waypoint files."""

from __future__ import annotations

import itertools
import math
from pathlib import Path

import numpy as np
import pytest

from groundstation.config import TrajectoryConfig
from groundstation.control import (
    FigureEight,
    Hover,
    PiecewiseLinear,
    Trajectory,
    build_trajectory,
    make_trajectory,
    square,
)
from groundstation.control.shaping import MinJerkPath, TimeWarp, min_jerk_path, shape_for_flight
from groundstation.control.trajectories import TRAJECTORY_NAMES, load_waypoints
from groundstation.control.trajectory import YawTurn
from groundstation.errors import TrajectoryError
from groundstation.flight.assembly import trajectory_spec


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
    sq = build_trajectory(trajectory_spec(cfg))
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


# ---------------------------------------------------------------- exact derivatives
def _fd_check(traj: Trajectory, t: float, h: float = 1e-3, tol: float = 2e-5) -> None:
    """Velocity, acceleration and jerk against central differences of the *positions*,
    the heading rate against those of the heading (truncation error O(h^2))."""
    p = {k: traj.sample(t + k * h).position for k in (-2, -1, 0, 1, 2)}
    yaw = {k: traj.sample(t + k * h).yaw for k in (-1, 1)}
    ref = traj.sample(t)
    scale = 1.0 + float(np.max(np.abs(ref.jerk)))
    np.testing.assert_allclose(ref.velocity, (p[1] - p[-1]) / (2 * h), atol=tol * scale)
    np.testing.assert_allclose(ref.acceleration, (p[1] - 2 * p[0] + p[-1]) / h**2,
                               atol=tol * scale)
    jerk = (p[2] - 2 * p[1] + 2 * p[-1] - p[-2]) / (2 * h**3)
    np.testing.assert_allclose(ref.jerk, jerk, atol=50 * tol * scale)
    assert ref.yaw_rate == pytest.approx((yaw[1] - yaw[-1]) / (2 * h), abs=tol)


def _kinds() -> dict[str, Trajectory]:
    """One of every trajectory kind, headings turning where the kind allows it."""
    times, points = [0.0, 2.0, 3.0, 5.5, 7.0], [[0, 0, -1], [0.6, 0, -1], [1.0, 0, -1],
                                                 [1.0, 0.8, -1.3], [0, 0, -1]]
    yaws = np.array([0.0, 0.5, 0.5, -1.0, 0.0])
    return {
        "hover": Hover([0, 0, -1], yaw=0.3),
        "raw-path": PiecewiseLinear(times, points, yaw=yaws),
        "smoothed-square": square(smoothing_s=1.0),
        "figure-eight": FigureEight([0, 0, -1], width_m=1.2, period_s=8.0),
        "yaw-turn": YawTurn([0, 0, -1], turn=math.pi, period_s=6.0),
        "min-jerk-path": MinJerkPath(times, points, yaw=yaws),
        "min-jerk-square": min_jerk_path(square()),
        "eased-figure-eight": TimeWarp(FigureEight([0, 0, -1], width_m=1.2, period_s=8.0),
                                       8.0, 1.3),
        "eased-path": TimeWarp(MinJerkPath(times, points, yaw=yaws), 6.2, 1.5),
    }


@pytest.mark.parametrize("kind", list(_kinds()))
@pytest.mark.parametrize("t", [0.35, 1.1, 2.6, 4.9, 6.35, 7.6, 9.4])
def test_every_kind_has_exact_derivatives(kind: str, t: float) -> None:
    # times chosen at least 2h from any knot, corner blend edge or ramp end
    if kind == "smoothed-square" and abs(t - 4.9) < 0.1:
        t = 4.2  # 4.9 is within h of the corner blend's edge at 4.5 + 0.5
    _fd_check(_kinds()[kind], t)


@pytest.mark.parametrize(("span", "ramp"), [(8.0, 1.3), (6.2, 1.5), (3.0, 5.0), (1.0, 1.0)])
def test_the_warps_clock_at_one_time_is_its_clocks_at_many_bit_for_bit(span: float,
                                                                         ramp: float) -> None:
    # the flight samples one time a tick (in scalars), the feasibility check many at once
    warp = TimeWarp(FigureEight([0, 0, -1], width_m=1.2, period_s=8.0), span, ramp)
    r, end = warp.ramp_s, warp.duration
    edges = [0.0, r, end - r, end, math.nextafter(r, 0.0), math.nextafter(end - r, end)]
    t = np.concatenate((np.linspace(-0.5, end + 0.5, 4001), edges))
    np.testing.assert_array_equal(np.array([warp.clock(x) for x in t]),
                                  np.array(warp.clocks(t)).T)


def test_raw_and_smoothed_paths_say_their_jerk_is_zero_where_defined() -> None:
    # the independent answer: constant-speed segments and parabolic blends have no jerk
    for traj in (square(), square(smoothing_s=1.0)):
        for t in (1.0, 4.8, 5.2, 12.0):
            np.testing.assert_array_equal(traj.sample(t).jerk, 0.0)


# ---------------------------------------------------------------- min-jerk knots
def quintic_smoothstep(x: float) -> float:
    """10 x^3 - 15 x^4 + 6 x^5 written out (independent of the package)."""
    return 10 * x**3 - 15 * x**4 + 6 * x**5


def test_shaped_square_passes_through_its_corners_at_the_knot_times_on_the_edges() -> None:
    raw = square()
    shaped = min_jerk_path(raw)
    for t in (0.0, 5.0, 10.0, 15.0, 20.0, 25.0):
        np.testing.assert_allclose(shaped.sample(t).position, raw.sample(t).position,
                                   atol=1e-12)
        np.testing.assert_allclose(shaped.sample(t).velocity, 0.0, atol=1e-12)
        np.testing.assert_allclose(shaped.sample(t).acceleration, 0.0, atol=1e-12)
    # on the north edge (x = +0.375) from y = -0.375 to +0.375 along the min-jerk profile
    for t in np.linspace(0.0, 5.0, 23):
        p = shaped.sample(float(t)).position
        assert p[0] == pytest.approx(0.375, abs=1e-12) and p[2] == pytest.approx(-1.0)
        assert p[1] == pytest.approx(-0.375 + 0.75 * quintic_smoothstep(t / 5.0), abs=1e-12)
    # the peak speed of a rest-to-rest quintic is 15/8 of the average 0.15 m/s
    assert np.linalg.norm(shaped.sample(2.5).velocity) == pytest.approx(1.875 * 0.15)


def test_collinear_knots_are_flown_through_and_corners_stop() -> None:
    # 0 -> 1 m in 2 s (0.5 m/s), on to 1.5 m in 2 s (0.25 m/s), then a corner north
    path = MinJerkPath([0.0, 2.0, 4.0, 6.0], [[0, 0, -1], [0, 1, -1], [0, 1.5, -1],
                                              [1, 1.5, -1]])
    eps = 1e-9
    for knot in (2.0, 4.0):
        before, after = path.sample(knot - eps), path.sample(knot + eps)
        np.testing.assert_allclose(before.velocity, after.velocity, atol=1e-7)
        np.testing.assert_allclose(before.acceleration, after.acceleration, atol=1e-6)
        np.testing.assert_allclose(after.acceleration, 0.0, atol=1e-6)
    # through the collinear knot at the slower neighbour's average speed, not stopping
    np.testing.assert_allclose(path.sample(2.0).velocity, [0, 0.25, 0], atol=1e-12)
    np.testing.assert_allclose(path.sample(4.0).velocity, 0.0, atol=1e-12)  # the corner
    speed = np.array([path.sample(t).velocity[1] for t in np.linspace(0, 4, 401)])
    assert speed.min() >= -1e-12  # never backs up


def test_shaped_waypoints_hold_their_ends_at_rest() -> None:
    path = MinJerkPath([0.0, 3.0], [[0, 0, -1], [1, 0, -1]])
    for t in (-1.0, 0.0, 3.0, 9.0):
        np.testing.assert_allclose(path.sample(t).velocity, 0.0, atol=1e-12)
    for t in (-1.0, 3.0, 9.0):  # at rest; the jerk of a min-jerk move steps at its start
        np.testing.assert_array_equal(path.sample(t).jerk, 0.0)
    np.testing.assert_allclose(path.sample(-1.0).position, [0, 0, -1])
    np.testing.assert_allclose(path.sample(9.0).position, [1, 0, -1])


def test_a_yaw_column_across_180_degrees_turns_the_short_way(tmp_path: Path) -> None:
    path = tmp_path / "wp.csv"
    # 170 deg to -170 deg: 20 deg through south, not 340 deg back through north
    path.write_text(f"t,x,y,z,yaw\n0,0,0,-1,{math.radians(170)}\n4,1,0,-1,"
                    f"{math.radians(-170)}\n")
    raw = load_waypoints(path)
    assert not raw.free_heading
    assert math.degrees(raw.sample(2.0).yaw) % 360 == pytest.approx(180.0)
    assert raw.sample(2.0).yaw_rate == pytest.approx(math.radians(20) / 4)
    shaped = min_jerk_path(raw)
    yaws = [math.degrees(shaped.sample(t).yaw) for t in np.linspace(0, 4, 41)]
    assert yaws[0] == pytest.approx(170) and yaws[-1] == pytest.approx(190)
    assert all(b >= a for a, b in itertools.pairwise(yaws))  # one way, 20 deg
    assert math.degrees(shaped.sample(2.0).yaw_rate) == pytest.approx(1.875 * 20 / 4)


# ---------------------------------------------------------------- easing (time warp)
def test_eased_figure_eight_starts_and_ends_at_rest_and_is_the_raw_one_in_between() -> None:
    # the eight: 1.2 m x 0.6 m in 8 s starts at sqrt(2) a w = 0.67 m/s
    raw = FigureEight([0, 0, -1], width_m=1.2, period_s=8.0)
    assert np.linalg.norm(raw.sample(0.0).velocity) == pytest.approx(
        math.sqrt(2) * 0.6 * 2 * math.pi / 8.0)
    max_accel = 9.82 * math.tan(math.radians(20.0))
    eased, duration = shape_for_flight(raw, 8.0, max_accel)
    assert isinstance(eased, TimeWarp) and not eased.periodic
    ramp = eased.ramp_s
    assert duration == pytest.approx(8.0 + ramp)
    for t in (-1.0, 0.0, duration, duration + 2.0):
        ref = eased.sample(t)
        np.testing.assert_allclose(ref.velocity, 0.0, atol=1e-12)
        np.testing.assert_allclose(ref.acceleration, 0.0, atol=1e-12)
    np.testing.assert_allclose(eased.sample(0.0).position, raw.sample(0.0).position)
    np.testing.assert_allclose(eased.sample(duration).position, raw.sample(8.0).position,
                               atol=1e-12)
    # between the ramps: the raw eight, half a ramp late (the ramp's clock gains R/2)
    for t in np.linspace(ramp, duration - ramp, 17):
        a, b = eased.sample(float(t)), raw.sample(float(t) - 0.5 * ramp)
        np.testing.assert_allclose(a.position, b.position, atol=1e-12)
        np.testing.assert_allclose(a.velocity, b.velocity, atol=1e-12)
        np.testing.assert_allclose(a.jerk, b.jerk, atol=1e-12)
    # the easing's extra acceleration fits in the tilt's budget
    acc = [np.linalg.norm(eased.sample(float(t)).acceleration)
           for t in np.linspace(0, duration, 2001)]
    assert max(acc) < 0.9 * max_accel


def test_shaping_leaves_what_is_already_at_rest_and_knots_paths() -> None:
    max_accel = 3.0
    hover = Hover([0, 0, -1], step=[0.3, 0, 0])
    assert shape_for_flight(hover, 20.0, max_accel) == (hover, 20.0)  # a step is the test
    turn = YawTurn([0, 0, -1], period_s=20.0)
    assert shape_for_flight(turn, 20.0, max_accel) == (turn, 20.0)
    shaped, duration = shape_for_flight(square(), 20.0, max_accel)
    assert isinstance(shaped, MinJerkPath) and duration == 20.0
    # cut mid-edge, the shaped square is eased out as well
    cut, duration = shape_for_flight(square(), 22.5, max_accel)
    assert isinstance(cut, TimeWarp) and duration > 22.5
    np.testing.assert_allclose(cut.sample(duration).velocity, 0.0, atol=1e-12)


# ---------------------------------------------------------------- headings
def test_heading_is_free_unless_given() -> None:
    for name in ("hover", "square", "figure-eight", "yaw-turn", "step-x"):
        traj = make_trajectory(name)
        assert traj.free_heading and traj.sample(0.0).yaw == 0.0, name
        fixed = make_trajectory(name, yaw=1.0)
        assert not fixed.free_heading and fixed.sample(0.0).yaw == pytest.approx(1.0), name
    cfg = TrajectoryConfig(name="square", yaw_deg=90.0)
    sq = build_trajectory(trajectory_spec(cfg))
    assert not sq.free_heading and sq.sample(3.0).yaw == pytest.approx(math.pi / 2)
    assert build_trajectory(trajectory_spec(TrajectoryConfig(name="square"))).free_heading


def test_a_waypoint_yaw_column_is_absolute_and_without_one_yaw_deg_applies(
        tmp_path: Path) -> None:
    with_yaw, without = tmp_path / "a.csv", tmp_path / "b.csv"
    with_yaw.write_text("0,0,0,-1,0.5\n2,1,0,-1,0.5\n")
    without.write_text("0,0,0,-1\n2,1,0,-1\n")
    a = build_trajectory(trajectory_spec(TrajectoryConfig(name="waypoints", file=with_yaw)))
    assert not a.free_heading and a.sample(1.0).yaw == pytest.approx(0.5)
    b = build_trajectory(trajectory_spec(TrajectoryConfig(name="waypoints", file=without)))
    assert b.free_heading
    c = build_trajectory(trajectory_spec(TrajectoryConfig(name="waypoints", file=without,
                                                          yaw_deg=-45.0)))
    assert not c.free_heading and c.sample(1.0).yaw == pytest.approx(-math.pi / 4)


def test_yaw_turn_holds_the_centre_and_turns_with_a_min_jerk_profile() -> None:
    cfg = TrajectoryConfig(name="yaw-turn", yaw_turn_deg=270.0, period_s=12.0,
                           center=[0.2, -0.1, -1.2])
    turn = build_trajectory(trajectory_spec(cfg))
    assert turn.free_heading and turn.duration == 12.0 and not turn.periodic
    for t in (0.0, 3.0, 6.0, 9.5, 12.0, 15.0):
        ref = turn.sample(t)
        np.testing.assert_allclose(ref.position, [0.2, -0.1, -1.2])
        np.testing.assert_allclose(ref.velocity, 0.0)
        x = min(t / 12.0, 1.0)
        assert math.degrees(ref.yaw) == pytest.approx(270.0 * quintic_smoothstep(x))
    assert math.degrees(turn.sample(6.0).yaw_rate) == pytest.approx(1.875 * 270 / 12)
    start = build_trajectory(trajectory_spec(cfg.model_copy(update={"yaw_deg": 30.0})))
    assert not start.free_heading
    assert math.degrees(start.sample(0.0).yaw) == pytest.approx(30.0)
    assert math.degrees(start.sample(12.0).yaw) == pytest.approx(300.0)
