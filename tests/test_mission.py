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


def test_takeoff_climbs_vertically_then_moves_to_the_start() -> None:
    m = Mission(line, duration_s=10.0, climb_speed=0.5)
    ground = np.array([0.0, 0.0, 0.0])
    m.enter(State.TAKEOFF, 100.0, ground)
    ref = m.reference(101.0)  # 0.5 m climbed, straight up
    np.testing.assert_allclose(ref.position, [0.0, 0.0, -0.5], atol=1e-12)
    np.testing.assert_allclose(ref.velocity, [0.0, 0.0, -0.5], atol=1e-12)
    climb_end = 100.0 + 1.0 / 0.5
    horizontal = np.hypot(0.375, 0.375) / 0.5
    ref = m.reference(climb_end + horizontal / 2)
    np.testing.assert_allclose(ref.position, [0.1875, -0.1875, -1.0], atol=1e-12)
    assert not m.takeoff_done(climb_end + horizontal / 2, ref.position)
    end = climb_end + horizontal + 0.01
    np.testing.assert_allclose(m.reference(end).position, START, atol=1e-12)
    np.testing.assert_allclose(m.reference(end).velocity, 0.0, atol=1e-12)
    assert m.takeoff_done(end, START + 0.05)
    assert not m.takeoff_done(end, START + 0.2)  # reference there, vehicle not yet


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
    np.testing.assert_allclose(m.reference(7.0).position, [0.3, 0.1, -0.5])
    np.testing.assert_allclose(m.reference(7.0).velocity, [0.0, 0.0, 0.25])
    np.testing.assert_allclose(m.reference(60.0).position, [0.3, 0.1, 0.08])
