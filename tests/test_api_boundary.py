"""Run-time requests at the boundary: every number is checked before any arithmetic, every
motion obeys MAX_MOTION_S however its length arises, and every reply has a documented kind.

Each hostile tester finding is reproduced as the request they sent, on the flight core
the daemon runs (supervisor in TRACK, motions planned in this thread). The numbers the
refusals are judged against are the configured limits and the request's own numbers;
the fuzz test sends arbitrary JSON and asks only that every reply is one of the
documented shapes.
"""

from __future__ import annotations

import json
import re
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from lab_helpers import sim_config

from groundstation.app.api import MotionApi
from groundstation.config.ranges import MIN_MOTION_S
from groundstation.control.trajectories import TrajectorySpec
from groundstation.flight.assembly import assemble, trajectory_spec
from groundstation.flight.commander import (
    MAX_MOTION_S,
    Commander,
    CommandRefusedError,
    check_target,
    plan_follow,
)
from groundstation.flight.core import FlightCore
from groundstation.flight.planner import PlannerSettings, PrepareFollow
from groundstation.flight.supervisor import State

CFG = sim_config(**{"trajectory.name": "none"})
SETTINGS: PlannerSettings = assemble(CFG).planner
KINDS = {"request", "state", "volume", "infeasible", "busy", "internal"}
"""The documented refusal kinds (README, "What is refused")."""
README = Path(__file__).resolve().parents[1] / "README.md"
FIGURE8_3000 = {"name": "figure-eight", "period_s": 3000, "center": [0, 0, -1], "size_m": 0.2}
"""The hostile tester's legal request: a figure-eight with a 3000 s lap."""


def tracking_api(now_wall: float = 1.7e9) -> MotionApi:
    core = FlightCore(assemble(CFG))
    core.supervisor.force(0.0, State.TRACK, "test")
    return MotionApi(core, core.params, clock=lambda: 100.0, wall_clock=lambda: now_wall)


def refused(api: MotionApi, request: dict[str, Any]) -> tuple[str, str]:
    reply = api.handle(request)
    assert reply["ok"] is False, reply
    return reply["kind"], reply["error"]


# --------------------------------------------------------------------------- findings
@pytest.mark.parametrize(("request_", "words"), [
    # "duration: 1e-300" was answered "request failed: Singular matrix"
    ({"request": "go_to", "position": [0, 0, -1], "duration": 1e-300},
     f"duration 1e-300 s: must be in [{MIN_MOTION_S:g}, {MAX_MOTION_S:g}] s"),
    # a 4,000-digit number: "int too large to convert to float"
    ({"request": "go_to", "position": [0, 0, -1], "duration": int("9" * 4000)},
     "duration: must be a finite number, got an integer of"),
    ({"request": "go_to", "position": [int("1" * 400), 0, -1]}, "position: must be a finite"),
    # headings wrapped to a meaningless one
    ({"request": "go_to", "position": [0, 0, -1], "yaw": 1e308}, "yaw 1e+308 rad: a heading is "
     "within one turn"),
    ({"request": "go_to", "position": [0, 0, -1], "yaw": 1e15}, "within one turn"),
    ({"request": "go_to", "position": [0, 0, -1], "yaw": "1"}, "yaw: must be a finite number"),
    # a figure-eight faster than the feasibility check's sampling
    ({"request": "follow", "trajectory": {**FIGURE8_3000, "period_s": 1e-9}},
     f"period_s: outside [{MIN_MOTION_S:g}, 3600]"),
    # a motion of 998,204,286,386 s
    ({"request": "follow", "trajectory": FIGURE8_3000, "start_at": 1e12},
     "start_at is 998300000000 s from now: it must be within api.start_horizon_s = 300 s"),
    ({"request": "follow", "trajectory": FIGURE8_3000, "start_at": 0},
     "start_at is 1700000000 s ago"),
    ({"request": "follow", "trajectory": {**FIGURE8_3000, "yaw_deg": 1e300}}, "yaw_deg"),
    ({"request": "follow", "trajectory": {**FIGURE8_3000, "file": "/etc/passwd"}},
     "'file' names a file on the ground station"),
    ({"request": "follow", "waypoints": [[0, 0, 0, -1], [1, 0.1, 0, -1], [1.001, 0.2, 0, -1]]},
     "waypoint 2: t = 1.001 s must be at least 0.02 s after the one before"),
    ({"request": "follow", "waypoints": [[0, 0, 0, -1], [1e300, 0.1, 0, -1]]},
     "the path lasts 1e+300 s, longer than a motion may be (600 s)"),
    ({"request": "follow", "waypoints": [[0, 0, 0, -1, 7.0], [1, 0.1, 0, -1, 0.0]]},
     "waypoint 0 yaw 7 rad"),
    ({"request": "takeoff", "height": 1e9}, "height 1e+09 m: must be above the floor and at "
     "most the volume's 2.05 m"),
    ({"request": "status", "extra": 1}, "unknown field(s) extra"),
])
def test_absurd_numbers_are_refused_as_requests_before_any_arithmetic(
        request_: dict[str, Any], words: str) -> None:
    kind, error = refused(tracking_api(), request_)
    assert kind == "request" and words in error, error


