"""The EKF's IMU-driven model: propagation, error-state Jacobian, parameters."""

from __future__ import annotations

import math

import numpy as np
import pytest
from ekf_truth import SensorNoise, TruthSimulator, square_reference
from scipy.linalg import expm

from groundstation.config import EstimatorConfig, GroundStationConfig, SafetyConfig, ViconConfig
from groundstation.estimation import Ekf, EkfParams
from groundstation.estimation.imu_model import (
    boxminus,
    boxplus,
    derivative,
    error_jacobian,
    jacobian_flat_index,
    propagate,
)
from groundstation.flight.assembly import ekf_params
from groundstation.model.quaternion import normalize
from groundstation.types import ImuSample, Pose

G = 9.82


def _random_state(rng: np.random.Generator) -> np.ndarray:
    x = np.zeros(16)
    x[0:3] = rng.normal(size=3)
    x[3:7] = normalize(rng.normal(size=4))
    x[7:10] = rng.normal(size=3)
    x[10:13] = 0.05 * rng.normal(size=3)
    x[13:16] = 0.3 * rng.normal(size=3)
    return x


def _flow(x: np.ndarray, gyro: np.ndarray, acc: np.ndarray, dt: float) -> np.ndarray:
    out = np.empty(16)
    propagate(x, gyro, acc, gyro, acc, dt, G, out)
    return out


@pytest.mark.parametrize("seed", range(5))
def test_error_jacobian_matches_finite_differences(seed: int) -> None:
    # Independent answer: differentiate the nominal flow numerically in error coordinates,
    # (phi_dt(x ⊞ e) ⊟ phi_dt(x)) / eps  ->  Phi = expm(F dt) for constant inputs.
    rng = np.random.default_rng(seed)
    x = _random_state(rng)
    gyro, acc = rng.normal(size=3), rng.normal(size=3) + np.array([0, 0, -G])
    idx, F = jacobian_flat_index()
    w = gyro - x[10:13]
    error_jacobian(x, (w[0], w[1], w[2]), G, F, idx)
    dt, eps = 1e-3, 1e-6
    base = _flow(x, gyro, acc, dt)
    Phi_fd = np.empty((15, 15))
    for i in range(15):
        e = np.zeros(15)
        e[i] = eps
        plus = boxminus(_flow(boxplus(x, e), gyro, acc, dt), base)
        minus = boxminus(_flow(boxplus(x, -e), gyro, acc, dt), base)
        Phi_fd[:, i] = (plus - minus) / (2 * eps)
    F_fd = (Phi_fd - np.eye(15)) / dt
    # F is evaluated at the start of the step; over dt the state moves by O(dt),
    # so the finite-difference F matches to O(dt) relative to |F|.
    np.testing.assert_allclose(F, F_fd, atol=2e-2 * np.max(np.abs(F)))
    np.testing.assert_allclose(expm(F * dt), Phi_fd, atol=1e-4)


def test_nominal_derivative_matches_thesis_eq_7_17_to_7_21() -> None:
    # Independent: write eq. 7.17-7.21 with scipy's rotation (true = measured - bias).
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(7)
    x = _random_state(rng)
    gyro, acc = rng.normal(size=3), rng.normal(size=3)
    R = Rotation.from_quat(x[3:7], scalar_first=True).as_matrix()
    w, a = gyro - x[10:13], acc - x[13:16]
    q0, q1, q2, q3 = x[3:7]
    omega = np.array([[0, -w[0], -w[1], -w[2]], [w[0], 0, w[2], -w[1]],
                      [w[1], -w[2], 0, w[0]], [w[2], w[1], -w[0], 0]])
    expected = np.r_[R @ x[7:10], 0.5 * omega @ x[3:7],
                     a + R.T @ [0, 0, G] - np.cross(w, x[7:10]), np.zeros(6)]
    np.testing.assert_allclose(derivative(x, gyro, acc, G), expected, atol=1e-12)
    assert q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3 == pytest.approx(1.0)


