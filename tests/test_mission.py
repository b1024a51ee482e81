"""Mission references: take-off path, tracking clock paused by HOLD, landing below ground."""

from __future__ import annotations

import numpy as np
import pytest

from groundstation.loop.mission import Mission
from groundstation.loop.supervisor import State
from groundstation.types import Reference

START = np.array([0.375, -0.375, -1.0])


def line(t: float) -> Reference:
    """A trajectory moving north at 0.1 m/s from START."""
    return Reference(t, START + np.array([0.1 * t, 0.0, 0.0]), np.array([0.1, 0.0, 0.0]))


def trapezoid_distance(tau: float, length: float, v: float, a: float) -> float:
    """Closed form of a rest-to-rest trapezoidal profile (independent of the mission)."""
    t_acc, d_acc = v / a, v * v / (2 * a)
    total = 2 * t_acc + (length - 2 * d_acc) / v
    if tau <= t_acc:
        return 0.5 * a * tau**2
    if tau >= total - t_acc:
        return length - 0.5 * a * (total - tau) ** 2
    return d_acc + v * (tau - t_acc)


def test_takeoff_climbs_vertically_then_moves_to_the_start() -> None:
    m = Mission(line, duration_s=10.0, climb_speed=0.5)
    m.enter(State.TAKEOFF, 100.0, np.zeros(3))
    for tau in (0.5, 1.0, 1.7, 2.5):  # climb of 1 m at 0.5 m/s, 0.5 m/s^2
        ref = m.reference(100.0 + tau)
        np.testing.assert_allclose(ref.position, [0, 0, -trapezoid_distance(tau, 1.0, 0.5, 0.5)],
                                   atol=1e-12)
    climb_end = 100.0 + 3.0  # 1 s accelerate, 1 s cruise, 1 s decelerate
    np.testing.assert_allclose(m.reference(climb_end).position, [0.0, 0.0, -1.0], atol=1e-12)
    side = float(np.hypot(0.375, 0.375))  # 0.53 m sideways
    ref = m.reference(climb_end + 1.0)
    expected = trapezoid_distance(1.0, side, 0.5, 0.5) / side * START[:2]
    np.testing.assert_allclose(ref.position, [*expected, -1.0], atol=1e-12)
    assert not m.takeoff_done(climb_end + 1.0, ref.position)
    end = climb_end + 5.0
    np.testing.assert_allclose(m.reference(end).position, START, atol=1e-12)
    np.testing.assert_allclose(m.reference(end).velocity, 0.0, atol=1e-12)
    assert m.takeoff_done(end, START + 0.05)
    assert not m.takeoff_done(end, START + 0.2)  # reference there, vehicle not yet


def test_reference_velocity_never_steps() -> None:
    m = Mission(line, duration_s=10.0, climb_speed=0.5)
    m.enter(State.TAKEOFF, 0.0, np.zeros(3))
    times = np.arange(0.0, 8.0, 0.01)
    vel = np.array([m.reference(t).velocity for t in times])
    accel = np.linalg.norm(np.diff(vel, axis=0), axis=1) / 0.01
    assert accel.max() <= 0.5 + 1e-9  # the profile's acceleration, never a step
    # Numerical derivative of the position equals the velocity (consistency).
    pos = np.array([m.reference(t).position for t in times])
    np.testing.assert_allclose(np.gradient(pos, times, axis=0)[1:-1], vel[1:-1], atol=6e-3)


def test_takeoff_waits_on_the_ground_while_the_thrust_spools_up() -> None:
    m = Mission(line, duration_s=10.0, climb_speed=0.5, spool_s=1.0)
    m.enter(State.TAKEOFF, 100.0, np.zeros(3))
    np.testing.assert_allclose(m.reference(100.9).position, 0.0, atol=1e-12)
    np.testing.assert_allclose(m.reference(100.9).velocity, 0.0, atol=1e-12)
    np.testing.assert_allclose(m.reference(102.0).position, [0.0, 0.0, -0.25], atol=1e-12)


def test_track_clock_pauses_in_hold_and_ends_after_duration() -> None:
    m = Mission(line, duration_s=2.0)
    m.enter(State.TRACK, 10.0, START)
    m.reference(10.0)
    ref = m.reference(11.0)
    np.testing.assert_allclose(ref.position, START + np.array([0.1, 0.0, 0.0]))
    m.enter(State.HOLD, 11.0, np.array([1.0, 2.0, -1.0]))
    hold = m.reference(11.5)
    np.testing.assert_allclose(hold.position, [1.0, 2.0, -1.0])
    np.testing.assert_allclose(hold.velocity, 0.0)
    m.enter(State.TRACK, 12.0, START)
    assert m.reference(12.0).t == pytest.approx(1.0)  # paused for the whole hold
    assert not m.trajectory_done()
    m.reference(13.0)
    assert m.trajectory_done()


def test_land_descends_to_below_the_ground() -> None:
    m = Mission(line, duration_s=1.0, land_speed=0.25, touchdown_depth=0.1)
    m.enter(State.TAKEOFF, 0.0, np.array([0.0, 0.0, -0.02]))
    m.enter(State.LAND, 5.0, np.array([0.3, 0.1, -1.0]))
    # 1.08 m at 0.25 m/s with 0.5 m/s^2: 0.5 s to cruise speed, then 0.25 m/s.
    tau = 2.0
    depth = trapezoid_distance(tau, 1.08, 0.25, 0.5)
    np.testing.assert_allclose(m.reference(5.0 + tau).position, [0.3, 0.1, -1.0 + depth])
    np.testing.assert_allclose(m.reference(5.0 + tau).velocity, [0.0, 0.0, 0.25])
    np.testing.assert_allclose(m.reference(60.0).position, [0.3, 0.1, 0.08])
    m.enter(State.DISARM, 61.0, np.array([0.31, 0.12, 0.0]))  # on the floor where it landed
    np.testing.assert_allclose(m.reference(61.5).position, [0.31, 0.12, 0.0])
