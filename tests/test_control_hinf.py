"""H-infinity (Ch. 10): the thesis's finding, reproduced with the committed gains.

The gains in ``groundstation/control/data`` were synthesised by
``write_default_gains()`` (cvxpy, the continuous LMI of eq. 10.12-10.17 at
gamma = 1). These tests need no cvxpy; the synthesis itself is tested only
where cvxpy is installed (the optional ``hinf`` extra).
"""

from __future__ import annotations

from pathlib import Path

import control
import numpy as np
import pytest

from groundstation.control import make_trajectory
from groundstation.control.hinf import (
    HinfController,
    HinfGain,
    default_gain_path,
    load_hinf_gain,
)
from groundstation.control.hinf_design import (
    HinfWeights,
    continuous_closed_loop,
    discrete_spectral_radius,
    plant_model,
    standard_problem,
)
from groundstation.control.simulate import SimPlant, simulate
from groundstation.errors import ControlError
from groundstation.model import QuadrotorParams

PARAMS = QuadrotorParams()
LAB_TAU, LAB_DELAY, DT = 0.064, 0.02, 0.01  # the virtual lab's rate loop and command delay


@pytest.fixture(scope="module")
def thesis_gain() -> HinfGain:
    return load_hinf_gain(default_gain_path(include_rate_loop=False))


@pytest.fixture(scope="module")
def lag_gain() -> HinfGain:
    return load_hinf_gain(default_gain_path(include_rate_loop=True))


def test_thesis_gain_stabilises_the_thesis_model(thesis_gain: HinfGain) -> None:
    A, B = plant_model(PARAMS, include_rate_loop=False)
    poles = continuous_closed_loop(A, B, thesis_gain.F_s)
    assert poles.real.max() < -0.5  # reached -0.96 rad/s
    assert discrete_spectral_radius(A, B, thesis_gain.F_s, DT) < 0.995  # 0.9906 at 100 Hz


def test_thesis_gain_does_not_stabilise_the_rate_loop_lag(thesis_gain: HinfGain) -> None:
    # Ch. 10.3: stable in simulation, unstable on the vehicle; the missing dynamics
    # is the on-board rate loop. Continuous and sampled, with and without the delay.
    A, B = plant_model(PARAMS, include_rate_loop=True, rate_tau=LAB_TAU)
    F = np.hstack([thesis_gain.F_s, np.zeros((4, 3))])  # the thesis model has no rate states
    assert continuous_closed_loop(A, B, F).real.max() > 0.0
    assert discrete_spectral_radius(A, B, thesis_gain.F_s, DT) > 1.01  # reached 1.018
    assert discrete_spectral_radius(A, B, thesis_gain.F_s, DT, LAB_DELAY) > 1.02  # 1.030


def test_gain_designed_with_the_lag_stabilises_the_lagged_plant(lag_gain: HinfGain) -> None:
    assert lag_gain.include_rate_loop and lag_gain.rate_tau == pytest.approx(0.077)
    for tau in (LAB_TAU, lag_gain.rate_tau):  # the lab's lag and the design's own
        A, B = plant_model(PARAMS, include_rate_loop=True, rate_tau=tau)
        assert continuous_closed_loop(A, B, lag_gain.F_s).real.max() < -0.3
        assert discrete_spectral_radius(A, B, lag_gain.F_s, DT, LAB_DELAY) < 0.995  # 0.9913


def test_findings_hold_on_the_nonlinear_model(thesis_gain: HinfGain, lag_gain: HinfGain) -> None:
    step = make_trajectory("step-x", step_m=0.3)
    ideal = SimPlant(rate_tau=0.0, delay_s=0.0)
    lab = SimPlant(rate_tau=LAB_TAU, delay_s=LAB_DELAY)
    ok = simulate(HinfController(thesis_gain), step, 10.0, plant=ideal)
    assert abs(ok.position[-1, 0] - 0.3) < 0.01
    bad = simulate(HinfController(thesis_gain), step, 10.0, plant=lab)
    tilt = 2 * np.arcsin(np.clip(np.linalg.norm(bad.quaternion[:, 1:3], axis=1), 0, 1))
    assert tilt.max() > np.radians(30) or not np.all(np.isfinite(bad.position))
    good = simulate(HinfController(lag_gain), step, 10.0, plant=lab)
    assert abs(good.position[-1, 0] - 0.3) < 0.01
    assert np.max(np.abs(good.position[:, 0])) < 0.3 * 1.2  # reached 13 % overshoot


def test_standard_problem_structure() -> None:
    A, B = plant_model(PARAMS, include_rate_loop=False)
    w = HinfWeights(eps=0.1, reference_pole=1.0, noise_gain=0.01, noise_zero=1.0, noise_pole=100)
    sp = standard_problem(A, B, w)
    assert sp.A.shape == (17, 17) and sp.B1.shape == (17, 8) and sp.B2.shape == (17, 4)
    assert np.linalg.matrix_rank(sp.D12) == 4  # full column rank (eq. 10.5)
    # each weight is the transfer function of eq. 10.7: evaluate at s = 2j independently
    s = 2j
    n = np.arange(9, 17)
    G = sp.C2[np.ix_([0], n)] @ np.linalg.solve(s * np.eye(8) - sp.A[np.ix_(n, n)],
                                                sp.B1[n][:, [4]]) + sp.D21[0, 4]
    assert complex(G[0, 0]) == pytest.approx(0.01 * (s + 1.0) / (s + 100.0))
    Gr = np.linalg.solve(s * np.eye(4) - sp.A[9:13, 9:13], sp.B1[9:13, :4])
    np.testing.assert_allclose(Gr, np.eye(4) * 1.0 / (s + 1.0))  # W_r = k / (s + a), k = a


def test_gain_file_round_trip_and_errors(tmp_path: Path, lag_gain: HinfGain) -> None:
    path = tmp_path / "g.npz"
    lag_gain.save(path)
    back = load_hinf_gain(path)
    np.testing.assert_array_equal(back.F_s, lag_gain.F_s)
    assert back.weights == lag_gain.weights and back.gamma == 1.0
    (tmp_path / "bad.npz").write_bytes(b"not a zip")
    with pytest.raises(ControlError, match="not an H-infinity gain file"):
        load_hinf_gain(tmp_path / "bad.npz")
    np.savez(tmp_path / "shape.npz", F_s=np.zeros((4, 5)), F_r=np.zeros((4, 4)),
             F_n=np.zeros((4, 4)), meta=np.array('{"include_rate_loop": false, "gamma": 1, '
                                                 '"rate_tau": 0, "weights": {}, '
                                                 '"objective": "x"}'))
    with pytest.raises(ControlError, match="do not match a 9-state design"):
        load_hinf_gain(tmp_path / "shape.npz")


def test_synthesis_meets_its_bound() -> None:
    pytest.importorskip("cvxpy")
    from groundstation.control.hinf import synthesise_hinf

    gain = synthesise_hinf(PARAMS, include_rate_loop=False, gamma=1.0)
    A, B = plant_model(PARAMS, include_rate_loop=False)
    sp = standard_problem(A, B, HinfWeights())
    F = np.hstack([gain.F_s, gain.F_r, gain.F_n])
    # independent check: the closed loop w -> z has an H-infinity norm below gamma
    closed = control.ss(sp.A + sp.B2 @ F, sp.B1, sp.C1 + sp.D12 @ F, sp.D11)
    assert control.norm(closed, p="inf") < 1.0
