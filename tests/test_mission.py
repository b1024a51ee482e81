"""Mission references: min-jerk take-off path and heading, tracking clock paused by HOLD,
headings held in HOLD and LAND, landing below ground, preview without side effects."""

from __future__ import annotations

import math

import numpy as np
import pytest

from groundstation.config import SafetyConfig, SerialConfig
from groundstation.control.trajectory import YawTurn
from groundstation.flight.assembly import mission_params
from groundstation.flight.mission import CREEP_RAMP_S, Mission
from groundstation.flight.supervisor import State
from groundstation.types import Reference

START = np.array([0.375, -0.375, -1.0])


class Line:
    """A trajectory moving north at 0.1 m/s from START (heading free or absolute)."""

    name, duration, periodic = "line", 10.0, False

    def __init__(self, yaw: float | None = None) -> None:
        self.free_heading = yaw is None
        self._yaw = 0.0 if yaw is None else yaw

    def sample(self, t: float) -> Reference:
        return Reference(t, START + np.array([0.1 * t, 0.0, 0.0]), np.array([0.1, 0.0, 0.0]),
                         yaw=self._yaw)


def min_jerk(x: float) -> float:
    """Rest-to-rest min-jerk profile 10 x^3 - 15 x^4 + 6 x^5 (Flash and Hogan), clamped."""
    x = min(max(x, 0.0), 1.0)
    return 10 * x**3 - 15 * x**4 + 6 * x**5


def duration(distance: float, speed: float, accel: float, jerk: float = 2.0) -> float:
    """A move's duration: as long as at the constant ``speed``, or longer if its peak
    acceleration 10/sqrt(3) d/T^2 would exceed ``accel`` or its peak jerk 60 d/T^3 the
    mission's 2 m/s^3."""
    return max(distance / speed, math.sqrt(10 / math.sqrt(3) * distance / accel),
               (60.0 * distance / jerk) ** (1.0 / 3.0))


def turn_duration(angle: float, rate: float, accel: float) -> float:
    """A heading turn's duration: peak rate 15/8 d/T within ``rate``."""
    return max(1.875 * angle / rate, math.sqrt(10 / math.sqrt(3) * angle / accel))


def test_takeoff_climbs_vertically_then_moves_to_the_start() -> None:
    m = Mission(Line(), duration_s=10.0, climb_speed=0.5)
    m.enter(State.TAKEOFF, 100.0, np.zeros(3), 0.0)
    climb = duration(1.0, 0.5, 0.5)  # 3.40 s: the acceleration limit binds
    assert climb == pytest.approx(3.398, abs=1e-3)
    # a 3 mm move lasts 0.45 s, not the 0.19 s the acceleration alone allows: its jerk,
    # a tilt rate j / g, stays at 2 m/s^3 (0.2 rad/s)
    assert duration(0.003, 0.5, 0.5) == pytest.approx(0.4481, abs=1e-4)
    for tau in (0.5, 1.0, 1.7, 2.5, climb):
        ref = m.reference(100.0 + tau)
        np.testing.assert_allclose(ref.position, [0, 0, -min_jerk(tau / climb)], atol=1e-12)
    side = float(np.hypot(0.375, 0.375))  # 0.53 m sideways
    move = duration(side, 0.5, 0.5)  # 2.54 s: the jerk limit binds
    ref = m.reference(100.0 + climb + 1.0)
    np.testing.assert_allclose(ref.position, [*(min_jerk(1.0 / move) * START[:2]), -1.0],
                               atol=1e-12)
    assert not m.takeoff_done(100.0 + climb + 1.0, ref.position)
    end = 100.0 + climb + move
    np.testing.assert_allclose(m.reference(end).position, START, atol=1e-12)
    np.testing.assert_allclose(m.reference(end).velocity, 0.0, atol=1e-12)
    assert m.takeoff_done(end, START + 0.05)
    assert not m.takeoff_done(end, START + 0.2)  # reference there, vehicle not yet


