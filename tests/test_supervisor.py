"""Supervisor state machine: each transition and failsafe from scripted observations."""

from __future__ import annotations

import dataclasses
import math

import pytest
from structlog.testing import capture_logs

from groundstation.flight.supervisor import (
    Observation,
    Outcome,
    State,
    Supervisor,
    SupervisorLimits,
)

GOOD = Observation(
    t=0.0, data_age_s=0.01, data_rate_hz=100.0, vicon_age_s=0.01, vicon_rate_hz=100.0,
    estimator_ok=True, estimator_diverged=False, gravity_ok=True, position=(0.0, 0.0, 0.0),
    tilt_rad=0.0, height_above_ground_m=0.0, takeoff_done=False, trajectory_done=False,
    pilot_enabled=True, vehicle_applying=True,
)


def obs(t: float, **changes: object) -> Observation:
    return dataclasses.replace(GOOD, t=t, **changes)  # type: ignore[arg-type]


def airborne(sup: Supervisor) -> float:
    """Drive a supervisor to TRACK; return the time reached."""
    assert sup.update(obs(0.0)) is State.TAKEOFF
    assert sup.update(obs(1.0, position=(0, 0, -0.5), height_above_ground_m=0.5)) is State.TAKEOFF
    assert sup.update(obs(2.0, position=(0, 0, -1), height_above_ground_m=1.0,
                          takeoff_done=True)) is State.TRACK
    return 2.0


FLYING_AT_1M = {"position": (0.0, 0.0, -1.0), "height_above_ground_m": 1.0}


def test_nominal_flight_ends_done_and_logs_every_transition() -> None:
    sup = Supervisor()
    t = airborne(sup)
    assert sup.commanding
    assert sup.update(obs(t + 1, trajectory_done=True, **FLYING_AT_1M)) is State.LAND
    # Still above the floor: keep landing.
    assert sup.update(obs(t + 2, position=(0, 0, -0.3), height_above_ground_m=0.3)) is State.LAND
    assert sup.update(obs(t + 3, position=(0, 0, -0.01), height_above_ground_m=0.01)) is State.LAND
    assert sup.update(obs(t + 3.6, height_above_ground_m=0.01)) is State.DISARM
    assert sup.update(obs(t + 4.2, height_above_ground_m=0.0)) is State.DONE
    assert sup.terminal and sup.success and not sup.commanding
    names = [(tr.old, tr.new) for tr in sup.transitions]
    assert names == [(State.PREFLIGHT, State.TAKEOFF), (State.TAKEOFF, State.TRACK),
                     (State.TRACK, State.LAND), (State.LAND, State.DISARM),
                     (State.DISARM, State.DONE)]
    assert all(tr.reason for tr in sup.transitions)


@pytest.mark.parametrize(
    ("change", "failure"),
    [
        ({"data_rate_hz": 50.0}, "DATA at 50 Hz"),
        ({"vicon_rate_hz": 1.0}, "Vicon"),
        ({"estimator_ok": False}, "estimator not converged"),
        ({"gravity_ok": False}, "world_to_ned"),
    ],
)
def test_preflight_waits_then_aborts_with_the_reason(change: dict[str, object],
                                                     failure: str) -> None:
    sup = Supervisor(SupervisorLimits(preflight_timeout_s=5.0))
    assert sup.update(obs(0.0, **change)) is State.PREFLIGHT
    assert any(failure in f for f in sup.preflight_failures)
    assert sup.update(obs(4.9, **change)) is State.PREFLIGHT
    assert sup.update(obs(5.1, **change)) is State.ABORTED
    assert failure in sup.transitions[-1].reason and not sup.success


def test_vicon_loss_holds_then_resumes() -> None:
    sup = Supervisor()
    t = airborne(sup)
    assert sup.update(obs(t + 0.4, vicon_age_s=0.4, **FLYING_AT_1M)) is State.TRACK
    assert sup.update(obs(t + 0.6, vicon_age_s=0.6, **FLYING_AT_1M)) is State.HOLD
    assert sup.update(obs(t + 0.7, vicon_age_s=0.01, **FLYING_AT_1M)) is State.TRACK


