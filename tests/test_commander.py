"""Run-time motions: planning, checks and the book of motions, without a flight.

Independent answers: the boundary conditions a quintic must meet, finite differences of
its samples, the closed-form minimum-jerk profile, the configured limits and volume.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest
from lab_helpers import sim_config

from groundstation.app.api import MotionApi
from groundstation.control.minjerk import smoothstep
from groundstation.flight.assembly import assemble
from groundstation.flight.commander import (
    Commander,
    CommandRefusedError,
    MotionLimits,
    PlanBase,
    QuinticMove,
    Rest,
    plan_follow,
    plan_go_to,
    plan_hold,
    sample_plan,
)
from groundstation.flight.core import FlightCore
from groundstation.flight.supervisor import State

CFG = sim_config(**{"trajectory.name": "none"})
LIMITS: MotionLimits = assemble(CFG).planner.limits
HOME = np.array([0.0, 0.0, -1.0])
GROUND = np.array([0.0, 0.0, 0.0])


def _base(commander: Commander, tau: float, offset: float = 0.0) -> PlanBase:
    return commander.base(tau, offset, "TRACK", GROUND)


def _derivative(f: Any, t: float, h: float = 1e-5) -> np.ndarray:
    return (np.asarray(f(t + h)) - np.asarray(f(t - h))) / (2 * h)


# --------------------------------------------------------------------------- the quintic
def test_a_quintic_meets_its_boundary_conditions_and_its_derivatives_are_exact() -> None:
    p0, v0, a0 = np.array([0.1, -0.2, -1.0, 0.3]), np.array([0.4, 0.1, -0.2, 0.5]), \
        np.array([-0.3, 0.2, 0.1, 0.0])
    p1 = np.array([0.8, 0.5, -1.4, -0.2])
    move = QuinticMove.between(2.0, 3.0, p0, v0, a0, p1)
    start, end = move.sample(2.0), move.sample(5.0)
    assert np.allclose(start.position, p0[:3]) and np.isclose(start.yaw, p0[3])
    assert np.allclose(start.velocity, v0[:3]) and np.isclose(start.yaw_rate, v0[3])
    assert np.allclose(start.acceleration, a0[:3])
    assert np.allclose(end.position, p1[:3]) and np.isclose(end.yaw, p1[3])
    assert np.allclose(end.velocity, 0.0) and np.allclose(end.acceleration, 0.0)
    for t in (2.3, 3.5, 4.9):  # finite differences of position, velocity, acceleration
        ref = move.sample(t)
        assert np.allclose(_derivative(lambda s: move.sample(s).position, t), ref.velocity,
                           atol=1e-6)
        assert np.allclose(_derivative(lambda s: move.sample(s).velocity, t),
                           ref.acceleration, atol=1e-5)
        assert np.allclose(_derivative(lambda s: move.sample(s).acceleration, t), ref.jerk,
                           atol=1e-4)
        assert np.isclose(_derivative(lambda s: move.sample(s).yaw, t), ref.yaw_rate,
                          atol=1e-6)
    # after its end it rests at the target
    assert np.allclose(move.sample(9.0).position, p1[:3])
    assert np.allclose(move.sample(9.0).velocity, 0.0)


def test_from_rest_the_quintic_is_the_minimum_jerk_profile() -> None:
    p0, p1 = np.array([0.0, 0.0, -1.0, 0.0]), np.array([1.0, -0.5, -1.2, 1.0])
    move = QuinticMove.between(0.0, 2.0, p0, np.zeros(4), np.zeros(4), p1)
    for t in np.linspace(0.0, 2.0, 9):
        s = smoothstep(t / 2.0)[0]
        assert np.allclose(move.sample(float(t)).position, p0[:3] + s * (p1 - p0)[:3])


# --------------------------------------------------------------------------- go to
def test_a_go_to_continues_a_moving_reference_without_a_jump() -> None:
    commander = Commander(HOME, 0.0, arrival_tolerance_m=0.05, idle_land_s=60.0)
    first = plan_go_to(_base(commander, 0.0), np.array([1.0, 0.0, -1.0]), None, None, LIMITS)
    commander.install(first, 0.0)
    mid = first.motion.start + 0.4 * (first.motion.end - first.motion.start)
    before = commander.sample(mid + 0.05)  # the new motion starts at mid + the lead
    assert np.linalg.norm(before.velocity) > 0.2  # it is moving
    second = plan_go_to(_base(commander, mid), np.array([0.0, 0.8, -1.2]), None, None, LIMITS)
    commander.install(second, mid)
    after = commander.sample(mid + 0.05)
    assert np.allclose(after.position, before.position)
    assert np.allclose(after.velocity, before.velocity)
    assert np.allclose(after.acceleration, before.acceleration)
    assert commander.motions[0].state == "superseded"
    # the default duration respects the configured speed and limits
    taus = np.arange(mid, second.motion.end, 0.01)
    speeds = [np.linalg.norm(commander.sample(float(t)).velocity) for t in taus]
    assert max(speeds) <= LIMITS.flight.max_speed_m_s
    assert np.allclose(commander.sample(second.motion.end + 1).position, [0.0, 0.8, -1.2])


def test_a_heading_turns_the_short_way_across_north_south() -> None:
    commander = Commander(HOME, 3.0, arrival_tolerance_m=0.05, idle_land_s=60.0)
    planned = plan_go_to(_base(commander, 0.0), HOME, -3.0, None, LIMITS)
    end = planned.pieces[-1]
    assert isinstance(end, Rest)
    assert math.isclose(end.yaw, 3.0 + (2 * math.pi - 6.0), abs_tol=1e-9)  # +0.28 rad
    assert math.isclose(planned.motion.target_yaw or 0.0, end.yaw)
    # with a heading offset (the mission's), the requested heading is absolute
    offset_plan = plan_go_to(_base(commander, 0.0, offset=0.5), HOME, 1.0, None, LIMITS)
    assert math.isclose(offset_plan.pieces[-1].sample(99.0).yaw + 0.5, 1.0, abs_tol=1e-9)


@pytest.mark.parametrize(("target", "words"), [
    ([2.0, 0.0, -1.0], "x = 2.00 m is outside safety.volume_x"),
    ([0.0, -1.45, -1.0], "y = -1.45 m is outside safety.volume_y [-1.50, 1.50] less the 0.10"),
    ([0.0, 0.0, -1.95], "z = -1.95 m is outside safety.volume_z"),
])
def test_a_target_outside_the_volume_is_refused(target: list[float], words: str) -> None:
    commander = Commander(HOME, 0.0, arrival_tolerance_m=0.05, idle_land_s=60.0)
    with pytest.raises(CommandRefusedError, match=words.replace("[", r"\[").replace(".", r"\.")
                       ) as exc:
        plan_go_to(_base(commander, 0.0), np.array(target), None, None, LIMITS)
    assert exc.value.kind == "volume"


def test_a_move_too_fast_for_the_limits_is_refused_naming_them() -> None:
    commander = Commander(HOME, 0.0, arrival_tolerance_m=0.05, idle_land_s=60.0)
    with pytest.raises(CommandRefusedError, match=r"safety\.max_speed_m_s") as exc:
        plan_go_to(_base(commander, 0.0), np.array([1.0, 0.0, -1.0]), None, 0.5, LIMITS)
    assert exc.value.kind == "infeasible"
    assert "trajectory_tilt_deg" in exc.value.reason  # 1 m in 0.5 s also tilts too far


@pytest.mark.parametrize(("factor", "accepted"), [(0.99, False), (1.01, True)])
def test_a_move_is_checked_exactly_at_its_tilt_rate_limit(factor: float,
                                                           accepted: bool) -> None:
    """A min-jerk move of d from rest starts with the jerk 60 d / T^3, tilting the thrust at
    jerk / g (its acceleration is zero there, so nothing else turns it): the closed form
    puts the shortest move the roll/pitch rate limit allows at T = (60 d / (g w))^(1/3).
    1 % either side of it is refused or accepted: the motion is read exactly (polynomial
    pieces), not sampled (a 10 ms sampling of the start would miss the peak)."""
    lim = LIMITS.flight
    d = 1.0
    t_crit = (60.0 * d / (lim.gravity * lim.max_rate_rad_s)) ** (1.0 / 3.0)
    commander = Commander(np.array([-0.5, 0.0, -1.0]), 0.0, arrival_tolerance_m=0.05,
                          idle_land_s=60.0)
    target, duration = np.array([0.5, 0.0, -1.0]), factor * t_crit
    if accepted:
        planned = plan_go_to(_base(commander, 0.0), target, None, duration, LIMITS)
        assert planned.motion.end - planned.motion.start == pytest.approx(duration)
        return
    rate = 60.0 * d / (lim.gravity * duration**3)  # the closed form's peak, at the start
    with pytest.raises(CommandRefusedError, match=f"at t = 0.00 s, .* tilt rate of {rate:.2f} "
                       "rad/s, the roll/pitch rate limit") as exc:
        plan_go_to(_base(commander, 0.0), target, None, duration, LIMITS)
    assert exc.value.kind == "infeasible"
    assert "speed" not in exc.value.reason and "deg tilt" not in exc.value.reason


def test_hold_stops_a_moving_reference_smoothly_within_the_limits() -> None:
    commander = Commander(HOME, 0.0, arrival_tolerance_m=0.05, idle_land_s=60.0)
    commander.install(plan_go_to(_base(commander, 0.0), np.array([1.2, 0.0, -1.0]), None,
                                 None, LIMITS), 0.0)
    tau = 1.5
    before = commander.sample(tau + 0.05)
    held = plan_hold(_base(commander, tau), LIMITS)
    commander.install(held, tau)
    after = commander.sample(tau + 0.05)
    assert np.allclose(after.position, before.position)
    assert np.allclose(after.velocity, before.velocity)
    rest = commander.sample(held.motion.end + 0.1)
    assert np.allclose(rest.velocity, 0.0)
    # it stops short of the old target, ahead of where the hold began
    assert before.position[0] < rest.position[0] < 1.2
    assert np.allclose(rest.position, held.motion.target)


def test_follow_flies_to_the_start_then_the_trajectory_with_a_continuous_heading() -> None:
    from groundstation.control.trajectory import Hover
    from groundstation.flight.prepare import trajectory_for_flight

    section = CFG.trajectory.model_copy(update={"name": "figure-eight", "period_s": 10.0,
                                                "yaw_deg": 170.0})
    trajectory, duration = trajectory_for_flight(assemble(CFG.model_copy(
        update={"trajectory": section})))
    commander = Commander(HOME, -3.0, arrival_tolerance_m=0.05, idle_land_s=60.0)
    planned = plan_follow(_base(commander, 0.0), trajectory, duration, LIMITS)
    commander.install(planned, 0.0)
    taus = np.arange(0.0, planned.motion.end + 1.0, 0.01)
    yaws = np.array([commander.sample(float(t)).yaw for t in taus])
    assert np.max(np.abs(np.diff(yaws))) < 0.05  # no 2 pi jump where the trajectory starts
    assert math.isclose(math.remainder(yaws[-1] - math.radians(170.0), 2 * math.pi), 0.0,
                        abs_tol=1e-6)
    positions = np.array([commander.sample(float(t)).position for t in taus])
    assert np.max(np.linalg.norm(np.diff(positions, axis=0), axis=1)) < 0.02
    # start_at too early for the approach is refused
    far = Hover([1.0, 1.0, -1.0])
    with pytest.raises(CommandRefusedError, match="start_at") as exc:
        plan_follow(_base(commander, 0.0), far, 1.0, LIMITS, start_at=0.5)
    assert exc.value.kind == "infeasible"


# --------------------------------------------------------------------------- the book
def test_install_refuses_a_plan_the_flight_has_moved_past() -> None:
    commander = Commander(HOME, 0.0, arrival_tolerance_m=0.05, idle_land_s=60.0)
    stale = plan_go_to(_base(commander, 0.0), np.array([0.3, 0.0, -1.0]), None, None, LIMITS)
    fresh = plan_go_to(_base(commander, 0.0), np.array([0.0, 0.3, -1.0]), None, None, LIMITS)
    commander.install(fresh, 0.0)
    with pytest.raises(CommandRefusedError, match="another motion") as exc:
        commander.install(stale, 0.0)  # planned from the plan before `fresh`
    assert exc.value.kind == "busy"
    late = plan_go_to(_base(commander, 1.0), np.array([0.3, 0.3, -1.0]), None, None, LIMITS)
    with pytest.raises(CommandRefusedError, match="lead"):
        commander.install(late, 1.0 + 0.2)
    assert [m.id for m in commander.motions] == [1]


def test_motions_start_arrive_are_preempted_and_idle_flights_land() -> None:
    commander = Commander(HOME, 0.0, arrival_tolerance_m=0.05, idle_land_s=2.0)
    planned = plan_go_to(_base(commander, 0.0), np.array([0.5, 0.0, -1.0]), None, 2.0, LIMITS)
    motion = commander.install(planned, 0.0)
    motion.received = 100.0
    commander.update(100.01, 0.01, True, HOME)
    assert commander.current is not None and commander.current.started is None
    commander.update(100.06, 0.06, True, HOME)
    assert commander.current.started == 100.06 and commander.idle_land_in(100.06) is None
    commander.update(103.0, 3.0, True, np.array([0.6, 0.0, -1.0]))  # at rest, 10 cm off
    assert commander.current.state == "moving"
    commander.update(103.1, 3.1, True, np.array([0.52, 0.0, -1.0]))
    assert commander.current.state == "arrived" and commander.current.arrived == 103.1
    assert not commander.update(104.0, 4.0, True, np.array([0.5, 0.0, -1.0]))
    assert commander.update(105.2, 5.2, True, np.array([0.5, 0.0, -1.0])) == \
        "idle for 2 s without a motion command"
    # a failsafe ends the motion in progress and the plan rests where the reference was
    other = Commander(HOME, 0.0, arrival_tolerance_m=0.05, idle_land_s=60.0)
    other.install(plan_go_to(_base(other, 0.0), np.array([0.5, 0.0, -1.0]), None, 2.0,
                             LIMITS), 0.0)
    where = other.sample(1.0).position
    other.preempt(1.0, "HOLD: Vicon lost")
    assert other.motions[0].state == "preempted" and other.motions[0].reason == "HOLD: Vicon lost"
    assert np.allclose(sample_plan(other.plan, 50.0).position, where)


# --------------------------------------------------------------------------- requests
@pytest.mark.parametrize(("request_", "kind", "words"), [
    ({"request": "go_to", "position": [0, 0]}, "request", "3 numbers"),
    ({"request": "go_to", "position": [0, 0, float("nan")]}, "request", "finite"),
    ({"request": "go_to", "position": [0, True, -1]}, "request", "finite"),
    ({"request": "go_to", "position": [0, 0, -1], "duration": -1}, "request", "duration"),
    ({"request": "go_to", "position": [0, 0, -1], "speed": 3}, "request", "unknown field"),
    ({"request": "fly_away"}, "request", "unknown request"),
    ({"request": "takeoff", "height": -1}, "request", "above the floor"),
    ({"request": "follow"}, "request", "one of 'trajectory'"),
    ({"request": "follow", "trajectory": {"name": "square", "size_m": -1}}, "request",
     "size_m"),
    ({"request": "follow", "waypoints": [[0, 0, 0, -1], [1, 0, 0]]}, "request", "waypoint 1"),
    ({"request": "go_to", "position": [0, 0, -1]}, "state", "not airborne yet (PREFLIGHT)"),
    ({"request": "land"}, "state", "not flying yet"),
])
def test_requests_are_checked_before_anything_flies(request_: dict[str, Any], kind: str,
                                                    words: str) -> None:
    core = FlightCore(assemble(CFG))
    api = MotionApi(core, core.params)
    reply = api.handle(request_)
    assert reply["ok"] is False and reply["kind"] == kind and words in reply["error"], reply


def test_a_flight_with_a_configured_trajectory_refuses_motions() -> None:
    cfg = sim_config(**{"trajectory.name": "square"})
    core = FlightCore(assemble(cfg))
    core.supervisor.force(0.0, State.TRACK, "test")
    reply = MotionApi(core, core.params).handle({"request": "go_to", "position": [0, 0, -1]})
    assert reply["kind"] == "state" and "--trajectory none" in reply["error"]
    status = MotionApi(core, core.params).handle({"request": "status"})
    assert status["ok"] and status["commanded"] is False and status["state"] == "TRACK"


def test_follow_start_at_is_a_unix_time_converted_to_trajectory_time() -> None:
    """``start_at`` 5 s from now (the client's clock) begins the trajectory 5 s of
    trajectory time after the loop's present, whatever the planning lead."""
    from groundstation.flight.prepare import trajectory_for_flight

    core = FlightCore(assemble(CFG))
    core.supervisor.force(0.0, State.TRACK, "test")
    api = MotionApi(core, core.params, clock=lambda: 100.0, wall_clock=lambda: 1.7e9)
    section = {"name": "figure-eight", "period_s": 10.0, "center": [0.0, 0.0, -1.0]}
    reply = api.handle({"request": "follow", "trajectory": section, "start_at": 1.7e9 + 5.0})
    assert reply["ok"], reply
    _, duration = trajectory_for_flight(assemble(CFG.model_copy(update={
        "trajectory": CFG.trajectory.model_copy(update=section)})))
    begin = core.mission.trajectory_time + 5.0
    assert reply["motion"]["duration_s"] == pytest.approx(begin + duration - 0.05)
    late = api.handle({"request": "follow", "trajectory": section, "start_at": 1.7e9 + 0.2})
    assert late["ok"] is False and late["kind"] == "infeasible" and "start_at" in late["error"]