def test_the_configured_acceleration_limit_and_speeds_set_the_take_off_and_the_landing(
        ) -> None:
    """``safety.takeoff_land_accel_m_s2`` through the assembly: at the default 0.5 m/s^2 a 1 m
    climb takes 3.40 s whatever ``takeoff_speed_m_s`` above 0.29 m/s says; at 1 m/s^2 and
    1 m/s, 2.47 s (the jerk limit, 4 m/s^3, binds), and a 1.1 m landing at 0.5 m/s 2.55 s."""
    for accel, climb_speed, land_speed in ((0.5, 0.5, 0.3), (0.5, 1.0, 0.3),
                                            (1.0, 1.0, 0.5)):
        safety = SafetyConfig(takeoff_land_accel_m_s2=accel, takeoff_speed_m_s=climb_speed,
                              land_speed_m_s=land_speed)
        m = Mission.from_params(Line(), 10.0, mission_params(safety, SerialConfig()))
        spool = SerialConfig().handover_blend_s
        m.enter(State.TAKEOFF, 0.0, np.array([*START[:2], 0.0]), 0.0)  # straight up
        climb = duration(1.0, climb_speed, accel, 4.0 * accel)
        assert climb == pytest.approx({0.5: 3.398, 1.0: 2.466}[accel], abs=1e-3)
        np.testing.assert_allclose(m.reference(spool + 0.5 * climb).position[2], -0.5,
                                   atol=1e-12)  # halfway at half the time (symmetric)
        assert not m.takeoff_done(spool + climb - 0.01, START)
        assert m.takeoff_done(spool + climb, START)
        m.enter(State.LAND, 50.0, START, 0.0)
        land = duration(1.1, land_speed, accel, 4.0 * accel)  # 0.1 m below the floor
        assert land == pytest.approx({0.5: 3.667, 1.0: 2.546}[accel], abs=1e-3)
        np.testing.assert_allclose(m.reference(50.0 + land).position[2], 0.1, atol=1e-12)
        np.testing.assert_allclose(m.reference(50.0 + 0.5 * land).position[2], -0.45,
                                   atol=1e-12)


def fd_check(m: Mission, t: float, h: float = 1e-3) -> None:
    """Velocity, acceleration and jerk against central differences of the positions, the
    heading rate against those of the heading (phases other than TRACK: no clock)."""
    p = {k: m.reference(t + k * h).position for k in (-2, -1, 0, 1, 2)}
    yaw = {k: m.reference(t + k * h).yaw for k in (-1, 1)}
    ref = m.reference(t)
    np.testing.assert_allclose(ref.velocity, (p[1] - p[-1]) / (2 * h), atol=1e-6)
    np.testing.assert_allclose(ref.acceleration, (p[1] - 2 * p[0] + p[-1]) / h**2, atol=1e-5)
    jerk = (p[2] - 2 * p[1] + 2 * p[-1] - p[-2]) / (2 * h**3)
    np.testing.assert_allclose(ref.jerk, jerk, atol=1e-3)
    assert ref.yaw_rate == pytest.approx((yaw[1] - yaw[-1]) / (2 * h), abs=1e-6)


@pytest.mark.parametrize("t", [1.3, 2.9, 4.4, 5.0, 6.2, 7.1, 8.8])
def test_takeoff_derivatives_are_exact(t: float) -> None:
    m = Mission(Line(yaw=2.0), duration_s=10.0, climb_speed=0.5, spool_s=0.5)
    m.enter(State.TAKEOFF, 0.0, np.array([0.1, 0.2, -0.02]), -1.0)  # turns 3 rad
    fd_check(m, t)


@pytest.mark.parametrize("t", [5.3, 6.0, 7.7, 9.1])
def test_landing_derivatives_are_exact(t: float) -> None:
    m = Mission(Line(), duration_s=10.0, land_speed=0.3)
    m.enter(State.TAKEOFF, 0.0, np.zeros(3), 0.0)
    m.enter(State.LAND, 5.0, np.array([0.3, 0.1, -1.0]), 0.5)
    fd_check(m, t)


def test_reference_acceleration_is_continuous_and_within_the_limit() -> None:
    m = Mission(Line(), duration_s=10.0, climb_speed=0.5)
    m.enter(State.TAKEOFF, 0.0, np.zeros(3), 0.0)
    times = np.arange(0.0, 8.0, 0.01)
    acc = np.array([m.reference(t).acceleration for t in times])
    assert np.linalg.norm(acc, axis=1).max() <= 0.5 + 1e-9
    # no step: successive samples differ by at most the peak jerk (60 d / T^3) times dt
    side = float(np.hypot(0.375, 0.375))
    jerk = max(60 * 1.0 / duration(1.0, 0.5, 0.5) ** 3, 60 * side / duration(side, 0.5, 0.5) ** 3)
    assert np.linalg.norm(np.diff(acc, axis=0), axis=1).max() <= jerk * 0.01 + 1e-12


def test_takeoff_waits_on_the_ground_while_the_thrust_spools_up() -> None:
    m = Mission(Line(), duration_s=10.0, climb_speed=0.5, spool_s=1.0)
    m.enter(State.TAKEOFF, 100.0, np.zeros(3), 0.0)
    np.testing.assert_allclose(m.reference(100.9).position, 0.0, atol=1e-12)
    np.testing.assert_allclose(m.reference(100.9).velocity, 0.0, atol=1e-12)
    np.testing.assert_allclose(m.reference(102.0).position,
                               [0, 0, -min_jerk(1.0 / duration(1.0, 0.5, 0.5))], atol=1e-12)


