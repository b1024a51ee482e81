"""LQR design with reference models (Ch. 9) against independent answers.

Independent references: scipy's cont2discrete (ZOH), python-control's dlqr, the
scalar DARE closed form, the thesis's own Algorithm 3 iterated on the whole
augmented system of eq. 9.16-9.20, and simulations of the linear closed loop.
"""

from __future__ import annotations

import math

import control
import numpy as np
import pytest
import scipy.signal

from groundstation.control.lqr import H_OUTPUTS, LqrController
from groundstation.control.lqr_design import (
    design_tracking_lqr,
    discretise,
    dlqr,
    full_tracking_system,
    reference_model,
    riccati_iteration,
)
from groundstation.errors import ControlError
from groundstation.model import QuadrotorParams, hover_model, hover_model_reduced

DT = 0.01
Q_E = np.diag([8.0, 8.0, 20.0, 2.0])
R = np.diag([4.0, 4.0, 4.0, 2.0])


@pytest.fixture(scope="module")
def plant() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    Phi, Gamma = discretise(*_ab(), DT)
    H = np.zeros((4, 9))
    H[np.arange(4), H_OUTPUTS] = 1.0
    return Phi, Gamma, H


def _ab() -> tuple[np.ndarray, np.ndarray]:
    m = hover_model_reduced(QuadrotorParams())
    return m.A, m.B


def test_zoh_matches_scipy_cont2discrete() -> None:
    A, B = _ab()
    Phi, Gamma = discretise(A, B, DT)
    ref = scipy.signal.cont2discrete((A, B, np.eye(9), np.zeros((9, 4))), DT, method="zoh")
    np.testing.assert_allclose(Phi, ref[0], atol=1e-14)
    np.testing.assert_allclose(Gamma, ref[1], atol=1e-14)


def test_q0_is_why_the_full_model_is_not_stabilisable() -> None:
    # eq. 4.18: q0_dot = 0 and no input reaches it: an uncontrollable pole at z = 1
    full = hover_model(QuadrotorParams())
    Phi, Gamma = discretise(full.A, full.B, DT)
    ctrb = np.hstack([np.linalg.matrix_power(Phi, k) @ Gamma for k in range(10)])
    assert np.linalg.matrix_rank(ctrb) == 9  # of 10 states
    Phi_r, Gamma_r = discretise(*_ab(), DT)
    ctrb_r = np.hstack([np.linalg.matrix_power(Phi_r, k) @ Gamma_r for k in range(9)])
    assert np.linalg.matrix_rank(ctrb_r) == 9


def test_scalar_dlqr_matches_the_closed_form() -> None:
    # x+ = a x + b u, weights q, r: P solves b^2 P^2 + (r - a^2 r - q b^2) P - q r = 0
    a, b, q, r = 1.0, 0.1, 2.0, 0.5
    K, P = dlqr(np.array([[a]]), np.array([[b]]), np.array([[q]]), np.array([[r]]))
    c2, c1, c0 = b * b, r - a * a * r - q * b * b, -q * r
    p_closed = (-c1 + math.sqrt(c1 * c1 - 4 * c2 * c0)) / (2 * c2)
    assert P[0, 0] == pytest.approx(p_closed, rel=1e-10)
    assert K[0, 0] == pytest.approx(-a * b * p_closed / (r + b * b * p_closed), rel=1e-10)


def test_a_design_asked_again_is_the_same_and_its_arrays_are_the_callers(plant) -> None:
    """Designs are remembered per process: the second answer equals python-control's like
    the first, whatever the first caller did to the arrays it got."""
    Phi, Gamma, H = plant
    Q = H.T @ Q_E @ H
    K_ctrl, P_ctrl, _ = control.dlqr(Phi, Gamma, Q, R)
    first, P_first = dlqr(Phi, Gamma, Q, R)
    first *= 0.0
    P_first[:] = np.nan
    again, P_again = dlqr(Phi.copy(), Gamma.copy(), Q, R)
    np.testing.assert_allclose(again, -K_ctrl, rtol=1e-7, atol=1e-9)
    np.testing.assert_allclose(P_again, P_ctrl, rtol=1e-7, atol=1e-9)
    A, B = _ab()
    Phi1, Gamma1 = discretise(A, B, DT)
    Phi1[:] = 0.0
    Gamma1[:] = 0.0
    np.testing.assert_array_equal(discretise(A, B, DT)[0], Phi)
    np.testing.assert_array_equal(discretise(A, B, DT)[1], Gamma)
    # another sample time is another design
    assert not np.array_equal(discretise(A, B, 2 * DT)[0], Phi)


def test_plant_gain_matches_python_control(plant) -> None:
    Phi, Gamma, H = plant
    gains = design_tracking_lqr(Phi, Gamma, H, Q_E, R, reference="position", dt=DT)
    K_ctrl, _, _ = control.dlqr(Phi, Gamma, H.T @ Q_E @ H, R)
    np.testing.assert_allclose(gains.K_s, -K_ctrl, rtol=1e-7, atol=1e-9)  # thesis sign u = K x