def test_vicon_loss_holds_then_lands() -> None:
    sup = Supervisor()
    t = airborne(sup)
    assert sup.update(obs(t + 0.6, vicon_age_s=0.6, **FLYING_AT_1M)) is State.HOLD
    assert sup.update(obs(t + 1.9, vicon_age_s=1.9, **FLYING_AT_1M)) is State.HOLD
    assert sup.update(obs(t + 2.1, vicon_age_s=2.1, **FLYING_AT_1M)) is State.LAND
    # Landing continues on the IMU estimate without bouncing back to HOLD.
    assert sup.update(obs(t + 2.2, vicon_age_s=2.2, **FLYING_AT_1M)) is State.LAND


def test_tilt_over_the_limit_lands() -> None:
    sup = Supervisor()
    t = airborne(sup)
    assert sup.update(obs(t + 0.1, tilt_rad=math.radians(40), **FLYING_AT_1M)) is State.LAND


OUTSIDE = [
    {"position": (1.6, 0.0, -1.0)}, {"position": (0.0, -1.6, -1.0)},
    {"position": (0.0, 0.0, -2.1)},  # the estimate beyond a side or the ceiling
    {"vicon_position": (1.6, 0.0, -1.0)},  # Vicon there, the estimate still inside
    {"vicon_position": (0.0, 0.0, -2.01)},
    {"vicon_outside": (0.0, 0.0, -9.0)},  # a sighting beyond the plausible volume
]


@pytest.mark.parametrize("change", OUTSIDE)
def test_leaving_the_volume_hands_back_at_once_with_an_error(change: dict[str, object]) -> None:
    """The geofence acts on the truth as well as on the estimate (which may be wrong), and
    hands back by default: the vehicle is beyond what the controller was trusted with."""
    sup = Supervisor()
    t = airborne(sup)
    with capture_logs() as logs:
        assert sup.update(obs(t + 0.1, **{**FLYING_AT_1M, **change})) is State.HANDBACK
    assert sup.transitions[-1].failsafe and sup.outcome is Outcome.FAILSAFE
    assert sup.transitions[-1].reason.startswith("left the volume")
    assert [e["log_level"] for e in logs] == ["error"]


@pytest.mark.parametrize("change", OUTSIDE)
def test_leaving_the_volume_lands_when_configured(change: dict[str, object]) -> None:
    sup = Supervisor(SupervisorLimits(on_geofence="land"))
    t = airborne(sup)
    assert sup.update(obs(t + 0.1, **{**FLYING_AT_1M, **change})) is State.LAND
    # still outside while landing: it goes on landing
    assert sup.update(obs(t + 0.2, **{**FLYING_AT_1M, **change})) is State.LAND


def test_a_landing_that_leaves_the_volume_is_handed_back() -> None:
    """The thrust-fault fly-away: landing on an estimate near 1 m while Vicon shows the
    vehicle climbing through the ceiling."""
    sup = Supervisor()
    t = airborne(sup)
    assert sup.update(obs(t + 0.1, trajectory_done=True, **FLYING_AT_1M)) is State.LAND
    assert sup.update(obs(t + 0.2, vicon_position=(0.0, 0.0, -1.9), **FLYING_AT_1M)) \
        is State.LAND
    assert sup.update(obs(t + 0.3, vicon_position=(0.0, 0.0, -2.05), **FLYING_AT_1M)) \
        is State.HANDBACK


@pytest.mark.parametrize("where", ["position", "vicon_position"])
def test_the_floor_is_no_fence(where: str) -> None:
    """Nothing flies through the floor: below it is an estimate or an origin that is off,
    never a vehicle that left (a landing aims 10 cm below the floor)."""
    sup = Supervisor()
    t = airborne(sup)
    assert sup.update(obs(t + 0.1, trajectory_done=True, **FLYING_AT_1M)) is State.LAND
    low = {where: (0.0, 0.0, 0.08), "height_above_ground_m": -0.08}
    assert sup.update(obs(t + 0.2, **low)) is State.LAND


def test_a_landing_that_loses_the_attitude_is_handed_back() -> None:
    sup = Supervisor()
    t = airborne(sup)
    assert sup.update(obs(t + 0.1, tilt_rad=math.radians(40), **FLYING_AT_1M)) is State.LAND
    assert sup.update(obs(t + 0.2, tilt_rad=math.radians(50), **FLYING_AT_1M)) is State.LAND
    assert sup.update(obs(t + 0.3, tilt_rad=math.radians(61), **FLYING_AT_1M)) is State.HANDBACK
    assert "landing failed" in sup.transitions[-1].reason and not sup.success