def test_rk4_propagation_converges_at_fourth_order() -> None:
    rng = np.random.default_rng(3)
    x = _random_state(rng)
    g0, a0, g1, a1 = (rng.normal(size=3) for _ in range(4))

    def run(n: int) -> np.ndarray:
        y = x.copy()
        for i in range(n):
            f0, f1 = i / n, (i + 1) / n
            propagate(y, g0 + f0 * (g1 - g0), a0 + f0 * (a1 - a0),
                      g0 + f1 * (g1 - g0), a0 + f1 * (a1 - a0), 0.1 / n, G, y)
        return y

    ref = run(512)
    e1 = np.linalg.norm(boxminus(run(1), ref))
    e2 = np.linalg.norm(boxminus(run(2), ref))
    assert e1 / e2 > 12.0  # 4th order: halving the step divides the error by ~16
    assert np.linalg.norm(run(1)[3:7]) == pytest.approx(1.0, abs=1e-15)


@pytest.mark.slow
def test_noise_free_estimate_follows_truth_without_vicon() -> None:
    # With perfect IMU data the prediction alone must reproduce the truth simulator
    # (same nonlinear model, inputs linear between samples) for 10 s of the square.
    sim = TruthSimulator(square_reference(), noise=SensorNoise.none(), seed=0)
    ekf = Ekf()
    for _ in range(300):  # get moving first
        sim.step()
    ekf.initialise(sim.pose(), [])
    ekf._x[7:10] = sim.x[7:10]  # start with the true velocity (initialise assumes rest)
    ekf.predict(sim.imu())
    for _ in range(1000):
        sim.step()
        ekf.predict(sim.imu())
    x = ekf.state
    assert np.linalg.norm(x[0:3] - sim.x[0:3]) < 1e-5  # measured 2e-7 m
    assert np.linalg.norm(boxminus(np.r_[sim.x, np.zeros(6)], x)[3:6]) < 1e-9


def test_boxplus_boxminus_roundtrip() -> None:
    rng = np.random.default_rng(11)
    for _ in range(20):
        x, dx = _random_state(rng), 0.3 * rng.normal(size=15)
        np.testing.assert_allclose(boxminus(boxplus(x, dx), x), dx, atol=1e-12)


def test_params_from_config_and_validation() -> None:
    p = ekf_params(GroundStationConfig())
    assert p == EkfParams()  # defaults agree with the config defaults (Tables 6.1, 6.3)
    # attitude residual variance is 4 var(q_i) of Table 6.1; q0 is not used
    np.testing.assert_allclose(p.measurement_variance()[3:], 4 * np.array([5.17e-6, 9.74e-6,
                                                                             3.62e-6]))
    np.testing.assert_allclose(p.measurement_variance()[1], 3.28e-9)
    est = EstimatorConfig(r_override=[1e-6] * 3 + [1e-9, 1e-5, 1e-5, 1e-5])
    np.testing.assert_allclose(
        ekf_params(GroundStationConfig(estimator=est)).measurement_variance(),
        [1e-6] * 3 + [4e-5] * 3)
    with pytest.raises(ValueError):
        EkfParams(gyro_var=(1.0, -1.0, 1.0))
    with pytest.raises(ValueError):
        EkfParams(gate_probability=1.0)
    with pytest.raises(ValueError):
        EkfParams(initial_variance=(1.0,) * 15)
    assert math.isclose(EkfParams().imu_period, 0.01)
    with pytest.raises(ValueError):
        EkfParams(plausible_volume=((1.0, -1.0), (-1.0, 1.0), (-2.0, 0.0)))


def test_params_take_the_reset_and_the_plausible_volume_from_vicon_and_safety() -> None:
    default = ekf_params(GroundStationConfig())
    assert default == EkfParams()  # the defaults agree with the configuration's
    vicon = ViconConfig(reanchor_poses=5, plausibility_margin_m=0.0, max_speed_m_s=2.0)
    safety = SafetyConfig(volume_x=(-1.0, 1.0))
    p = ekf_params(GroundStationConfig(vicon=vicon, safety=safety))
    assert (p.gate_reset_count, p.max_speed, p.max_rotation_rate) == (5, 2.0, 30.0)
    assert p.plausible_volume == ((-1.0, 1.0), (-1.5, 1.5), (-2.0, 0.05))


