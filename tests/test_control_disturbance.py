"""The constant-disturbance observer against the closed form of its first-order estimate."""

from __future__ import annotations

import numpy as np
import pytest

from groundstation.control import DisturbanceObserver
from groundstation.control.lqr_design import discretise
from groundstation.model import QuadrotorParams, hover_model_reduced

DT, TAU = 0.01, 0.5


def test_estimate_converges_as_a_first_order_lag_to_the_true_disturbance() -> None:
    model = hover_model_reduced(QuadrotorParams())
    Phi, Gamma = discretise(model.A, model.B, DT)
    obs = DisturbanceObserver(Phi, Gamma, DT, TAU)
    d_true = np.array([0.3, -0.2, 0.98])  # body-axis acceleration offsets [m/s^2]
    # the exact ZOH effect of a constant acceleration on the state over one step
    _, Gamma_d = discretise(model.A, np.vstack([np.zeros((6, 3)), np.eye(3)]), DT)
    x = np.zeros(9)
    rng = np.random.default_rng(4)
    history = []
    for _ in range(300):
        u = rng.normal(0.0, [0.2, 0.2, 0.2, 0.5])  # arbitrary excitation: the model predicts it
        obs.update(x)
        obs.commit(u)
        history.append(obs.estimate.copy())
        x = Phi @ x + Gamma @ u + Gamma_d @ d_true
    history = np.array(history)
    # d_hat(k) - d = (d_hat(k-1) - d)(1 - dt/tau) once the loop runs: after 299 updates
    # the error is (1 - dt/tau)^299 of the start (up to the ZOH shape of the offset)
    expected = d_true * (1.0 - (1.0 - DT / TAU) ** 299)
    np.testing.assert_allclose(history[-1], expected, rtol=0.02)
    k = 50  # and along the way
    np.testing.assert_allclose(history[k], d_true * (1.0 - (1.0 - DT / TAU) ** (k - 1)),
                               rtol=0.03)
    obs.reset()
    np.testing.assert_array_equal(obs.estimate, 0.0)


def test_bad_time_constant_is_refused() -> None:
    model = hover_model_reduced(QuadrotorParams())
    Phi, Gamma = discretise(model.A, model.B, DT)
    with pytest.raises(ValueError, match="tau >= dt"):
        DisturbanceObserver(Phi, Gamma, DT, 0.001)