ABOVE_THE_FLOOR = {"position": (0.0, 0.0, -0.15), "height_above_ground_m": 0.15}


@pytest.mark.parametrize(
    ("lift", "force_g", "landed"),
    [(0.3, 1.0, True),  # little lift, 1 g felt: the floor holds it up
     (0.3, 0.62, False),  # little lift and falling: in the air
     (0.95, 1.0, False),  # hover lift, 1 g: flying (or resting on its rotors)
     (0.59, 1.19, True), (0.61, 1.0, False), (0.3, 1.21, False)],  # the bounds
)
def test_ground_contact_lands_whatever_the_height_estimate(lift: float, force_g: float,
                                                           landed: bool) -> None:
    """Landing without Vicon: the height estimate says 15 cm up, the physics says down."""
    sup = Supervisor()
    t = airborne(sup)
    assert sup.update(obs(t + 1, trajectory_done=True, **FLYING_AT_1M)) is State.LAND
    felt = {"lift_fraction": lift, "specific_force_g": force_g, **ABOVE_THE_FLOOR}
    assert sup.update(obs(t + 2.0, **felt)) is State.LAND
    assert sup.update(obs(t + 2.4, **felt)) is State.LAND  # not yet landed_time_s (0.5 s)
    end = sup.update(obs(t + 2.5, **felt))
    assert end is (State.DISARM if landed else State.LAND)
    if landed:
        assert "ground contact felt at estimated height 0.15 m" in sup.transitions[-1].reason
    # A contact that does not last resets the timer.
    sup2 = Supervisor()
    t = airborne(sup2)
    sup2.update(obs(t + 1, trajectory_done=True, **FLYING_AT_1M))
    sup2.update(obs(t + 2.0, **felt))
    sup2.update(obs(t + 2.3, **ABOVE_THE_FLOOR))
    assert sup2.update(obs(t + 2.6, **felt)) is State.LAND


def test_estimator_divergence_hands_back_at_once() -> None:
    sup = Supervisor()
    t = airborne(sup)
    assert sup.update(obs(t + 0.01, estimator_diverged=True, **FLYING_AT_1M)) is State.HANDBACK
    assert not sup.commanding and not sup.success


def test_link_loss_stops() -> None:
    sup = Supervisor()
    t = airborne(sup)
    assert sup.update(obs(t + 0.2, data_age_s=0.2, **FLYING_AT_1M)) is State.TRACK
    assert sup.update(obs(t + 0.4, data_age_s=0.31, **FLYING_AT_1M)) is State.LINK_LOST


def test_pilot_switch_is_respected_at_once() -> None:
    sup = Supervisor()
    t = airborne(sup)
    assert sup.update(obs(t + 0.01, pilot_enabled=False, **FLYING_AT_1M)) is State.PILOT


def test_vehicle_not_applying_commands_is_a_takeover_after_grace() -> None:
    sup = Supervisor()
    t = airborne(sup)
    assert sup.update(obs(t + 0.01, vehicle_applying=False, **FLYING_AT_1M)) is State.TRACK
    assert sup.update(obs(t + 0.1, vehicle_applying=True, **FLYING_AT_1M)) is State.TRACK
    assert sup.update(obs(t + 0.2, vehicle_applying=False, **FLYING_AT_1M)) is State.TRACK
    assert sup.update(obs(t + 0.45, vehicle_applying=False, **FLYING_AT_1M)) is State.PILOT


def test_first_signal_lands_second_hands_back() -> None:
    sup = Supervisor()
    t = airborne(sup)
    assert sup.update(obs(t + 0.1, stop_requests=1, **FLYING_AT_1M)) is State.LAND
    assert sup.update(obs(t + 0.2, stop_requests=1, **FLYING_AT_1M)) is State.LAND
    assert sup.update(obs(t + 0.3, stop_requests=2, **FLYING_AT_1M)) is State.HANDBACK
    assert sup.success  # a requested stop is a normal end


def test_signal_with_handback_configured() -> None:
    sup = Supervisor(SupervisorLimits(on_signal="handback"))
    t = airborne(sup)
    assert sup.update(obs(t + 0.1, stop_requests=1, **FLYING_AT_1M)) is State.HANDBACK


