"""The API's requests in a flight on the virtual lab's simulated clock.

A failsafe pre-empts a motion and refuses new ones; after it clears, motions are
accepted again and arrive where the ground truth says; a land request ends the flight
normally. Fast and deterministic: the same requests as the daemon answers, on the
flight core the daemon runs.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from lab_helpers import sim_config

from groundstation.app.api import MotionApi
from groundstation.app.inprocess import InProcessFlight
from groundstation.flight.assembly import assemble
from groundstation.flight.supervisor import Outcome, State


@pytest.mark.slow
def test_a_failsafe_preempts_a_motion_and_refuses_new_ones_until_it_clears() -> None:
    cfg = sim_config(**{"trajectory.name": "none"})
    flight = InProcessFlight(assemble(cfg))
    api = MotionApi(flight.core, flight.params, clock=lambda: flight.lab.t,
                    wall_clock=lambda: flight.lab.t)
    replies: dict[str, dict[str, Any]] = {}
    arrived_at: list[float] = []

    def ask(name: str, request: dict[str, Any]) -> Any:
        def event(f: InProcessFlight) -> None:
            replies[name] = api.handle(request)
        return event

    def outage(f: InProcessFlight) -> None:
        f.lab.vicon_outage(1.5)  # type: ignore[attr-defined]

    def watch(f: InProcessFlight) -> None:
        status = api.handle({"request": "status"})
        if status["motion"] and status["motion"]["state"] == "arrived" and not arrived_at:
            arrived_at.append(f.lab.t)

    events = [(9.0, ask("first", {"request": "go_to", "position": [0.6, 0.0, -1.0],
                                  "duration": 4.0})),
              (10.0, outage), (10.8, ask("during", {"request": "go_to",
                                                    "position": [0.0, 0.0, -1.0]})),
              (10.9, ask("status_hold", {"request": "status"})),
              (14.0, ask("after", {"request": "go_to", "position": [0.3, 0.4, -1.2]})),
              *[(14.0 + 0.05 * k, watch) for k in range(200)],
              (25.0, ask("land", {"request": "land"}))]
    result = flight.run(max_time_s=60.0, events=events)

    assert replies["first"]["ok"], replies["first"]
    # the outage put the flight in HOLD: the motion was pre-empted, new ones refused
    hold = replies["status_hold"]
    assert hold["state"] == "HOLD"
    assert hold["motion"]["state"] == "preempted" and hold["motion"]["reason"].startswith("HOLD")
    during = replies["during"]
    assert during["ok"] is False and during["kind"] == "state" and "HOLD" in during["error"]
    # Vicon back: tracking again; the next motion arrives where the truth says
    assert replies["after"]["ok"], replies["after"]
    assert arrived_at
    truth = flight.lab.truth_log.arrays()  # type: ignore[attr-defined]
    k = int(np.searchsorted(truth["t"], arrived_at[0]))
    error = float(np.linalg.norm(truth["position"][k] - [0.3, 0.4, -1.2]))
    assert error < 0.05, error
    # the land request lands it normally; the flight still reports that a failsafe acted
    assert replies["land"] == {"ok": True, "state": "TRACK"}
    assert result.final_state is State.DONE and not result.success
    assert flight.core.supervisor.outcome is Outcome.FAILSAFE
    assert [tr.new for tr in result.transitions] == [
        State.TAKEOFF, State.TRACK, State.HOLD, State.TRACK, State.LAND, State.DISARM,
        State.DONE]
    land = result.transitions[4]
    assert land.reason == "land requested by a client" and land.nominal and not land.failsafe


FIGURE8_3000 = {"name": "figure-eight", "period_s": 3000, "center": [0.0, 0.0, -1.0],
                "size_m": 0.2}
"""The hostile tester's legal request: a figure-eight with a 3000 s lap."""


@pytest.mark.slow
def test_the_hostile_requests_are_refused_and_the_legal_one_flown_safely() -> None:
    """The hostile tester's requests, in TRACK on the simulated clock: each absurd number
    refused as a request, the 3000 s lap refused as longer than a motion may be, a target
    below the floor refused; none of them changes the plan. The same figure-eight flown for
    20 s is accepted and flown: the truth stays level and on the figure-eight."""
    cfg = sim_config(**{"trajectory.name": "none"})
    flight = InProcessFlight(assemble(cfg))
    api = MotionApi(flight.core, flight.params, clock=lambda: flight.lab.t,
                    wall_clock=lambda: 1.7e9 + flight.lab.t)
    replies: dict[str, dict[str, Any]] = {}

    def ask(name: str, request: dict[str, Any]) -> Any:
        def event(f: InProcessFlight) -> None:
            replies[name] = api.handle(request)
        return event

    here = [0.0, 0.0, -1.0]
    hostile = {
        "lap": {"request": "follow", "trajectory": FIGURE8_3000},
        "fast": {"request": "follow", "trajectory": {**FIGURE8_3000, "period_s": 1e-9}},
        "far": {"request": "follow", "trajectory": FIGURE8_3000, "start_at": 1e12},
        "yaw": {"request": "go_to", "position": here, "yaw": 1e308},
        "tiny": {"request": "go_to", "position": here, "duration": 1e-300},
        "huge": {"request": "go_to", "position": here, "duration": int("9" * 4000)},
        "floor": {"request": "go_to", "position": [0.0, 0.0, 0.1]},
    }
    events = [*[(9.0, ask(name, request)) for name, request in hostile.items()],
              (9.5, ask("flown", {"request": "follow", "trajectory": FIGURE8_3000,
                                  "duration": 20.0})),
              (35.0, ask("land", {"request": "land"}))]
    result = flight.run(max_time_s=80.0, events=events)

    kinds = {name: (replies[name]["ok"], replies[name].get("kind")) for name in hostile}
    assert kinds == {"lap": (False, "infeasible"), "fast": (False, "request"),
                     "far": (False, "request"), "yaw": (False, "request"),
                     "tiny": (False, "request"), "huge": (False, "request"),
                     "floor": (False, "volume")}, replies
    flown = replies["flown"]
    assert flown["ok"], flown
    commander = flight.core.commander
    assert commander is not None and [m.kind for m in commander.motions] == ["follow"]
    assert result.final_state is State.DONE and result.success, result.transitions
    truth = flight.lab.truth_log.arrays()  # type: ignore[attr-defined]
    air = (truth["t"] >= 9.0) & (truth["t"] <= 35.0)
    q = truth["quaternion"][air]
    tilt = np.degrees(np.arccos(np.clip(1.0 - 2.0 * (q[:, 1] ** 2 + q[:, 2] ** 2), -1, 1)))
    offset = np.linalg.norm(truth["position"][air] - FIGURE8_3000["center"], axis=1)
    assert tilt.max() < 10.0 and offset.max() < 0.15, (tilt.max(), offset.max())
