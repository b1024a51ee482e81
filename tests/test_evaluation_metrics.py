"""Evaluation metrics on synthetic signals with known answers.

Expected values are closed forms: a pure delay gives its delay as lag; a
first-order step response settles to 2 % at tau ln 50 without overshoot; a
second-order one overshoots by exp(-zeta pi / sqrt(1 - zeta^2)); a constant
offset gives its own length as RMS and maximum; a roll-only quaternion has the
roll as tilt; a point's distance to a square is the Euclidean distance to the
square's boundary (outside: the norm of the excess over the half-side per axis,
inside: the half-side less the larger coordinate); a circle of radius R + e is
e off a circle of radius R; a quaternion built from Euler angles has their yaw as
heading.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from groundstation.evaluation.metrics import (
    PATH_SEGMENT_M,
    heading_deg,
    lag_s,
    lap_mean,
    moving_axes,
    path_distances,
    percentiles,
    resample,
    rms,
    step_figures,
    tilt_deg,
    track_clock,
    tracking_errors,
    wrap_deg,
)
from groundstation.model.quaternion import quat_from_euler


def circle(t: np.ndarray, period: float = 20.0, radius: float = 0.4) -> np.ndarray:
    w = 2 * math.pi / period
    return np.column_stack([radius * np.cos(w * t), radius * np.sin(w * t), -np.ones_like(t)])


@pytest.mark.slow
def test_pure_delay_of_half_a_second_gives_lag_half_a_second() -> None:
    t = np.arange(0.0, 60.0, 0.01)
    ref = circle(t)
    path = circle(t - 0.5)  # the same path 0.5 s later
    assert lag_s(t, path, ref) == pytest.approx(0.5, abs=1e-3)
    assert lag_s(t, ref, path) == pytest.approx(-0.5, abs=1e-3)  # ahead is negative
    assert lag_s(t, ref, ref) == pytest.approx(0.0, abs=1e-9)


@pytest.mark.slow
def test_lag_resolves_below_one_sample_by_parabolic_interpolation() -> None:
    t = np.arange(0.0, 60.0, 0.01)
    lag = lag_s(t, circle(t - 0.234), circle(t))  # 23.4 samples
    assert lag == pytest.approx(0.234, abs=0.002)  # well below the 10 ms sample
    assert abs(lag - 0.23) > 0.002 and abs(lag - 0.24) > 0.002


@pytest.mark.slow
def test_lag_on_jittered_tick_times_is_resampled() -> None:
    # Real-time ticks are not evenly spaced: +-3 ms of jitter on a 10 ms schedule.
    rng = np.random.default_rng(3)
    t = np.arange(0.0, 60.0, 0.01) + rng.uniform(-0.003, 0.003, 6000)
    t.sort()
    assert lag_s(t, circle(t - 0.5), circle(t)) == pytest.approx(0.5, abs=2e-3)


def test_lag_of_a_hover_is_not_a_number() -> None:
    t = np.arange(0.0, 20.0, 0.01)
    ref = np.tile([0.0, 0.0, -1.0], (len(t), 1))
    path = ref + 0.005 * np.sin(t)[:, None]
    assert moving_axes(ref) == []
    assert math.isnan(lag_s(t, path, ref))


def test_lag_uses_only_the_moving_axes() -> None:
    # x moves, y and z hold; noise on y must not bias the x lag.
    t = np.arange(0.0, 60.0, 0.01)
    ref = np.column_stack([0.3 * np.sin(2 * math.pi * t / 10), np.zeros_like(t), -np.ones_like(t)])
    path = np.column_stack([0.3 * np.sin(2 * math.pi * (t - 0.7) / 10),
                            0.005 * np.random.default_rng(1).normal(size=len(t)),
                            -np.ones_like(t)])
    assert moving_axes(ref) == [0]
    assert lag_s(t, path, ref) == pytest.approx(0.7, abs=2e-3)


def test_first_order_step_settles_at_tau_ln50_without_overshoot() -> None:
    tau, t_step = 0.4, 1.0
    t = np.arange(0.0, 8.0, 0.001)
    y = np.where(t < t_step, 0.2, 0.2 + 0.5 * (1 - np.exp(-(t - t_step) / tau)))
    m = step_figures(t, y, t_step=t_step, initial=0.2, final=0.7)
    assert m["overshoot_pct"] == 0.0
    # |y - final| = 0.5 exp(-t/tau) <= 0.02 * 0.5  <=>  t >= tau ln 50
    assert m["settling_s"] == pytest.approx(tau * math.log(50.0), abs=0.002)
    assert m["rise_s"] == pytest.approx(tau * math.log(9.0), abs=0.002)  # 10 % -> 90 %
    assert abs(m["steady_state_m"]) < 1e-6


@pytest.mark.parametrize("zeta", [0.3, 0.5, 0.7])
def test_second_order_step_overshoot_is_the_closed_form(zeta: float) -> None:
    wn, t_step = 3.0, 0.5
    wd = wn * math.sqrt(1 - zeta**2)
    t = np.arange(0.0, 12.0, 0.0005)
    tau = np.clip(t - t_step, 0.0, None)
    s = 1 - np.exp(-zeta * wn * tau) * (np.cos(wd * tau) + zeta / math.sqrt(1 - zeta**2)
                                        * np.sin(wd * tau))
    y = -1.0 - 0.5 * s  # a 0.5 m step up in NED: z from -1.0 to -1.5
    m = step_figures(t, y, t_step=t_step, initial=-1.0, final=-1.5)
    expected = 100 * math.exp(-zeta * math.pi / math.sqrt(1 - zeta**2))
    assert m["overshoot_pct"] == pytest.approx(expected, rel=1e-3)
    # the envelope exp(-zeta wn t) / sqrt(1 - zeta^2) bounds the settling time from above
    bound = math.log(1 / (0.02 * math.sqrt(1 - zeta**2))) / (zeta * wn)
    assert 0.5 * bound < m["settling_s"] <= bound + 1e-3


def test_tracking_errors_of_a_constant_offset() -> None:
    ref = np.zeros((100, 3))
    path = ref + np.array([0.03, -0.04, 0.0])  # 3-4-5 triangle: 5 cm everywhere
    e = tracking_errors(path, ref)
    assert e["rms_m"] == pytest.approx(0.05) and e["max_m"] == pytest.approx(0.05)
    assert (e["rms_x_m"], e["rms_y_m"], e["rms_z_m"]) == pytest.approx((0.03, 0.04, 0.0))
    assert all(math.isnan(v) for v in tracking_errors(path[:0], ref[:0]).values())
    assert rms(np.array([3.0, 4.0])) == pytest.approx(math.sqrt(12.5))


def test_tilt_of_roll_and_pitch() -> None:
    q = np.array([quat_from_euler(math.radians(10), 0.0, math.radians(50)),
                  quat_from_euler(math.radians(10), math.radians(20), 0.0),
                  [1.0, 0.0, 0.0, 0.0]])
    # yaw does not tilt; roll then pitch: cos(tilt) = cos(roll) cos(pitch)
    expected = [10.0, math.degrees(math.acos(math.cos(math.radians(10))
                                             * math.cos(math.radians(20)))), 0.0]
    assert tilt_deg(q) == pytest.approx(expected, abs=1e-9)


def test_track_clock_pauses_outside_tracking() -> None:
    t = np.arange(0.0, 1.0, 0.1)
    active = np.array([0, 1, 1, 1, 0, 0, 1, 1, 1, 0], dtype=bool)  # a HOLD in the middle
    clock = track_clock(t, active)
    assert clock == pytest.approx([0, 0, 0.1, 0.2, 0.2, 0.2, 0.2, 0.3, 0.4, 0.4])


def test_lap_mean_of_a_periodic_path_is_the_path() -> None:
    t = np.arange(0.0, 60.0, 0.01)
    path = circle(t) + np.array([[0.01, 0.0, 0.0]]) * (t // 20.0)[:, None]  # lap k: +k cm
    phase, mean = lap_mean(t, path, 20.0, laps=2, first=1)  # laps 1 and 2: +1, +2 cm
    assert mean == pytest.approx(circle(phase) + np.array([0.015, 0.0, 0.0]), abs=1e-4)


def test_percentiles_ignore_missing_values() -> None:
    v = np.array([np.nan, *range(1, 101)], dtype=float)
    p50, p99, worst = percentiles(v, scale=2.0)
    assert (p50, p99, worst) == pytest.approx((101.0, 2 * 99.01, 200.0))
    assert all(math.isnan(x) for x in percentiles(np.array([np.nan])))


def test_resample_is_linear_interpolation() -> None:
    grid, out = resample(np.array([0.0, 1.0, 3.0]), np.array([0.0, 2.0, 6.0]), 0.5)
    assert grid == pytest.approx([0.0, 0.5, 1.0, 1.5, 2.0, 2.5, 3.0])
    assert out[:, 0] == pytest.approx(2 * grid)


def square_distance(p: np.ndarray, h: float) -> np.ndarray:
    """Closed form: distance of (N, 2) points to the boundary of the square |x|, |y| <= h."""
    a = np.abs(p)
    outside = np.linalg.norm(np.clip(a - h, 0.0, None), axis=1)
    inside = h - np.max(a, axis=1)
    return np.asarray(np.where(np.all(a <= h, axis=1), inside, outside))


def test_distance_to_a_square_path_is_the_closed_form() -> None:
    h = 0.375
    corners = np.array([[h, -h], [h, h], [-h, h], [-h, -h], [h, -h]])  # the Ch. 11 square
    points = np.random.default_rng(7).uniform(-0.6, 0.6, size=(2000, 2))
    points = np.vstack([points, [[0.5, 0.5], [h, h], [0.0, 0.0], [h + 0.01, 0.0]]])
    d = path_distances(points, corners)
    assert d == pytest.approx(square_distance(points, h), abs=1e-12)
    assert d[-4:] == pytest.approx([math.hypot(0.125, 0.125), 0.0, h, 0.01], abs=1e-12)


def test_distance_to_a_densely_sampled_path_does_not_depend_on_the_sampling() -> None:
    # the square as 10 ms reference samples at 0.15 m/s (repeated vertices where it would
    # stand) gives the same distances as its four corners
    h = 0.375
    t = np.arange(0.0, 20.0 + 1e-9, 0.01)
    corners = np.array([[h, -h], [h, h], [-h, h], [-h, -h], [h, -h]])
    dense = np.column_stack([np.interp(t, np.linspace(0.0, 20.0, 5), corners[:, k])
                             for k in range(2)])
    dense = np.vstack([dense[:100], np.repeat(dense[100:101], 50, axis=0), dense[100:]])
    points = np.random.default_rng(8).uniform(-0.5, 0.5, size=(500, 2))
    assert path_distances(points, dense) == pytest.approx(square_distance(points, h), abs=1e-12)


def test_distance_off_a_circle() -> None:
    # a circle of radius R + e flown against one of radius R: e everywhere, up to the chord
    # sagitta R (1 - cos(dtheta / 2)) of the sampled reference
    radius, e, n = 0.4, 0.01, 2000
    theta = np.linspace(0.0, 2 * math.pi, n + 1)
    ref = np.column_stack([radius * np.cos(theta), radius * np.sin(theta), -np.ones_like(theta)])
    phase = theta[:-1] + 0.37  # any timing: the distance to the path ignores it
    flown = np.column_stack([(radius + e) * np.cos(phase), (radius + e) * np.sin(phase),
                             -np.ones_like(phase)])
    sagitta = radius * (1 - math.cos(math.pi / n))
    d = path_distances(flown, ref)
    assert np.all(d >= e - 1e-12) and np.all(d <= e + sagitta + 1e-12)
    assert rms(d) == pytest.approx(e, abs=sagitta)


def test_distance_to_a_long_segment_and_to_a_single_point() -> None:
    segment = np.array([[0.0, 0.0, -1.0], [2.0, 0.0, -1.0]])  # split into 5 mm pieces
    assert 2.0 / PATH_SEGMENT_M > 100
    points = np.array([[1.2345, 0.03, -1.0], [-0.03, 0.04, -1.0], [2.0, 0.0, -1.2]])
    assert path_distances(points, segment) == pytest.approx([0.03, 0.05, 0.2], abs=1e-12)
    hover = np.tile([0.0, 0.0, -1.0], (300, 1))
    assert path_distances(points[:2], hover) == pytest.approx(
        [math.hypot(1.2345, 0.03), 0.05], abs=1e-12)


@pytest.mark.parametrize("yaw_deg", [0.0, 90.0, 135.0, 179.0, -135.0, -30.0])
def test_heading_is_the_euler_yaw(yaw_deg: float) -> None:
    q = np.array([quat_from_euler(math.radians(r), math.radians(p), math.radians(yaw_deg))
                  for r, p in ((0.0, 0.0), (10.0, -5.0), (-20.0, 15.0))])
    assert heading_deg(q) == pytest.approx([yaw_deg] * 3, abs=1e-9)


def test_wrap_deg() -> None:
    assert wrap_deg(np.array([0.0, 190.0, -190.0, 358.0, 540.0, -180.0])) == pytest.approx(
        [0.0, -170.0, 170.0, -2.0, -180.0, -180.0])