def test_takeoff_turns_the_short_way_to_an_absolute_heading() -> None:
    # placed at 170 deg, the trajectory flies at -170 deg: 20 deg on through south
    m = Mission(Line(yaw=math.radians(-170)), duration_s=10.0, climb_speed=0.5,
                max_yaw_rate=math.radians(90), yaw_accel=1.0)
    m.enter(State.TAKEOFF, 0.0, np.zeros(3), math.radians(170))
    climb = duration(1.0, 0.5, 0.5)
    turn = turn_duration(math.radians(20), math.radians(90), 1.0)
    for t in (0.0, 2.0, climb):  # the heading holds until the top of the climb
        assert math.degrees(m.reference(t).yaw) == pytest.approx(170)
    for tau in (0.3, 0.8, turn):
        assert math.degrees(m.reference(climb + tau).yaw) == pytest.approx(
            170 + 20 * min_jerk(tau / turn))
    rates = [abs(m.reference(t).yaw_rate) for t in np.arange(0, 10, 0.01)]
    assert max(rates) <= math.radians(90) + 1e-9
    end = climb + duration(float(np.hypot(0.375, 0.375)), 0.5, 0.5)
    assert m.takeoff_done(end, START)
    # TRACK continues the heading without a jump: -170 deg + 360 deg
    m.enter(State.TRACK, end, START, m.reference(end).yaw)
    assert math.degrees(m.reference(end + 1.0).yaw) == pytest.approx(190)
    assert math.degrees(m.heading_offset) == pytest.approx(360)


def test_a_free_heading_keeps_the_heading_at_takeoff() -> None:
    m = Mission(YawTurn(START, turn=math.pi / 2, period_s=4.0), duration_s=4.0)
    m.enter(State.TAKEOFF, 0.0, np.zeros(3), 1.0)
    for t in np.arange(0.0, 12.0, 0.5):
        ref = m.reference(float(t))
        assert ref.yaw == pytest.approx(1.0) and ref.yaw_rate == 0.0
    m.enter(State.TRACK, 12.0, START, 1.0)
    m.reference(12.0)
    ref = m.reference(14.0)  # half-way through the turn, relative to the take-off heading
    assert ref.yaw == pytest.approx(1.0 + math.pi / 4)
    assert ref.yaw_rate == pytest.approx(1.875 * (math.pi / 2) / 4.0)


def test_hold_and_land_keep_the_heading_they_began_with() -> None:
    m = Mission(YawTurn(START, turn=math.pi, period_s=4.0), duration_s=4.0)
    m.enter(State.TAKEOFF, 0.0, np.zeros(3), 0.0)
    m.enter(State.TRACK, 10.0, START, 0.0)
    m.reference(10.0)
    m.reference(11.0)
    m.enter(State.HOLD, 11.0, START, 0.3)  # the vehicle's heading, not the reference's
    for t in (11.0, 12.5):
        ref = m.reference(t)
        assert (ref.yaw, ref.yaw_rate) == (0.3, 0.0)
        np.testing.assert_allclose(ref.position, START)
    m.enter(State.LAND, 13.0, START, -2.5)
    for t in (13.0, 15.0, 30.0):
        ref = m.reference(t)
        assert (ref.yaw, ref.yaw_rate) == (-2.5, 0.0)


def test_track_clock_pauses_in_hold_and_ends_after_duration() -> None:
    m = Mission(Line(), duration_s=2.0)
    m.enter(State.TRACK, 10.0, START, 0.0)
    m.reference(10.0)
    ref = m.reference(11.0)
    np.testing.assert_allclose(ref.position, START + np.array([0.1, 0.0, 0.0]))
    m.enter(State.HOLD, 11.0, np.array([1.0, 2.0, -1.0]), 0.0)
    hold = m.reference(11.5)
    np.testing.assert_allclose(hold.position, [1.0, 2.0, -1.0])
    np.testing.assert_allclose(hold.velocity, 0.0)
    m.enter(State.TRACK, 12.0, START, 0.0)
    assert m.reference(12.0).t == pytest.approx(1.0)  # paused for the whole hold
    assert not m.trajectory_done()
    m.reference(13.0)
    assert m.trajectory_done()


def test_takeoff_resumed_after_a_hold_goes_on_from_where_the_vehicle_is() -> None:
    m = Mission(Line(), duration_s=10.0, climb_speed=0.5, spool_s=1.0)
    m.enter(State.TAKEOFF, 0.0, np.array([0.0, 0.0, -0.02]), 0.0)
    m.enter(State.HOLD, 2.5, np.array([0.0, 0.0, -0.4]), 0.2)
    m.enter(State.TAKEOFF, 4.0, np.array([0.0, 0.0, -0.4]), 0.2)
    np.testing.assert_allclose(m.ground, [0.0, 0.0, -0.02])  # still the floor
    np.testing.assert_allclose(m.reference(4.0).position, [0.0, 0.0, -0.4])  # no spool
    climb = duration(0.6, 0.5, 0.5)
    np.testing.assert_allclose(m.reference(4.0 + 0.5 * climb).position, [0, 0, -0.7],
                               atol=1e-12)
    assert m.reference(4.0).yaw == pytest.approx(0.2)  # turns back from where it points
    assert m.reference(30.0).yaw == pytest.approx(0.0)


