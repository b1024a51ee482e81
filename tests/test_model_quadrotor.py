"""Nonlinear quadrotor model (eq. 3.19-3.22) and the linear hover models (Ch. 4)."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import pytest
from scipy.signal import cont2discrete

from groundstation.model import (
    HOVER_STATE,
    QuadrotorModel,
    QuadrotorParams,
    hover_model,
    hover_model_rate_lag,
    hover_model_reduced,
    inputs_from_sticks,
    stick_input_gain,
)
from groundstation.model.quaternion import quat_from_euler
from groundstation.types import Sticks

PARAMS = QuadrotorParams()
MODEL = QuadrotorModel(PARAMS)


def _fd_jacobian(
    f: Callable[[np.ndarray], np.ndarray], x0: np.ndarray, h: float = 1e-6
) -> np.ndarray:
    cols = []
    for i in range(x0.size):
        e = np.zeros_like(x0)
        e[i] = h
        cols.append((f(x0 + e) - f(x0 - e)) / (2 * h))
    return np.column_stack(cols)


def test_hover_is_an_equilibrium() -> None:
    np.testing.assert_allclose(MODEL.derivative(HOVER_STATE, MODEL.hover_input()), 0.0, atol=1e-15)
    # an accelerometer at rest reads (0, 0, -g) (spec §3.3)
    np.testing.assert_allclose(MODEL.specific_force(HOVER_STATE, np.zeros(4)), [0, 0, -9.82])


def test_linear_model_is_the_jacobian_at_hover() -> None:
    lin = hover_model(PARAMS)
    u0 = np.zeros(4)
    A_fd = _fd_jacobian(lambda x: MODEL.derivative(x, u0), HOVER_STATE)
    B_fd = _fd_jacobian(lambda u: MODEL.derivative(HOVER_STATE, u), u0)
    np.testing.assert_allclose(lin.A, A_fd, atol=1e-7)
    np.testing.assert_allclose(lin.B, B_fd, atol=1e-7)


def test_reduced_model_is_the_jacobian_on_the_unit_sphere() -> None:
    # Independent construction: parameterise q by (q1, q2, q3) with q0 = sqrt(1 - |qv|^2).
    def f(z: np.ndarray, u: np.ndarray) -> np.ndarray:
        qv = z[3:6]
        x = np.r_[z[0:3], math.sqrt(1.0 - qv @ qv), qv, z[6:9]]
        xd = MODEL.derivative(x, u)
        return np.r_[xd[0:3], xd[4:7], xd[7:10]]

    z0 = np.r_[HOVER_STATE[0:3], 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]
    red = hover_model_reduced(PARAMS)
    np.testing.assert_allclose(red.A, _fd_jacobian(lambda z: f(z, np.zeros(4)), z0), atol=1e-7)
    np.testing.assert_allclose(red.B, _fd_jacobian(lambda u: f(z0, u), np.zeros(4)), atol=1e-7)
    assert red.states == ("x", "y", "z", "q1", "q2", "q3", "v1", "v2", "v3")


def test_erratum_4_14_tilt_accelerates_the_right_way() -> None:
    # Nose up (positive pitch) accelerates toward -x; right side down (positive roll) toward +y.
    for euler, axis, sign in (((0.0, 0.1, 0.0), 0, -1.0), ((0.1, 0.0, 0.0), 1, +1.0)):
        x = HOVER_STATE.copy()
        x[3:7] = quat_from_euler(*euler)
        vdot = MODEL.derivative(x, np.zeros(4))[7:10]
        assert np.sign(vdot[axis]) == sign
        assert abs(vdot[axis]) == pytest.approx(9.82 * math.sin(0.1), rel=1e-12)
    lin = hover_model(PARAMS)
    assert lin.A[lin.index("v1"), lin.index("q2")] == pytest.approx(-2 * 9.82)
    assert lin.A[lin.index("v2"), lin.index("q1")] == pytest.approx(+2 * 9.82)


def test_vertical_climb_matches_inflow_closed_form() -> None:
    # v3_dot = (F_z + I_i v3)/m  ->  v3(t) = -(F_z/I_i) (1 - exp(I_i t / m))   (eq. 4.24)
    f_z, dt = -0.5, 0.01
    x = HOVER_STATE.copy()
    u = np.array([0.0, 0.0, 0.0, f_z])
    for _ in range(300):
        x = MODEL.step(x, u, dt)
    t = 3.0
    i_i, m = PARAMS.inflow, PARAMS.mass
    v_exact = -(f_z / i_i) * (1.0 - math.exp(i_i * t / m))
    z_exact = -1.0 + (-(f_z / i_i)) * (t - (m / i_i) * (math.exp(i_i * t / m) - 1.0))
    assert x[9] == pytest.approx(v_exact, rel=1e-8)
    assert x[2] == pytest.approx(z_exact, rel=1e-8)
    assert v_exact < 0.0  # climbing: body z down, so negative velocity is up


def test_free_fall_and_rotation_kinematics() -> None:
    # F_lift = 0 (F_z = m g): the vehicle falls with g.
    xd = MODEL.derivative(HOVER_STATE, np.array([0.0, 0.0, 0.0, PARAMS.mass * PARAMS.g]))
    assert xd[9] == pytest.approx(9.82)
    # constant yaw rate for 1 s rotates the heading by the rate
    x = HOVER_STATE.copy()
    for _ in range(100):
        x = MODEL.step(x, np.array([0.0, 0.0, 0.5, 0.0]), 0.01)
    assert 2 * math.atan2(x[6], x[3]) == pytest.approx(0.5, abs=1e-9)
    assert np.linalg.norm(x[3:7]) == pytest.approx(1.0, abs=1e-12)


def test_inputs_from_sticks() -> None:
    # Ch. 3.3.1: maximum roll step (2047) gave 2.25 rad/s.
    u = inputs_from_sticks(Sticks(roll=2047, pitch=-1000, yaw=100, thrust=0), PARAMS)
    assert u[0] == pytest.approx(2.25, abs=0.01)
    assert u[1] == pytest.approx(-1.1) and u[2] == pytest.approx(0.11)
    assert u[3] == pytest.approx(-0.903 + 0.60 * 9.82)  # F_lift(0) + m g
    # hovers near mid-stick with the default mass (F_z ~ 0 at ~1990)
    assert abs(inputs_from_sticks(Sticks(thrust=1990), PARAMS)[3]) < 0.01
    np.testing.assert_allclose(np.diag(stick_input_gain(PARAMS)), [1.1e-3, 1.1e-3, 1.1e-3, 1.0])


def _ctrb_rank(A: np.ndarray, B: np.ndarray) -> int:
    """Rank of the Kalman controllability matrix, in time units of the rate loop: the
    rank is invariant under the time scaling (A, B) -> (c A, c B), and with c = tau the
    powers of the fast rate-loop pole (1/tau) stay of order one, so the numerical rank
    is not lost to scaling."""
    c = PARAMS.rate_tau
    n = A.shape[0]
    blocks = [c * B]
    for _ in range(n - 1):
        blocks.append(c * A @ blocks[-1])
    return int(np.linalg.matrix_rank(np.hstack(blocks)))


def test_controllability_full_vs_reduced_and_lag() -> None:
    full, red, lag = hover_model(PARAMS), hover_model_reduced(PARAMS), hover_model_rate_lag(PARAMS)
    assert _ctrb_rank(full.A, full.B) == 9  # q0 is not controllable
    assert _ctrb_rank(red.A, red.B) == 9
    assert _ctrb_rank(lag.A, lag.B) == 12
    eig = np.linalg.eigvals(lag.A)
    assert np.sum(np.isclose(eig, -1.0 / PARAMS.rate_tau)) == 3
    assert np.isclose(eig, PARAMS.inflow / PARAMS.mass).any()


def test_rate_lag_model_tends_to_reduced_model() -> None:
    # With a very fast rate loop the lagged model's response equals the reduced model's.
    red = hover_model_reduced(PARAMS)
    lag = hover_model_rate_lag(PARAMS, tau=1e-4)
    dt = 0.01
    Ar, Br = red.discretize(dt)
    Al, Bl = lag.discretize(dt)
    xr, xl = np.zeros(9), np.zeros(12)
    u = np.array([0.1, -0.05, 0.2, -0.3])
    for _ in range(100):
        xr, xl = Ar @ xr + Br @ u, Al @ xl + Bl @ u
    np.testing.assert_allclose(xl[:9], xr, atol=2e-3 * np.max(np.abs(xr)))


def test_discretize_matches_scipy_cont2discrete() -> None:
    red = hover_model_reduced(PARAMS)
    Ad, Bd = red.discretize(0.01)
    Ad2, Bd2, *_ = cont2discrete((red.A, red.B, np.eye(9), np.zeros((9, 4))), 0.01, "zoh")
    np.testing.assert_allclose(Ad, Ad2, atol=1e-12)
    np.testing.assert_allclose(Bd, Bd2, atol=1e-12)


def test_params_validation() -> None:
    with pytest.raises(ValueError):
        QuadrotorParams(mass=0.0)
    with pytest.raises(ValueError):
        QuadrotorParams(k_rate=(1.0, 2.0))  # type: ignore[arg-type]
    with pytest.raises(ValueError):
        hover_model_rate_lag(PARAMS, tau=0.0)