@pytest.mark.parametrize("kind", ["position", "velocity"])
@pytest.mark.parametrize("integral", [False, True])
def test_blockwise_solution_equals_algorithm_3(plant, kind: str, integral: bool) -> None:
    Phi, Gamma, H = plant
    Q_i = np.diag([0.5, 0.5, 2.0]) if integral else None
    integrate = [0, 1, 2] if integral else None
    gains = design_tracking_lqr(Phi, Gamma, H, Q_E, R, reference=kind, dt=DT, Q_i=Q_i,
                                integrate=integrate)
    F, G, Q = full_tracking_system(Phi, Gamma, H, Q_E, reference=kind, dt=DT, Q_i=Q_i,
                                   integrate=integrate)
    K_iter, iterations = riccati_iteration(F, G, Q, R, tol=1e-10)
    assert iterations > 100  # it really iterated
    K = np.hstack([gains.K_s, gains.K_i, gains.K_r])
    np.testing.assert_allclose(K, K_iter, atol=1e-6)
    assert np.max(np.abs(gains.closed_loop_poles)) < 1.0


def test_reference_models_are_eq_9_25_and_9_26() -> None:
    Phi_r, H_r = reference_model("velocity", 1)
    np.testing.assert_array_equal(Phi_r, [[2, -1], [1, 0]])
    np.testing.assert_array_equal(H_r, [[1, 0]])
    r = np.array([3.0, 1.0])  # r(k) = 3, r(k-1) = 1: the next is 5 (constant velocity)
    assert (Phi_r @ r)[0] == 5.0
    Phi_p, H_p = reference_model("position", 4)
    np.testing.assert_array_equal(Phi_p, np.eye(4))
    np.testing.assert_array_equal(H_p, np.eye(4))
    with pytest.raises(ControlError, match="unknown reference model"):
        reference_model("acceleration", 4)  # type: ignore[arg-type]


@pytest.mark.parametrize("kind", ["position", "velocity"])
def test_hover_at_any_reference_is_an_equilibrium(plant, kind: str) -> None:
    # zero error and zero input must hold together: K_s T + sum of K_r blocks = 0,
    # T placing r on the x, y, z, q3 states (a property, not the design equations)
    Phi, Gamma, H = plant
    g = design_tracking_lqr(Phi, Gamma, H, Q_E, R, reference=kind, dt=DT)
    blocks = g.K_r[:, :4] + (g.K_r[:, 4:] if kind == "velocity" else 0.0)
    np.testing.assert_allclose(g.K_s @ H.T + blocks, 0.0, atol=1e-8)


def _ramp_error(kind: str, plant) -> float:
    """Steady x error of the linear closed loop following x_ref = 0.2 t."""
    Phi, Gamma, H = plant
    g = design_tracking_lqr(Phi, Gamma, H, Q_E, R, reference=kind, dt=DT)
    x = np.zeros(9)
    err = 0.0
    for k in range(3000):
        r = np.array([0.2 * k * DT, 0.0, 0.0, 0.0])
        r_prev = np.array([0.2 * (k - 1) * DT, 0.0, 0.0, 0.0])
        x_r = r if kind == "position" else np.concatenate([r, r_prev])
        err = float(r[0] - x[0])
        x = Phi @ x + Gamma @ (g.K_s @ x + g.K_r @ x_r)
    return err


def test_constant_velocity_model_follows_a_ramp_without_error(plant) -> None:
    # the thesis's central claim (Ch. 9.2.1, 11.3) on the linear model: the velocity
    # model feeds the reference velocity forward, the position model lags
    assert abs(_ramp_error("velocity", plant)) < 1e-6
    lag_error = _ramp_error("position", plant)
    assert lag_error > 0.05  # behind the reference by v * lag


def test_design_validation(plant) -> None:
    Phi, Gamma, H = plant
    with pytest.raises(ControlError, match="R must be positive definite"):
        design_tracking_lqr(Phi, Gamma, H, Q_E, np.zeros((4, 4)), reference="position", dt=DT)
    with pytest.raises(ControlError, match=r"H_s must have shape \(4, 9\)"):
        design_tracking_lqr(Phi, Gamma, H[:, :8], Q_E, R, reference="position", dt=DT)
    with pytest.raises(ControlError, match="q_integral"):
        LqrController(q_integral=[1.0, -1.0, 0.0, 0.0])
    with pytest.raises(ControlError, match="no stabilising solution"):
        # a detectable-but-unstabilisable pair: the input cannot reach the unstable state
        dlqr(np.diag([1.1, 0.5]), np.array([[0.0], [1.0]]), np.eye(2), np.eye(1))
