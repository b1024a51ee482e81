"""Issue 19: the API's requests in a flight on the virtual lab's simulated clock.

A failsafe pre-empts a motion and refuses new ones; after it clears, motions are
accepted again and arrive where the ground truth says; a land request ends the flight
normally. Fast and deterministic: the same requests as the daemon answers, on the
flight core the daemon runs.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from lab_helpers import sim_config

from groundstation.loop.api import MotionApi
from groundstation.loop.inprocess import InProcessFlight
from groundstation.loop.supervisor import Outcome, State


def test_a_failsafe_preempts_a_motion_and_refuses_new_ones_until_it_clears() -> None:
    cfg = sim_config(**{"trajectory.name": "none"})
    flight = InProcessFlight(cfg)
    api = MotionApi(flight.core, cfg, clock=lambda: flight.lab.t,
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
