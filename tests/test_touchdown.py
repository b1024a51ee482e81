"""The landing on the IMU alone feels for the floor (groundstation/flight/touchdown.py):
the cap on the lift against its closed form, and what ends it, on made-up samples."""

from __future__ import annotations

import math

import numpy as np
import pytest

from groundstation.flight.supervisor import SupervisorLimits
from groundstation.flight.touchdown import (
    FORCE_FILTER_S,
    LIFT_FLOOR,
    LIFT_RAMP_PER_S,
    TouchdownProbe,
)

TOLERANCE = SupervisorLimits().contact_accel_tolerance
DT = 0.01  # the IMU's period [s]


def test_on_the_floor_the_cap_falls_from_the_lift_commanded_to_below_contact() -> None:
    probe = TouchdownProbe(TOLERANCE)
    assert probe.update(0.0, True, False, 1.0, 1.04) is None  # the estimate not yet down
    times = np.arange(1.0, 4.0, DT)
    caps = [probe.update(float(t), True, True, 1.0, 1.04) for t in times]
    expected = np.maximum(LIFT_FLOOR, 1.0 - LIFT_RAMP_PER_S * (times - 1.0))  # from 1, not 1.04
    assert caps == pytest.approx(expected.tolist(), abs=1e-12)
    # below the supervisor's contact fraction within 1.5 s: contact can be felt
    below = times[np.array(caps) < SupervisorLimits().contact_lift_fraction][0] - 1.0
    assert below == pytest.approx(0.4 / LIFT_RAMP_PER_S, abs=DT)
    assert not probe.airborne


def test_a_lower_lift_starts_the_cap_lower() -> None:
    probe = TouchdownProbe(TOLERANCE)
    assert probe.update(0.0, True, True, 1.0, 0.8) == pytest.approx(0.8)
    assert probe.update(0.5, True, True, 1.0, 0.8) == pytest.approx(0.8 - 0.5 * LIFT_RAMP_PER_S)


def test_in_the_air_the_falling_specific_force_ends_the_probe_for_the_landing() -> None:
    """In the air the specific force follows the lift: below 1 - tolerance the vehicle is
    not on the floor, and the controller has its thrust back for the rest of the landing."""
    probe = TouchdownProbe(TOLERANCE)
    t, cap = 0.0, probe.update(0.0, True, True, 1.0, 1.0)
    while cap is not None:
        t += DT
        cap = probe.update(t, True, True, cap, cap)  # free flight: the force is the lift
    assert probe.airborne
    # the filtered force crosses 1 - tolerance about one filter constant after the lift
    assert t == pytest.approx(TOLERANCE / LIFT_RAMP_PER_S + FORCE_FILTER_S, abs=2 * DT)
    for k in range(100):  # the estimate still at the floor, still no Vicon: no new probe
        assert probe.update(t + DT * (k + 1), True, True, 1.0, 1.0) is None
    probe.update(t + 2.0, False, True, 1.0, 1.0)  # Vicon back (or the landing over)
    assert not probe.airborne
    assert probe.update(t + 2.0 + DT, True, True, 1.0, 1.0) == pytest.approx(1.0)


def test_one_sample_of_a_knock_does_not_end_it() -> None:
    """A single IMU sample 0.4 g low (a knock on the floor) moves the filtered force by
    0.4 (1 - exp(-dt / tau)), 0.07 g: short of the tolerance."""
    probe = TouchdownProbe(TOLERANCE)
    for k in range(50):
        probe.update(k * DT, True, True, 1.0, 1.0)
    assert probe.update(0.5, True, True, 0.6, 1.0) is not None
    assert 0.4 * (1.0 - math.exp(-DT / FORCE_FILTER_S)) < TOLERANCE
    assert not probe.airborne


def test_with_vicon_or_off_the_floor_nothing_is_capped() -> None:
    probe = TouchdownProbe(TOLERANCE)
    assert probe.update(0.0, False, True, 1.0, 1.0) is None  # Vicon fused: its floor
    assert probe.update(0.1, True, False, 1.0, 1.0) is None  # the estimate above the floor
    assert probe.update(0.2, True, True, 1.0, 1.0) == pytest.approx(1.0)  # starts now
    assert probe.update(0.3, True, False, 1.0, 0.97) is None  # back above: no cap ...
    assert probe.update(0.4, True, True, 1.0, 0.97) == pytest.approx(0.97)  # ... and anew