def test_signal_before_takeoff_hands_back() -> None:
    sup = Supervisor()
    assert sup.update(obs(0.0, estimator_ok=False, stop_requests=1)) is State.HANDBACK
    assert sup.success


def test_no_data_before_takeoff_is_a_preflight_failure() -> None:
    sup = Supervisor(SupervisorLimits(preflight_timeout_s=2.0))
    assert sup.update(obs(0.0, data_age_s=math.inf, data_rate_hz=0.0)) is State.PREFLIGHT
    assert "no DATA" in sup.preflight_failures[0]
    assert sup.update(obs(2.5, data_age_s=math.inf, data_rate_hz=0.0)) is State.ABORTED


def test_terminal_states_stay_terminal() -> None:
    sup = Supervisor()
    t = airborne(sup)
    sup.update(obs(t + 1.0, data_age_s=1.0, **FLYING_AT_1M))
    assert sup.state is State.LINK_LOST
    assert sup.update(obs(t + 2.0)) is State.LINK_LOST


def test_a_takeoff_that_does_not_complete_lands_after_the_timeout() -> None:
    sup = Supervisor(SupervisorLimits(takeoff_timeout_s=12.0))
    assert sup.update(obs(1.0)) is State.TAKEOFF
    stuck = {"position": (0.0, 0.0, -0.3), "height_above_ground_m": 0.3}
    with capture_logs() as logs:
        assert sup.update(obs(13.0, **stuck)) is State.TAKEOFF  # 12 s: not yet
        assert sup.update(obs(13.01, **stuck)) is State.LAND
    reason = sup.transitions[-1].reason
    assert "take-off timeout" in reason and "12.0 s" in reason and "(0.00, 0.00, -0.30)" in reason
    assert [(e["log_level"], e["failsafe"], e["new"]) for e in logs] == [
        ("warning", True, "LAND")]
    # a take-off that completes in time is not affected
    sup = Supervisor(SupervisorLimits(takeoff_timeout_s=12.0))
    sup.update(obs(1.0))
    assert sup.update(obs(12.9, takeoff_done=True, **FLYING_AT_1M)) is State.TRACK
    assert sup.update(obs(30.0, **FLYING_AT_1M)) is State.TRACK


def test_the_takeoff_timeout_comes_from_the_configuration() -> None:
    from groundstation.config import validate_config
    from groundstation.flight.assembly import supervisor_limits

    cfg = validate_config({"safety": {"takeoff_timeout_s": 7.5}})
    assert supervisor_limits(cfg).takeoff_timeout_s == 7.5


def test_outcome_completed_stopped_and_failsafe() -> None:
    """The outcome is `gs fly`'s exit code: 0 completed, 4 stopped on request, 1 failsafe."""
    sup = Supervisor()
    t = airborne(sup)
    sup.update(obs(t + 1, trajectory_done=True, **FLYING_AT_1M))
    sup.update(obs(t + 2, height_above_ground_m=0.01))
    sup.update(obs(t + 2.6, height_above_ground_m=0.01))
    sup.update(obs(t + 3.2, height_above_ground_m=0.0))
    assert sup.state is State.DONE and sup.outcome is Outcome.COMPLETED and sup.outcome == 0

    stopped = Supervisor()
    t = airborne(stopped)
    stopped.update(obs(t + 0.1, stop_requests=1, **FLYING_AT_1M))
    stopped.update(obs(t + 0.2, stop_requests=2, **FLYING_AT_1M))
    assert stopped.state is State.HANDBACK and stopped.outcome is Outcome.STOPPED
    assert stopped.outcome == 4 and stopped.success
    assert not any(tr.failsafe for tr in stopped.transitions)


