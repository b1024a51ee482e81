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


@pytest.mark.slow
def test_the_lqr_observer_learns_only_from_fully_automatic_commands() -> None:
    """A step whose COMMAND went out with the pilot on a channel, or during a
    handover blend, is not the model's input: the estimate holds over it."""
    from groundstation.control import LqrController
    from groundstation.types import ControlOutput, Reference, StateEstimate

    def estimate(vz: float) -> StateEstimate:
        return StateEstimate(t=0.0, position=np.array([0.0, 0.0, -1.0]),
                             quaternion=np.array([1.0, 0.0, 0.0, 0.0]),
                             velocity_body=np.array([0.0, 0.0, vz]), omega=np.zeros(3),
                             gyro_bias=np.zeros(3), acc_bias=np.zeros(3),
                             covariance_diag=np.zeros(16))

    ref = Reference(0.0, np.array([0.0, 0.0, -1.0]), np.zeros(3))
    estimates = []
    for automatic in (True, False):
        ctrl = LqrController()
        out = ctrl.step(0.0, estimate(0.0), ref)
        ctrl.sent(out, automatic)
        # the vehicle sinks although nothing asked for it: a disturbance, if we know the input
        ctrl.step(0.02, estimate(0.05), ref)
        estimates.append(ctrl.disturbance[2])
    # learned: 0.05 m/s unexplained in one step, times dt / tau / dt = 1 / (1 s)
    assert estimates[0] == pytest.approx(0.05, abs=0.005)
    assert estimates[1] == 0.0  # held
    # the sent command is what the observer's model takes as the input
    # (with the 31 ms input delay modelled, a command acts on the velocity from the
    # second period on)
    ctrl = LqrController()
    for k in range(4):
        out = ctrl.step(0.02 * k, estimate(0.0), ref)  # the vehicle does not move ...
        ctrl.sent(ControlOutput(omega=out.omega, f_z=out.f_z - 1.0), True)  # ... on 1 N more
    assert ctrl.disturbance[2] > 0.01  # so something pushes down: a disturbance
