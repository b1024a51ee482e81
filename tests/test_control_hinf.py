"""H-infinity (Ch. 10): the thesis's finding, reproduced with the committed gains.

The gains in ``groundstation/control/data`` were synthesised by
``write_default_gains()`` (cvxpy, the continuous LMI of eq. 10.12-10.17 at
gamma = 1). The synthesis itself (and ``gs synth hinf``) is checked against an
independent frequency sweep of the closed loop's H-infinity norm; cvxpy is in the
``dev`` extra that ``make test`` installs, so these tests run (and fail, not skip,
without it).
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path
from typing import Any

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
    StandardProblem,
    continuous_closed_loop,
    discrete_spectral_radius,
    plant_model,
    standard_problem,
    uncertainty_vertices,
)
from groundstation.control.simulate import SimPlant, simulate
from groundstation.errors import ControlError
from groundstation.model import QuadrotorParams

PARAMS = QuadrotorParams()
ROOT = Path(__file__).resolve().parents[1]
LAB_TAU, LAB_DELAY, DT = 0.064, 0.02, 0.01  # the virtual lab's rate loop and command delay;
# DT: the thesis-model findings are checked at 100 Hz, as before the 50 Hz commands


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
    assert lag_gain.include_rate_loop and lag_gain.rate_tau == pytest.approx(LAB_TAU)
    assert lag_gain.robust_range == pytest.approx(0.3) and lag_gain.F_i.shape == (4, 4)
    for tau in (0.7 * LAB_TAU, LAB_TAU, 1.3 * LAB_TAU):  # the range it was designed for
        A, B = plant_model(PARAMS, include_rate_loop=True, rate_tau=tau)
        assert continuous_closed_loop(A, B, lag_gain.F_s).real.max() < -1.0  # -1.67..-1.89
        # at the 50 Hz command period with the command delay: 0.962-0.964
        assert discrete_spectral_radius(A, B, lag_gain.F_s, 0.02, LAB_DELAY) < 0.975


def _sampled_loop_radius(gain: HinfGain, k_rate: float, tau: float, k_thrust: float,
                         delay: float, motor_tau: float = 0.02, dt: float = 0.02) -> float:
    """Spectral radius of the sampled loop ``u = F_s x + F_i x_i`` on the lagged hover
    model with its rate gains scaled by ``k_rate``, thrust per newton by ``k_thrust``, a
    first-order motor lag on the lift, and the input ``delay`` (an independent build of
    the closed loop from the continuous model: exact ZOH, delay as in Astrom-Wittenmark)."""
    from groundstation.control.lqr_design import discretise_delayed
    from groundstation.model import hover_model_rate_lag

    model = hover_model_rate_lag(PARAMS, tau)
    A, B = np.zeros((13, 13)), np.zeros((13, 4))
    A[:12, :12], B[:12, :3] = model.A, k_rate * model.B[:, :3]
    A[8, 12], A[12, 12], B[12, 3] = 1.0 / PARAMS.mass, -1.0 / motor_tau, k_thrust / motor_tau
    Phi, Gamma, _ = discretise_delayed(A, B, dt, delay)
    n = Phi.shape[0]
    M = np.zeros((n + 4, n + 4))
    M[:n, :n] = Phi
    K = np.zeros((4, n + 4))
    K[:, :12], K[:, n:] = gain.F_s, gain.F_i
    M[:n] += Gamma @ K
    M[n + np.arange(4), [0, 1, 2, 5]] = -dt  # x_i += dt (r - y), r = 0
    M[n:, n:] += np.eye(4)
    return float(np.max(np.abs(np.linalg.eigvals(M))))


@pytest.mark.parametrize("k_rate", [0.7, 1.3])
@pytest.mark.parametrize("tau_scale", [0.7, 1.3])
@pytest.mark.parametrize("k_thrust", [0.7, 1.3])
def test_robust_gain_is_stable_over_the_uncertainty_box(lag_gain: HinfGain, k_rate: float,
                                                        tau_scale: float,
                                                        k_thrust: float) -> None:
    """Stable with each rate gain 30 % off (and the rate loop's time constant,
    mass and thrust map off), at 50 Hz with 5-30 ms of command delay plus the frames'
    11 ms on the wire and a 20 ms motor lag the design never saw. Reached <= 0.987."""
    for delay in (0.016, 0.041):
        assert _sampled_loop_radius(lag_gain, k_rate, tau_scale * LAB_TAU, k_thrust,
                                    delay) < 0.995


def test_old_rate_loop_design_fed_the_yaw_rate_back_positively(lag_gain: HinfGain) -> None:
    """The first rate-loop design (the thesis's own fix, no robustness) had F[psi_dot] =
    +0.80: a yaw rate gain 36 % high made k F > 1, the rate loop lost its damping and the
    heading spun. The robust gain stays stable with every yaw gain up to +30 %, and its
    yaw loop alone (q3, omega_z) with +36 %."""
    from groundstation.control.lqr_design import discretise_delayed

    for k in (1.0, 1.36):
        A = np.array([[0.0, 0.5], [0.0, -1.0 / LAB_TAU]])
        B = np.array([[0.0], [k / LAB_TAU]])
        Phi, Gamma, _ = discretise_delayed(A, B, 0.02, 0.031)
        K = np.zeros((1, Phi.shape[0]))
        K[0, :2] = lag_gain.F_s[2, [5, 11]]
        M = np.zeros((Phi.shape[0] + 1, Phi.shape[0] + 1))
        M[:-1, :-1] = Phi + Gamma @ K
        M[:-1, -1:] = Gamma * lag_gain.F_i[2, 3]
        M[-1, 0], M[-1, -1] = -0.02, 1.0  # heading integrator: x_i += dt (0 - q3)
        assert np.max(np.abs(np.linalg.eigvals(M))) < 1.0


@pytest.mark.slow
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
    # reached 37 % overshoot: the integrators see the whole raw step (the flight's
    # references are shaped; the thesis's set-point steps are not)
    assert np.max(np.abs(good.position[:, 0])) < 0.3 * 1.45


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


def _swept_hinf_norm(A: np.ndarray, B: np.ndarray, C: np.ndarray, D: np.ndarray) -> float:
    """sup over w of the largest singular value of C (jwI - A)^-1 B + D, by a frequency sweep.

    Independent of python-control and of the LMI: a log grid over 1e-3..1e4 rad/s, then a
    finer grid around the grid's peak.
    """
    def peak(w: np.ndarray) -> tuple[float, float]:
        n = A.shape[0]
        values = [np.linalg.svd(C @ np.linalg.solve(1j * wi * np.eye(n) - A, B) + D,
                                compute_uv=False)[0] for wi in w]
        i = int(np.argmax(values))
        return float(values[i]), float(w[i])

    coarse, w0 = peak(np.logspace(-3, 4, 1400))
    fine, _ = peak(np.linspace(w0 / 1.02, w0 * 1.02, 400))
    return max(coarse, fine, float(np.linalg.svd(D, compute_uv=False)[0]))


def test_frequency_sweep_finds_a_known_peak() -> None:
    """The sweep can fail: 1/(s^2 + 0.2 s + 1) peaks at 1/(2 zeta sqrt(1 - zeta^2)), zeta 0.1."""
    A = np.array([[0.0, 1.0], [-1.0, -0.2]])
    B = np.array([[0.0], [1.0]])
    C = np.array([[1.0, 0.0]])
    assert _swept_hinf_norm(A, B, C, np.zeros((1, 1))) == pytest.approx(
        1 / (2 * 0.1 * np.sqrt(1 - 0.01)), rel=1e-4)


def _closed_loop_norm(gain: HinfGain, sp: StandardProblem) -> tuple[float, float]:
    """(swept, python-control) H-infinity norm of w -> z with u = F [x_s; x_r; x_n]."""
    F = np.hstack([gain.F_s, gain.F_r, gain.F_n])
    A, B1, C1 = sp.A + sp.B2 @ F, sp.B1, sp.C1 + sp.D12 @ F
    assert np.max(np.linalg.eigvals(A).real) < 0  # the norm is finite only for a stable loop
    swept = _swept_hinf_norm(A, B1, C1, sp.D11)
    return swept, float(control.norm(control.ss(A, B1, C1, sp.D11), p="inf"))


@pytest.mark.slow
def test_synthesis_meets_its_bound() -> None:
    """The LMI's gain keeps the closed loop's H-infinity norm below gamma = 1 (eq. 10.11)."""
    from groundstation.control.hinf import synthesise_hinf

    gain = synthesise_hinf(PARAMS, include_rate_loop=False, gamma=1.0)
    A, B = plant_model(PARAMS, include_rate_loop=False)
    swept, reference = _closed_loop_norm(gain, standard_problem(A, B, HinfWeights()))
    assert swept < 1.0
    assert swept == pytest.approx(reference, rel=1e-3)  # the sweep found the true peak


@pytest.mark.slow
def test_gs_synth_hinf_writes_a_gain_that_meets_its_bound(tmp_path: Path) -> None:
    """`gs synth hinf` end to end (the robust rate-loop design of config/sim.yaml)."""
    out = tmp_path / "hinf.npz"
    result = subprocess.run([sys.executable, "-m", "groundstation", "synth", "hinf",
                             "--config", str(ROOT / "config" / "sim.yaml"), "--out", str(out)],
                            capture_output=True, text=True, timeout=300, cwd=ROOT)
    assert result.returncode == 0, result.stderr
    gain = load_hinf_gain(out)
    assert gain.include_rate_loop and gain.rate_tau == PARAMS.rate_tau
    # the bound holds at every vertex of the uncertainty box it was designed for
    fields: dict[str, Any] = {k: (tuple(v) if isinstance(v, list) else v)
                              for k, v in gain.weights.items()}
    weights = HinfWeights(**fields)
    vertices = uncertainty_vertices(PARAMS, gain.rate_tau, weights, gain.robust_range,
                                    gain.robust_range, gain.robust_range)
    assert gain.robust_range > 0 and len(vertices) > 1
    for sp in vertices:
        F = np.hstack([gain.F_s, gain.F_r, gain.F_n, gain.F_i])
        A, B1, C1 = sp.A + sp.B2 @ F, sp.B1, sp.C1 + sp.D12 @ F
        assert np.max(np.linalg.eigvals(A).real) < 0
        assert _swept_hinf_norm(A, B1, C1, sp.D11) < gain.gamma