@pytest.mark.parametrize(("request_", "words"), [
    ({"request": "follow", "trajectory": {**FIGURE8_3000, "size_m": 50.0}},
     "size_m 50 m: larger than the flight volume (4.71 m)"),
    ({"request": "follow", "trajectory": {**FIGURE8_3000, "center": [0, 0, -5]}},
     "trajectory: center: z = -5.00 m is outside safety.volume_z"),
    ({"request": "follow", "waypoints": [[0, 0, 0, -1], [1, 9, 0, -1]]},
     "waypoint 1: x = 9.00 m is outside safety.volume_x"),
])
def test_sizes_and_positions_the_volume_cannot_hold_are_refused_unplanned(
        request_: dict[str, Any], words: str) -> None:
    kind, error = refused(tracking_api(), request_)
    assert kind == "volume" and words in error, error


def test_a_legal_request_of_a_3000_s_lap_is_refused_before_it_is_sampled() -> None:
    """The hostile tester's request was planned for 12 s and accepted with duration_s
    3001.5, past MAX_MOTION_S. The lap-length default obeys the cap like any duration,
    and is refused before a sample is taken (the planning took 10 s of CPU before)."""
    api = tracking_api()
    cpu = time.thread_time()
    kind, error = refused(api, {"request": "follow", "trajectory": FIGURE8_3000})
    cpu = time.thread_time() - cpu
    assert kind == "infeasible", error
    assert error == ("one lap of figure-eight is 3000.0 s: longer than a motion may be "
                     f"({MAX_MOTION_S:g} s); give a shorter duration")
    assert cpu < 1.0, cpu
    assert api.core.commander is not None and api.core.commander.motions == []


@pytest.mark.parametrize(("duration", "start_in", "words"), [
    (None, 0.0, "one lap of figure-eight is 3000.0 s"),
    (590.0, 20.0, "the duration is 590.0 s starting 20.0 s from now"),
])
def test_every_way_a_follow_grows_obeys_max_motion_s(duration: float | None, start_in: float,
                                                      words: str) -> None:
    job = PrepareFollow(_section(FIGURE8_3000), None, duration, start_in)
    with pytest.raises(CommandRefusedError, match=re.escape(words)) as exc:
        job.run(SETTINGS)
    assert exc.value.kind == "infeasible"


def test_the_approach_plus_the_trajectory_obey_max_motion_s() -> None:
    """A trajectory of 599 s is fine alone; with the approach to its start (from 1.4 m
    away) the motion is longer than MAX_MOTION_S."""
    f = PrepareFollow(_section({"name": "figure-eight", "period_s": 3000, "size_m": 0.2,
                                "center": [0.5, 0.5, -1.0]}), None, 598.0).run(SETTINGS)
    assert f.duration == pytest.approx(599.0)  # the ease-in and out added 1 s
    commander = Commander(np.array([-0.5, -0.5, -1.0]), 0.0, arrival_tolerance_m=0.05,
                          idle_land_s=60.0)
    base = commander.base(0.0, 0.0, "TRACK", np.zeros(3))
    with pytest.raises(CommandRefusedError, match=r"the motion would last 60\d\.\d s \(to the "
                       r"start \d\.\d s, then the trajectory 599\.0 s\)") as exc:
        plan_follow(base, f.trajectory, f.duration, SETTINGS.limits)
    assert exc.value.kind == "infeasible"


def test_the_3000_s_lap_flown_for_a_given_duration_is_accepted_within_the_cap() -> None:
    api = tracking_api()
    reply = api.handle({"request": "follow", "trajectory": FIGURE8_3000, "duration": 580.0})
    assert reply["ok"], reply
    # approach (at rest already: the shortest move, 0.5 s) + 580 s + the 1 s ease-in/out
    assert reply["motion"]["duration_s"] == pytest.approx(581.5)
    assert reply["motion"]["duration_s"] <= MAX_MOTION_S


