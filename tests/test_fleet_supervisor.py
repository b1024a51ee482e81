"""The supervisor's separation rule for a fleet, from scripted observations: closer than
``separation_m`` to a peer, hold (from TAKEOFF or TRACK); closer than half of it, land;
the gap open again (1.1 x the separation), resume; held too long, land. Without a
separation nothing changes."""

from __future__ import annotations

import dataclasses
import math

from test_supervisor import FLYING_AT_1M, airborne, obs

from groundstation.flight.supervisor import (
    PEER_RESUME,
    Outcome,
    State,
    Supervisor,
    SupervisorLimits,
)

SEP = 0.6
LIMITS = SupervisorLimits(separation_m=SEP, separation_hold_s=3.0)


def near(t: float, distance: float, **changes: object) -> object:
    return obs(t, peer_distance_m=distance, peer_name="v2", **{**FLYING_AT_1M, **changes})


def test_closer_than_the_separation_holds_and_the_gap_opening_resumes() -> None:
    sup = Supervisor(LIMITS)
    t = airborne(sup)
    assert sup.update(near(t + 0.1, SEP + 0.01)) is State.TRACK  # just outside: nothing
    assert sup.update(near(t + 0.2, SEP - 0.01)) is State.HOLD
    assert "too close to a peer: v2 0.59 m away" in sup.transitions[-1].reason
    assert sup.transitions[-1].failsafe
    assert sup.update(near(t + 0.3, SEP * PEER_RESUME - 0.01)) is State.HOLD  # hysteresis
    assert sup.update(near(t + 0.4, SEP * PEER_RESUME + 0.01)) is State.TRACK
    assert sup.transitions[-1].reason == "the gap to the peers is open again"


def test_closer_than_half_lands_from_track_and_from_the_hold() -> None:
    for first in (SEP / 2 - 0.01, SEP - 0.1):
        sup = Supervisor(LIMITS)
        t = airborne(sup)
        state = sup.update(near(t + 0.1, first))
        assert state is (State.LAND if first < SEP / 2 else State.HOLD)
        assert sup.update(near(t + 0.2, SEP / 2 - 0.01)) is State.LAND
        assert "less than half the separation (0.60 m)" in sup.transitions[-1].reason
        assert sup.outcome is Outcome.FAILSAFE


def test_a_hold_beside_a_peer_that_lasts_lands() -> None:
    sup = Supervisor(LIMITS)
    t = airborne(sup)
    assert sup.update(near(t, SEP - 0.05)) is State.HOLD
    assert sup.update(near(t + 2.9, SEP - 0.05)) is State.HOLD
    assert sup.update(near(t + 3.1, SEP - 0.05)) is State.LAND
    assert sup.transitions[-1].reason.startswith("held beside a peer for 3.1 s (v2 0.55 m")


def test_the_take_off_holds_too_and_a_landing_goes_on() -> None:
    sup = Supervisor(LIMITS)
    assert sup.update(obs(0.0)) is State.TAKEOFF
    assert sup.update(near(0.5, SEP - 0.1, takeoff_done=False)) is State.HOLD
    assert sup.update(near(0.6, 2.0)) is State.TAKEOFF  # resumed where it was interrupted
    sup2 = Supervisor(LIMITS)
    t = airborne(sup2)
    assert sup2.update(near(t + 1, 2.0, trajectory_done=True)) is State.LAND
    assert sup2.update(near(t + 1.1, 0.1)) is State.LAND  # already landing: lands on


def test_no_separation_or_no_peer_changes_nothing() -> None:
    for limits, distance in ((SupervisorLimits(), 0.01), (LIMITS, math.inf)):
        sup = Supervisor(limits)
        t = airborne(sup)
        assert sup.update(near(t + 1, distance)) is State.TRACK


def test_a_vicon_hold_is_not_ended_by_the_gap() -> None:
    """A hold for a Vicon loss and one for a peer are told apart: a peer far away does not
    end a Vicon hold, and Vicon coming back does not end a peer hold."""
    sup = Supervisor(LIMITS)
    t = airborne(sup)
    assert sup.update(near(t + 1, 5.0, vicon_age_s=0.6)) is State.HOLD
    assert sup.update(near(t + 1.1, 5.0, vicon_age_s=0.7)) is State.HOLD
    assert sup.update(near(t + 1.2, 5.0)) is State.TRACK  # Vicon back
    assert sup.update(near(t + 1.3, SEP - 0.1)) is State.HOLD
    assert sup.update(near(t + 1.4, SEP - 0.1)) is State.HOLD  # Vicon fine, gap not open


def test_limits_come_from_the_fleet_section() -> None:
    from groundstation.config import validate_config
    from groundstation.flight.assembly import supervisor_limits

    alone = supervisor_limits(validate_config({}))
    assert alone.separation_m is None
    fleet = supervisor_limits(validate_config(
        {"fleet": {"vehicle": "a", "separation_m": 0.7, "separation_hold_s": 4.0}}))
    assert (fleet.separation_m, fleet.separation_hold_s) == (0.7, 4.0)
    assert dataclasses.replace(fleet, separation_m=None, separation_hold_s=3.0) == alone