def test_process_noise_equals_g_qc_gt() -> None:
    # Independent construction of Q_d = G Qc G^T dt from the noise model of imu_model:
    # dtheta_dot = -n_g, dv_dot = -[v×] n_g - n_a, bias rates = random walks.
    from groundstation.model.quaternion import skew

    p = EkfParams()
    ekf = Ekf(p)
    rng = np.random.default_rng(5)
    ekf._x[7:10] = v = rng.normal(size=3)
    ekf._P[:] = 0.0
    dt = 0.01
    ekf._add_process_noise(dt)
    G = np.zeros((15, 12))
    G[3:6, 0:3] = -np.eye(3)
    G[6:9, 0:3] = -skew(v)
    G[6:9, 3:6] = -np.eye(3)
    G[9:15, 6:12] = np.eye(6)
    Qc = np.diag(np.r_[np.array(p.gyro_var) * p.imu_period, np.array(p.acc_var) * p.imu_period,
                       [p.gyro_bias_walk] * 3, [p.acc_bias_walk] * 3])
    np.testing.assert_allclose(ekf._P, G @ Qc @ G.T * dt, rtol=1e-12, atol=1e-20)


def test_health_trace_equals_the_16_state_covariance_trace() -> None:
    """The closed-form trace in health() equals the sum of estimate().covariance_diag."""
    from groundstation.estimation.ekf import Ekf
    from groundstation.types import Pose

    rng = np.random.default_rng(7)
    ekf = Ekf()
    q = rng.normal(size=4)
    ekf.initialise(Pose(0.0, np.zeros(3), q / np.linalg.norm(q)))
    a = rng.normal(size=(15, 15))
    ekf._P[:] = a @ a.T  # a full, random covariance (white-box: P is private)
    expected = float(np.sum(ekf.estimate().covariance_diag))
    assert ekf.health().covariance_trace == pytest.approx(expected, rel=1e-12)


def test_diverged_flags_a_large_or_non_finite_covariance() -> None:
    from groundstation.estimation.ekf import Ekf
    from groundstation.types import Pose

    ekf = Ekf(EkfParams(divergence_trace=1.0))
    assert not ekf.diverged  # not initialised yet
    ekf.initialise(Pose(0.0, np.zeros(3), np.array([1.0, 0.0, 0.0, 0.0])))
    assert not ekf.diverged and ekf.diverged == ekf.health().diverged
    ekf._P[7, 7] = 2.0  # velocity variance alone over the limit
    assert ekf.diverged and ekf.health().diverged
    ekf._P[7, 7] = math.nan
    assert ekf.diverged


def test_a_prediction_that_reuses_the_estimate_ahead_is_the_one_it_would_integrate(
        monkeypatch: pytest.MonkeyPatch) -> None:
    # the flight core's order, one IMU sample behind: poses, predict to the held sample,
    # then the estimate ahead to the new one. A filter never asked for the estimate ahead
    # integrates every step itself; both must end bit for bit equal. Poses defeat the
    # reuse: one newer than the filter splits the next step, one stamped at the filter
    # time is fused at once and moves the state the estimate ahead started from
    from groundstation.estimation import ekf as ekf_module

    calls = {"n": 0}
    original = ekf_module.propagate

    def counted(*args: object) -> None:
        calls["n"] += 1
        original(*args)  # type: ignore[arg-type]

    monkeypatch.setattr(ekf_module, "propagate", counted)
    sim = TruthSimulator(square_reference(), seed=3)
    asked, plain = Ekf(), Ekf()
    start, first = sim.pose(), sim.imu()
    for f in (asked, plain):
        f.initialise(start, [first])
    held: ImuSample | None = None
    measured: list[Pose] = []  # the true pose at each sample, with Vicon's noise
    counts = {"asked": 0, "plain": 0}
    for k in range(600):
        sim.step()
        imu = sim.imu()
        measured.append(sim.pose())
        poses = []
        if k % 10 == 0:
            poses = [sim.pose(-0.004)]
        elif k % 10 == 5:  # at the filter time: the sample predicted a tick ago
            poses = [measured[-3]]
            assert poses[0].t == asked.estimate().t
        for name, f in (("asked", asked), ("plain", plain)):
            calls["n"] = 0
            for pose in poses:
                assert f.update(pose).reason in ("deferred", "ok")
            if held is not None:
                f.predict(held)
            if name == "asked":
                f.estimate_ahead(imu)
            counts[name] += calls["n"]
        held = imu
    np.testing.assert_array_equal(asked.state, plain.state)
    np.testing.assert_array_equal(asked.error_covariance, plain.error_covariance)
    # reused on most ticks: few more integrations than the plain filter's, not one a tick
    assert counts["asked"] < counts["plain"] + 250, counts
