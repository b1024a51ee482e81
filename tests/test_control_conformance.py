"""Every controller honours the Controller protocol, and the protocol means something.

The assertions are physical: at hover exactly on the reference (the linearisation
point of eq. 4.1-4.3) every controller must ask for zero body rates and F_z = 0
(lift equals weight, eq. 4.14); a position error must tilt the vehicle towards
the reference (nose down to go north: negative pitch rate, eq. 4.22); a reset
controller repeats its first output.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest

from groundstation.control import (
    Controller,
    LqrController,
    NullController,
    PidController,
)
from groundstation.control.hinf import HinfController, default_gain_path, load_hinf_gain
from groundstation.control.lqr_ff import FeedforwardLqr
from groundstation.model.quaternion import multiply
from groundstation.types import ControlOutput, Reference, StateEstimate

FACTORIES: dict[str, Callable[[], Controller]] = {
    "null": NullController,
    "lqr-cp": lambda: LqrController(reference_model="position"),
    "lqr-cv": lambda: LqrController(reference_model="velocity"),
    "lqr-integral": lambda: LqrController(q_integral=(0.5, 0.5, 2.0, 0.0),
                                          disturbance_tau=None),
    "lqr-thesis-model": lambda: LqrController(design_model="thesis"),
    "lqr-ff": FeedforwardLqr,
    "pid": PidController,
    "hinf-thesis": lambda: HinfController(load_hinf_gain(default_gain_path(False))),
    "hinf-rate-loop": lambda: HinfController(load_hinf_gain(default_gain_path(True))),
}
FLYING = [name for name in FACTORIES if name != "null"]


def estimate(position: tuple[float, float, float] = (0.0, 0.0, -1.0),
             quaternion: tuple[float, ...] = (1.0, 0.0, 0.0, 0.0),
             velocity_body: tuple[float, ...] = (0.0, 0.0, 0.0),
             omega: tuple[float, ...] = (0.0, 0.0, 0.0)) -> StateEstimate:
    return StateEstimate(
        t=0.0, position=np.array(position, dtype=float),
        quaternion=np.array(quaternion, dtype=float),
        velocity_body=np.array(velocity_body, dtype=float), omega=np.array(omega, dtype=float),
        gyro_bias=np.zeros(3), acc_bias=np.zeros(3), covariance_diag=np.full(16, 1e-4),
    )


def reference(position: tuple[float, float, float] = (0.0, 0.0, -1.0), yaw: float = 0.0,
              velocity: tuple[float, ...] = (0.0, 0.0, 0.0),
              acceleration: tuple[float, ...] = (0.0, 0.0, 0.0)) -> Reference:
    return Reference(t=0.0, position=np.array(position, dtype=float),
                     velocity=np.array(velocity, dtype=float),
                     acceleration=np.array(acceleration, dtype=float), yaw=yaw)


def _turn(v: tuple[float, ...], psi: float) -> tuple[float, float, float]:
    """The earth-axis vector ``v`` turned by ``psi`` about the vertical (NED z)."""
    c, s = np.cos(psi), np.sin(psi)
    return (c * v[0] - s * v[1], s * v[0] + c * v[1], v[2])


@pytest.mark.parametrize("name", list(FACTORIES))
def test_hover_on_the_reference_is_the_equilibrium(name: str) -> None:
    ctrl = FACTORIES[name]()
    assert isinstance(ctrl, Controller)
    for k in range(3):  # also after the filters and observers have seen samples
        out = ctrl.step(0.01 * k, estimate(), reference())
        assert isinstance(out, ControlOutput)
        assert out.omega.shape == (3,) and out.omega.dtype == np.float64
        # only rounding: K_s x + K_r r cancels gains of order 100 at z = -1
        np.testing.assert_allclose(out.omega, 0.0, atol=1e-9)
        assert out.f_z == pytest.approx(0.0, abs=1e-9)


@pytest.mark.parametrize("name", FLYING)
def test_an_error_commands_motion_towards_the_reference(name: str) -> None:
    ctrl = FACTORIES[name]()
    # reference 0.3 m north: pitch nose down (negative rate about body y, eq. 4.22)
    out = ctrl.step(0.0, estimate(), reference((0.3, 0.0, -1.0)))
    assert out.omega[1] < -0.01 and abs(out.omega[0]) < 1e-9
    ctrl.reset()
    # reference 0.3 m east: roll right (positive rate about body x, eq. 4.23)
    out = ctrl.step(0.0, estimate(), reference((0.0, 0.3, -1.0)))
    assert out.omega[0] > 0.01 and abs(out.omega[1]) < 1e-9
    ctrl.reset()
    # reference 0.3 m higher (z more negative): more lift, F_z < 0 (eq. 4.24)
    out = ctrl.step(0.0, estimate(), reference((0.0, 0.0, -1.3)))
    assert out.f_z < -0.05


@pytest.mark.parametrize("name", list(FACTORIES))
def test_reset_repeats_the_first_output(name: str) -> None:
    ctrl = FACTORIES[name]()
    est, ref = estimate((0.1, -0.2, -0.9)), reference((0.0, 0.0, -1.0))
    first = ctrl.step(0.0, est, ref)
    for k in range(1, 20):
        ctrl.step(0.01 * k, est, ref)
    ctrl.reset()
    again = ctrl.step(0.0, est, ref)
    np.testing.assert_array_equal(again.omega, first.omega)
    assert again.f_z == first.f_z
    # the output does not alias an internal buffer
    again.omega[:] = 99.0
    np.testing.assert_array_equal(ctrl.step(0.0, est, ref).omega != 99.0, True)


def test_null_controller_is_hover_thrust_and_zero_rates_anywhere() -> None:
    out = NullController().step(0.0, estimate((3.0, 3.0, -3.0)), reference())
    np.testing.assert_array_equal(out.omega, 0.0)
    assert out.f_z == 0.0


@pytest.mark.parametrize("psi_deg", [90.0, 135.0, 180.0, -100.0, 270.0])
@pytest.mark.parametrize("name", FLYING)
def test_the_output_does_not_depend_on_the_heading(name: str, psi_deg: float) -> None:
    """Turning the whole scene (vehicle, reference, its motion) about the vertical must
    not change what the vehicle is asked to do in its own body axes: the dynamics do
    not depend on the heading. The thesis's linearisation at q = [1, 0, 0, 0] fed
    earth-axis errors and failed this beyond small headings."""
    psi = np.radians(psi_deg)
    q_tilt = np.array([np.cos(0.04), 0.3 * np.sin(0.04), -0.9 * np.sin(0.04), 0.0])
    q_tilt /= np.linalg.norm(q_tilt)
    q_yaw0 = np.array([np.cos(0.1), 0.0, 0.0, np.sin(0.1)])
    q_turn = np.array([np.cos(psi / 2), 0.0, 0.0, np.sin(psi / 2)])
    p, r = (0.12, -0.07, -0.95), (0.3, 0.1, -1.0)
    v_body, w = (0.2, -0.1, 0.05), (0.1, -0.2, 0.05)
    a_ref, v_ref = (0.3, -0.2, 0.1), (0.1, 0.25, 0.0)
    outs = []
    for turn, q_turned in ((0.0, np.array([1.0, 0, 0, 0])), (psi, q_turn)):
        ctrl = FACTORIES[name]()
        q = multiply(q_turned, multiply(q_yaw0, q_tilt))
        out = None
        for k in range(3):  # also the filters, integrators and observers
            out = ctrl.step(0.02 * k, estimate(_turn(p, turn), tuple(q), v_body, w),
                            reference(_turn(r, turn), 0.3 + turn, _turn(v_ref, turn),
                                      _turn(a_ref, turn)))
        assert out is not None
        outs.append(out)
    np.testing.assert_allclose(outs[1].omega, outs[0].omega, atol=1e-9)
    assert outs[1].f_z == pytest.approx(outs[0].f_z, abs=1e-9)


@pytest.mark.parametrize("name", [n for n in FLYING if n != "pid"])
def test_the_heading_error_is_wrapped(name: str) -> None:
    """A reference heading one turn away is the same heading: the same output, and a
    reference just across +-180 degrees asks for the short way round (a small rate)."""
    q = (np.cos(np.radians(179.0) / 2), 0.0, 0.0, np.sin(np.radians(179.0) / 2))
    outs = [FACTORIES[name]().step(0.0, estimate(quaternion=q), reference(yaw=y))
            for y in (np.radians(-179.0), np.radians(-179.0) + 2 * np.pi)]
    np.testing.assert_allclose(outs[0].omega, outs[1].omega, atol=1e-12)
    # 2 degrees to go, counter-clockwise seen from above is positive yaw (NED, z down)
    assert 0.0 < outs[0].omega[2] < 0.2
