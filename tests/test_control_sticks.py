"""Conversion of controller outputs to stick units: inverse of the model's forward map."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from groundstation.control import CommandLimits, StickParams, to_sticks
from groundstation.model import QuadrotorParams, inputs_from_sticks
from groundstation.types import ControlOutput

PARAMS = QuadrotorParams()
SP = StickParams.from_quadrotor(PARAMS)


def test_round_trip_through_the_model_forward_map() -> None:
    # independent answer: eq. 3.7 and 3.22 evaluated forward by groundstation.model
    out = ControlOutput(omega=np.array([0.5, -1.0, 0.2]), f_z=-1.3)
    sticks, flags = to_sticks(out, SP)
    assert not flags.any
    back = inputs_from_sticks(sticks, PARAMS)
    np.testing.assert_allclose(back[0:3], out.omega, atol=0.5 * 1.1e-3)  # half a unit
    slope = abs(SP.thrust_map.slope(sticks.thrust))
    assert back[3] == pytest.approx(out.f_z, abs=0.5 * slope)
    # positive stick = positive FRD rate (DESIGN.md); more lift (F_z < 0) = more stick
    assert (sticks.roll, sticks.pitch, sticks.yaw) == (455, -909, 182)
    assert sticks.thrust > SP.hover_thrust


def test_hover_is_mid_stick() -> None:
    sticks, _ = to_sticks(ControlOutput(omega=np.zeros(3), f_z=0.0), SP)
    # F_lift(u) = -m g at the hover stick (eq. 3.7 with m = 0.6 kg: about 1990)
    assert abs(SP.thrust_map.force(sticks.thrust) + 0.6 * 9.82) < 2e-3
    assert 1950 < sticks.thrust < 2050


def test_saturation_is_flagged_per_channel() -> None:
    out = ControlOutput(omega=np.array([10.0, -10.0, 0.0]), f_z=50.0)
    sticks, flags = to_sticks(out, SP)
    assert (sticks.roll, sticks.pitch, sticks.thrust) == (2047, -2048, 0)
    assert flags.roll and flags.pitch and flags.thrust and not flags.yaw
    sticks, flags = to_sticks(ControlOutput(omega=np.zeros(3), f_z=-50.0), SP)
    assert flags.thrust and sticks.thrust == round(SP.thrust_map.u_max)


def test_non_finite_output_becomes_a_safe_flagged_command() -> None:
    sticks, flags = to_sticks(ControlOutput(omega=np.array([math.nan, 0, 0]), f_z=0.0), SP)
    assert flags.invalid
    assert (sticks.roll, sticks.pitch, sticks.yaw, sticks.thrust) == (0, 0, 0, SP.hover_thrust)


def test_command_limits_in_physical_units() -> None:
    lim = CommandLimits.from_stick_params(SP)
    np.testing.assert_allclose(lim.omega_max, 2047 * 1.1e-3)
    np.testing.assert_allclose(lim.omega_min, -2048 * 1.1e-3)
    # the reachable F_z spans the monotonic thrust range, hover (0 N) inside it
    assert lim.f_z_min < 0.0 < lim.f_z_max
    assert lim.f_z_max == pytest.approx(-0.903 + 0.6 * 9.82)  # F_lift(0) + m g


finite_or_not = st.floats(allow_nan=True, allow_infinity=True, width=64)


@given(st.tuples(finite_or_not, finite_or_not, finite_or_not), finite_or_not)
def test_sticks_never_leave_the_command_ranges(omega: tuple[float, float, float],
                                               f_z: float) -> None:
    sticks, _ = to_sticks(ControlOutput(omega=np.array(omega), f_z=f_z), SP)
    for value in (sticks.roll, sticks.pitch, sticks.yaw):
        assert isinstance(value, int) and -2048 <= value <= 2047
    assert isinstance(sticks.thrust, int) and 0 <= sticks.thrust <= 4096