def test_land_descends_to_below_the_ground() -> None:
    m = Mission(Line(), duration_s=1.0, land_speed=0.25, touchdown_depth=0.1)
    m.enter(State.TAKEOFF, 0.0, np.array([0.0, 0.0, -0.02]), 0.0)
    m.enter(State.LAND, 5.0, np.array([0.3, 0.1, -1.0]), 0.0)
    descent = duration(1.08, 0.25, 0.5)  # to 0.1 m below the ground at z = -0.02
    assert descent == pytest.approx(1.08 / 0.25)  # as long as at the landing speed
    ref = m.reference(5.0 + 0.5 * descent)
    np.testing.assert_allclose(ref.position, [0.3, 0.1, -1.0 + 0.54])
    np.testing.assert_allclose(ref.velocity, [0.0, 0.0, 1.875 * 0.25])  # the peak, mid-way
    end = 5.0 + descent
    np.testing.assert_allclose(m.reference(end).position, [0.3, 0.1, 0.08])
    # then it creeps on down, its speed eased in over CREEP_RAMP_S, until the supervisor
    # has evidence of the floor (a drifting height estimate never hovers "on" it)
    ramp, creep = CREEP_RAMP_S, 0.15
    mid = m.reference(end + 0.5 * ramp)
    assert mid.velocity[2] == pytest.approx(0.5 * creep)  # the smoothstep's middle
    # the smoothstep integral from 0 to 1/2: 10/64 - 15/160 + 6/384 = 5/64
    assert mid.position[2] == pytest.approx(0.08 + creep * ramp * 5.0 / 64.0)
    later = m.reference(end + ramp + 2.0)
    np.testing.assert_allclose(later.velocity, [0.0, 0.0, creep])
    np.testing.assert_allclose(later.position, [0.3, 0.1, 0.08 + creep * (0.5 * ramp + 2.0)])
    np.testing.assert_allclose(later.acceleration, 0.0, atol=1e-15)
    m.enter(State.DISARM, 61.0, np.array([0.31, 0.12, 0.0]), 0.0)  # on the floor where it landed
    np.testing.assert_allclose(m.reference(61.5).position, [0.31, 0.12, 0.0])


def same(a: Reference, b: Reference) -> None:
    assert a.t == pytest.approx(b.t) and a.yaw == pytest.approx(b.yaw)
    assert a.yaw_rate == pytest.approx(b.yaw_rate)
    for field in ("position", "velocity", "acceleration", "jerk"):
        np.testing.assert_allclose(getattr(a, field), getattr(b, field), atol=1e-12)


@pytest.mark.parametrize("state", [State.TAKEOFF, State.TRACK, State.HOLD, State.LAND])
def test_preview_is_the_reference_at_t_plus_lead_without_side_effects(state: State) -> None:
    def mission() -> Mission:
        m = Mission(YawTurn(START, turn=1.0, period_s=6.0), duration_s=6.0, spool_s=0.5)
        m.enter(State.TAKEOFF, 0.0, np.zeros(3), 0.4)
        if state is not State.TAKEOFF:
            m.enter(state, 8.0, START, 0.4)
        m.reference(8.0)
        m.reference(9.5)
        return m

    lead = 0.13
    m = mission()
    ahead = m.preview(9.5, lead)
    same(m.preview(9.5, lead), ahead)  # repeatable ...
    same(m.reference(9.6), mission().reference(9.6))  # ... and changes nothing
    same(ahead, mission().reference(9.5 + lead))


def test_a_tiny_takeoff_move_stays_gentle() -> None:
    """Placed 3 mm from the start's x/y: the horizontal move must not ask for the tilt
    rate of a 0.19 s min-jerk move (35-60 m/s^3 of jerk saturated the rate sticks at the
    first TRACK tick in the virtual lab): its jerk stays within 2 m/s^3."""
    m = Mission(Line(), duration_s=10.0, climb_speed=0.5)
    m.enter(State.TAKEOFF, 0.0, START - np.array([0.003, 0.0, -1.0]), 0.0)
    jerks = [np.linalg.norm(m.reference(t).jerk[:2]) for t in np.arange(0.0, 8.0, 0.005)]
    assert 0.1 < max(jerks) <= 2.0 + 1e-9