@pytest.mark.parametrize("change", [
    {"tilt_rad": math.radians(50.0)},  # e.g. H-infinity over the tilt limit
    {"vicon_age_s": 5.0},  # Vicon lost 5 s
])
def test_a_failsafe_landing_is_not_a_normal_end(change: dict[str, object]) -> None:
    """These landings ended in DONE and counted as a normal end (exit 0)."""
    sup = Supervisor()
    t = airborne(sup)
    with capture_logs() as logs:
        assert sup.update(obs(t + 0.1, **{**FLYING_AT_1M, **change})) is State.LAND
    sup.update(obs(t + 1.0, height_above_ground_m=0.0))
    sup.update(obs(t + 1.6, height_above_ground_m=0.0))
    sup.update(obs(t + 2.2, height_above_ground_m=0.0))
    assert sup.state is State.DONE
    assert sup.outcome is Outcome.FAILSAFE and not sup.success
    assert [tr.failsafe for tr in sup.transitions] == [False, False, True, False, False]
    assert [(e["log_level"], e["failsafe"]) for e in logs] == [("warning", True)]


@pytest.mark.parametrize(("change", "state"), [
    ({"data_age_s": 1.0}, State.LINK_LOST),
    ({"pilot_enabled": False}, State.PILOT),
    ({"estimator_diverged": True}, State.HANDBACK),
])
def test_every_global_failsafe_is_marked_and_warned(change: dict[str, object],
                                                    state: State) -> None:
    sup = Supervisor()
    t = airborne(sup)
    with capture_logs() as logs:
        assert sup.update(obs(t + 0.1, **{**FLYING_AT_1M, **change})) is state
    assert sup.transitions[-1].failsafe and sup.outcome is Outcome.FAILSAFE
    assert [(e["log_level"], e["failsafe"]) for e in logs] == [("warning", True)]


def test_a_short_watchdog_expiry_in_the_air_is_an_event_with_its_duration() -> None:
    sup = Supervisor()
    t = airborne(sup)
    with capture_logs() as logs:
        assert sup.update(obs(t + 0.01, vehicle_applying=False, **FLYING_AT_1M)) is State.TRACK
        assert sup.update(obs(t + 0.02, vehicle_applying=False, **FLYING_AT_1M)) is State.TRACK
        assert sup.update(obs(t + 0.09, vehicle_applying=True, **FLYING_AT_1M)) is State.TRACK
    (event,) = sup.events
    assert event.kind == "watchdog" and event.t == t + 0.01
    assert event.duration_s == pytest.approx(0.08)
    assert "80 ms" in event.reason
    assert [(e["log_level"], e["failsafe"], e["kind"], e["duration_s"]) for e in logs] == [
        ("warning", True, "watchdog", 0.08)]
    assert sup.outcome is Outcome.FAILSAFE  # even if the flight then completes


def test_the_first_command_taking_effect_is_not_an_expiry() -> None:
    """At take-off the vehicle applies nothing until the first COMMAND arrives."""
    sup = Supervisor()
    assert sup.update(obs(0.0, vehicle_applying=False)) is State.TAKEOFF
    assert sup.update(obs(0.05, vehicle_applying=False)) is State.TAKEOFF
    assert sup.update(obs(0.06, vehicle_applying=True)) is State.TAKEOFF
    assert not sup.events


def test_battery_below_the_limit_refuses_take_off_and_lands_after_the_grace_time() -> None:
    limits = SupervisorLimits(battery_land_v=10.5, battery_grace_s=10.0)
    sup = Supervisor(limits)
    assert sup.update(obs(0.0, battery_v=10.4)) is State.PREFLIGHT
    assert sup.preflight_failures == ["battery 10.40 V < 10.50 V"]
    assert sup.update(obs(0.1, battery_v=11.1)) is State.TAKEOFF
    sup.update(obs(1.0, takeoff_done=True, **FLYING_AT_1M))
    assert sup.update(obs(2.0, battery_v=10.4, **FLYING_AT_1M)) is State.TRACK
    assert sup.update(obs(11.9, battery_v=10.4, **FLYING_AT_1M)) is State.TRACK
    assert sup.update(obs(12.0, battery_v=10.6, **FLYING_AT_1M)) is State.TRACK  # recovered
    assert sup.update(obs(21.9, battery_v=10.4, **FLYING_AT_1M)) is State.TRACK  # restarts
    with capture_logs() as logs:
        assert sup.update(obs(31.9, battery_v=10.3, **FLYING_AT_1M)) is State.LAND
    assert sup.transitions[-1].reason == "battery 10.30 V below 10.50 V for 10.0 s"
    assert sup.transitions[-1].failsafe and logs[0]["log_level"] == "warning"
    # NaN (no STATUS block) never triggers it
    quiet = Supervisor(limits)
    assert quiet.update(obs(0.0, battery_v=math.nan)) is State.TAKEOFF