@pytest.mark.slow
# --------------------------------------------------------------------------- the floor
def test_one_floor_rule_in_the_code_the_refusal_and_the_readme() -> None:
    """The sides and the ceiling keep the margin; the floor has none (a reference may go
    down to it, as in the feasibility check). z = -0.049 m is 1 mm inside where a floor
    margin would be: accepted."""
    s = CFG.safety
    assert s.volume_z[1] - s.volume_margin_m == pytest.approx(-0.05)
    api = tracking_api()
    assert api.handle({"request": "go_to", "position": [0, 0, -0.049]})["ok"]
    floor = refused(api, {"request": "go_to", "position": [0, 0, 0.1]})
    ceiling = refused(api, {"request": "go_to", "position": [0, 0, -1.95]})
    side = refused(api, {"request": "go_to", "position": [3, 0, -1]})
    assert floor == ("volume", "z = 0.10 m is below the floor: outside safety.volume_z "
                     "[-2.00, 0.05] (the floor has no margin)")
    assert ceiling == ("volume", "z = -1.95 m is outside safety.volume_z [-2.00, 0.05] less "
                       "the 0.10 m margin")
    assert side == ("volume", "x = 3.00 m is outside safety.volume_x [-1.50, 1.50] less the "
                    "0.10 m margin")
    readme = README.read_text(encoding="utf-8")
    assert f"`gs goto 3 0 -1` -> `{side[1]}`" in readme
    assert f"`gs goto 0 0 0.1` -> `{floor[1]}`" in readme
    # the same rule as the feasibility check of trajectories: down to the floor, no margin
    with pytest.raises(CommandRefusedError):
        check_target(np.array([0.0, 0.0, s.volume_z[1] + 1e-6]), SETTINGS.limits.volume)
    check_target(np.array([0.0, 0.0, s.volume_z[1]]), SETTINGS.limits.volume)


# --------------------------------------------------------------------------- kinds
class _BrokenPlanner:
    """A planner with a bug (the handler's last line of defence is what is tested)."""

    def run(self, job: object, deadline: float) -> object:
        raise KeyError("bug")


def test_a_failure_of_ours_is_answered_internal_and_the_flight_goes_on() -> None:
    core = FlightCore(assemble(CFG))
    core.supervisor.force(0.0, State.TRACK, "test")
    api = MotionApi(core, core.params, planner=_BrokenPlanner())
    reply = api.handle({"request": "go_to", "position": [0.3, 0, -1]})
    assert reply == {"ok": False, "kind": "internal", "error": "internal error: KeyError: 'bug'"}
    assert api.handle({"request": "status"})["state"] == "TRACK"


JSON = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=8)
    | st.sampled_from([10**400, -(10**30), 1e308, 1e-300, 0, -1, 0.5, 599.0, 1e12]),
    lambda inner: st.lists(inner, max_size=5) | st.dictionaries(st.text(max_size=8), inner,
                                                               max_size=4),
    max_leaves=12)
FIELDS = ["position", "yaw", "duration", "height", "trajectory", "waypoints", "start_at",
          "auto", "name", "period_s", "size_m", "center"]


@st.composite
def requests(draw: st.DrawFn) -> dict[str, Any]:
    request: dict[str, Any] = {"request": draw(st.sampled_from(
        ["status", "go_to", "takeoff", "follow", "hold", "land", "channels", "nope"]))}
    for name in draw(st.lists(st.sampled_from(FIELDS), max_size=3, unique=True)):
        if name in ("trajectory",):
            request[name] = draw(st.fixed_dictionaries({}, optional={
                "name": st.sampled_from(["figure-eight", "square", "hover", "yaw-turn",
                                         "step-z", "none"]),
                "period_s": JSON, "size_m": JSON, "center": JSON, "yaw_deg": JSON,
                "yaw_turn_deg": JSON, "step_m": JSON}))
        else:
            request[name] = draw(JSON)
    return request


@pytest.mark.slow
@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(requests())
def test_every_reply_is_ok_or_a_refusal_of_a_documented_kind(request_: dict[str, Any]) -> None:
    """Whatever arrives, the handler answers (never raises) with ``ok`` or one of the
    documented kinds, and the reply is JSON a client can read (``NaN`` aside, which the
    status's missing values are)."""
    api = tracking_api(now_wall=time.time())
    reply = api.handle(request_)
    assert isinstance(reply, dict) and isinstance(reply["ok"], bool)
    if not reply["ok"]:
        assert reply["kind"] in KINDS and isinstance(reply["error"], str), reply
        assert reply["kind"] != "internal", reply  # no path out is a fault of ours
    json.loads(json.dumps(reply))


def _section(data: dict[str, Any]) -> TrajectorySpec:
    """The trajectory of a follow request's ``trajectory:`` section, as the API makes it."""
    from groundstation.config import TrajectoryConfig

    return trajectory_spec(TrajectoryConfig.model_validate(data))