def test_force_ends_the_flight_as_a_failsafe() -> None:
    sup = Supervisor()
    t = airborne(sup)
    with capture_logs() as logs:
        assert sup.force(t + 1, State.LINK_LOST, "serial link failed: EIO") is State.LINK_LOST
    assert sup.terminal and sup.transitions[-1].failsafe
    assert logs[0]["log_level"] == "warning" and logs[0]["new"] == "LINK_LOST"
    assert sup.force(t + 2, State.ABORTED, "late") is State.LINK_LOST  # terminal stays


def test_transition_kinds_decide_what_a_report_explains() -> None:
    """The report shows the reason of every transition that is not a step of a nominal
    flight, from the supervisor's transition kinds, not from its wording."""
    from groundstation.evaluation.report import states_line

    nominal = Supervisor()
    t = airborne(nominal)
    nominal.update(obs(t + 1, trajectory_done=True, **FLYING_AT_1M))
    nominal.update(obs(t + 3, height_above_ground_m=0.01))
    nominal.update(obs(t + 3.6, height_above_ground_m=0.01))
    nominal.update(obs(t + 4.2, height_above_ground_m=0.0))
    assert nominal.state is State.DONE
    assert all(tr.nominal and not tr.failsafe for tr in nominal.transitions)
    assert states_line(nominal.transitions) == "TAKEOFF -> TRACK -> LAND -> DISARM -> DONE"

    held = Supervisor()
    t = airborne(held)
    held.update(obs(t + 0.6, vicon_age_s=0.6, **FLYING_AT_1M))
    held.update(obs(t + 0.7, vicon_age_s=0.01, **FLYING_AT_1M))
    held.update(obs(t + 0.8, stop_requests=1, **FLYING_AT_1M))
    kinds = [(tr.new, tr.nominal, tr.failsafe) for tr in held.transitions[2:]]
    assert kinds == [(State.HOLD, False, True), (State.TRACK, False, False),
                     (State.LAND, False, False)]
    line = states_line(held.transitions)
    assert line.startswith("TAKEOFF -> TRACK -> HOLD (")
    assert "TRACK (Vicon back)" in line and line.count("(") == 3


def land_from_1m(sup: Supervisor) -> float:
    t = airborne(sup)
    assert sup.update(obs(t + 1, trajectory_done=True, **FLYING_AT_1M)) is State.LAND
    return t + 1


def test_a_landing_on_dead_reckoning_alone_is_not_confirmed_and_is_handed_back() -> None:
    """The fly-away's end: the estimate (Vicon lost, IMU only) reached the floor with the
    vehicle 9 m up. Without Vicon and without the floor's contact signature nothing is
    disarmed: after landing_confirm_s the pilot gets the vehicle with the thrust it had."""
    sup = Supervisor()
    t = land_from_1m(sup)
    blind = {"vicon_age_s": 3.0, "position": (0.0, 0.0, -0.01), "height_above_ground_m": 0.01,
             "lift_fraction": 0.95, "specific_force_g": 1.0}
    lim = sup.limits
    wait = lim.landed_time_s + lim.landing_confirm_s  # from the first tick at the floor
    for dt in (0.1, 0.7, 1.5, 0.05 + wait):
        assert sup.update(obs(t + dt, **blind)) is State.LAND
    assert sup.update(obs(t + 0.15 + wait, **blind)) is State.HANDBACK
    assert "landing not confirmed" in sup.transitions[-1].reason
    assert sup.transitions[-1].failsafe and not any(
        tr.new is State.DISARM for tr in sup.transitions)


@pytest.mark.parametrize(("height", "vicon_age", "disarmed"), [
    (0.01, 0.01, True),  # the estimate at the floor while Vicon is fused
    (0.30, 3.0, True),  # contact felt near the floor on dead reckoning (drifted 30 cm)
    (1.90, 3.0, False),  # "contact" with the estimate 1.9 m up: a thrust fault, not a floor
    (0.30, 0.01, False),  # Vicon fused says 30 cm: whatever the accelerometer says, not down
])
def test_floor_contact_counts_only_near_the_floor(height: float, vicon_age: float,
                                                  disarmed: bool) -> None:
    sup = Supervisor()
    t = land_from_1m(sup)
    felt = {"vicon_age_s": vicon_age, "position": (0.0, 0.0, -height),
            "height_above_ground_m": height, "lift_fraction": 0.3, "specific_force_g": 1.0}
    sup.update(obs(t + 0.1, **felt))
    end = sup.update(obs(t + 0.7, **felt))
    assert end is (State.DISARM if disarmed else State.LAND)


WHY = "3 consistent Vicon poses disagreed with the estimate for 0.30 s"


def test_an_estimate_overruled_by_vicon_hands_back_by_default() -> None:
    sup = Supervisor()
    t = airborne(sup)
    assert sup.update(obs(t + 0.1, overruled=WHY, **FLYING_AT_1M)) is State.HANDBACK
    assert sup.transitions[-1].failsafe and WHY in sup.transitions[-1].reason


def test_an_estimate_overruled_by_vicon_lands_when_configured_and_a_landing_goes_on() -> None:
    sup = Supervisor(SupervisorLimits(on_overruled="land"))
    t = airborne(sup)
    assert sup.update(obs(t + 0.1, overruled=WHY, **FLYING_AT_1M)) is State.LAND
    assert sup.transitions[-1].failsafe and WHY in sup.transitions[-1].reason
    default = Supervisor()
    t = land_from_1m(default)
    assert default.update(obs(t + 0.1, overruled=WHY, **FLYING_AT_1M)) is State.LAND


def test_a_reference_fault_lands() -> None:
    sup = Supervisor()
    t = airborne(sup)
    why = "it asks 82 deg of tilt (69.0 m/s^2)"
    assert sup.update(obs(t + 0.1, reference_fault=why, **FLYING_AT_1M)) is State.LAND
    assert sup.transitions[-1].reason == f"reference fault: {why}"


def test_a_second_vicon_stream_lands_by_default() -> None:
    sup = Supervisor()
    t = airborne(sup)
    assert sup.update(obs(t + 0.1, vicon_rivals=1, **FLYING_AT_1M)) is State.LAND
    assert "second Vicon pose stream" in sup.transitions[-1].reason
    assert sup.transitions[-1].failsafe


def test_a_second_vicon_stream_holds_until_it_stops_when_configured() -> None:
    sup = Supervisor(SupervisorLimits(on_second_stream="hold"))
    t = airborne(sup)
    assert sup.update(obs(t + 0.1, vicon_rivals=1, **FLYING_AT_1M)) is State.HOLD
    assert sup.update(obs(t + 0.5, vicon_rivals=1, **FLYING_AT_1M)) is State.HOLD
    assert sup.update(obs(t + 0.6, **FLYING_AT_1M)) is State.TRACK
    assert sup.update(obs(t + 0.7, vicon_rivals=1, **FLYING_AT_1M)) is State.HOLD
    assert sup.update(obs(t + 2.6, vicon_rivals=1, **FLYING_AT_1M)) is State.HOLD
    assert sup.update(obs(t + 2.8, vicon_rivals=1, **FLYING_AT_1M)) is State.LAND


@pytest.mark.parametrize(("change", "failure"), [
    ({"position": (2.0, 0.0, 0.0)}, "outside the volume"),
    ({"vicon_rivals": 1}, "second Vicon pose stream"),
])
def test_preflight_refuses_a_vehicle_outside_the_volume_or_two_streams(
        change: dict[str, object], failure: str) -> None:
    sup = Supervisor(SupervisorLimits(preflight_timeout_s=1.0))
    assert sup.update(obs(0.0, **change)) is State.PREFLIGHT
    assert sup.update(obs(1.1, **change)) is State.ABORTED
    assert failure in sup.transitions[-1].reason


def test_a_vicon_preflight_failure_says_what_the_pose_filter_saw() -> None:
    sup = Supervisor(SupervisorLimits(preflight_timeout_s=1.0))
    seen = "412 datagrams, 0 poses of 'X3D' passed: 412 refused as held-identity"
    silent = {"vicon_rate_hz": 0.0, "vicon_age_s": math.inf, "vicon_diagnosis": lambda: seen}
    assert sup.update(obs(0.0, **silent)) is State.PREFLIGHT
    assert sup.update(obs(1.1, **silent)) is State.ABORTED
    assert sup.transitions[-1].reason.endswith(f"Vicon: {seen}")
