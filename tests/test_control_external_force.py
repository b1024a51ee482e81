"""The accelerometer's external-force estimate (control/external_force.py) and its filters.

Independent answers: scipy's discrete Riccati solution for the steady-state Kalman filter
the alpha-beta gains claim to be (and its covariance for the noise figures), scipy.signal's
frequency response for the bandwidth, the sample statistics of the filter run on white
noise, the continuous response of a delayed first-order lag for the lift model, and the
small-gain bound of the loop it closes, evaluated here with numpy over the perturbation box
of ``gs eval --perturb``.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.linalg
import scipy.signal

from groundstation.control.external_force import ExternalForceObserver
from groundstation.control.tracking_filter import alpha_beta, frequency_response
from groundstation.model import QuadrotorParams
from groundstation.model.sensors import ACC_VARIANCE_TABLE_6_3
from groundstation.types import StateEstimate

T = 0.02
PARAMS = QuadrotorParams()
SIGMA_Z = math.sqrt(ACC_VARIANCE_TABLE_6_3[2])
SIGMA_H = math.sqrt(max(ACC_VARIANCE_TABLE_6_3[:2]))


def riccati(process_sd: float, sigma: float) -> tuple[np.ndarray, np.ndarray, float]:
    """Steady-state Kalman gain (2,), filtered covariance (2, 2) and innovation variance of
    the piecewise-constant white-acceleration model, from scipy's DARE."""
    F = np.array([[1.0, T], [0.0, 1.0]])
    G = np.array([[T * T / 2.0], [T]])
    H = np.array([[1.0, 0.0]])
    P = scipy.linalg.solve_discrete_are(F.T, H.T, G @ G.T * process_sd**2,
                                        np.array([[sigma**2]]))
    S = float(P[0, 0]) + sigma**2
    K = P[:, 0] / S
    return K, P - np.outer(K, K) * S, S


@pytest.mark.parametrize("process_sd", [0.01, 1.0, 10.0, 600.0])
def test_alpha_beta_is_the_steady_state_kalman_filter(process_sd: float) -> None:
    f = alpha_beta(process_sd, SIGMA_Z, T)
    K, P, S = riccati(process_sd, SIGMA_Z)
    assert (f.alpha, f.beta / T) == pytest.approx((K[0], K[1]), rel=1e-9)
    assert f.value_sd == pytest.approx(math.sqrt(P[0, 0]), rel=1e-9)
    assert f.rate_sd == pytest.approx(math.sqrt(P[1, 1]), rel=1e-9)
    assert f.innovation_sd == pytest.approx(math.sqrt(S), rel=1e-9)


@pytest.mark.parametrize("process_sd", [1.0, 10.0])
def test_the_bandwidth_is_where_scipy_finds_the_response_3_db_down(process_sd: float) -> None:
    f = alpha_beta(process_sd, SIGMA_Z, T)
    b, a = [f.alpha, f.beta - f.alpha, 0.0], [1.0, f.alpha + f.beta - 2.0, 1.0 - f.alpha]
    w, h = scipy.signal.freqz(b, a, worN=np.linspace(1e-4, math.pi, 200_000))
    first = np.flatnonzero(np.abs(h) < math.sqrt(0.5))[0]
    assert f.bandwidth_rad_s == pytest.approx(w[first] / T, rel=1e-3)
    omega = np.array([0.3, 3.0, 30.0])
    _, h3 = scipy.signal.freqz(b, a, worN=omega * T)
    assert frequency_response(f.alpha, f.beta, T, omega) == pytest.approx(h3, rel=1e-9)


@pytest.mark.parametrize("process_sd", [1.0, 10.0, 600.0])
def test_the_noise_gains_are_the_impulse_responses_squared_and_summed(
        process_sd: float) -> None:
    f = alpha_beta(process_sd, SIGMA_Z, T)
    den = [1.0, f.alpha + f.beta - 2.0, 1.0 - f.alpha]
    n = 20_000
    _, (value,) = scipy.signal.dimpulse(([f.alpha, f.beta - f.alpha, 0.0], den, 1.0), n=n)
    _, (rate,) = scipy.signal.dimpulse(([f.beta / T, -f.beta / T, 0.0], den, 1.0), n=n)
    assert f.noise_sd == pytest.approx(SIGMA_Z * math.sqrt(np.sum(value**2)), rel=1e-9)
    assert f.rate_noise_sd == pytest.approx(SIGMA_Z * math.sqrt(np.sum(rate**2)), rel=1e-9)


def test_the_documented_figures() -> None:
    vertical = alpha_beta(10.0, SIGMA_Z, T)
    assert (vertical.alpha, vertical.beta) == pytest.approx((0.31, 0.056), abs=0.005)
    assert vertical.bandwidth_rad_s == pytest.approx(24.8, abs=0.1)
    assert (vertical.noise_sd, vertical.rate_noise_sd) == pytest.approx((0.029, 0.23),
                                                                        abs=0.005)
    fast = alpha_beta(600.0, SIGMA_H, T)
    assert (fast.alpha, fast.beta) == pytest.approx((0.92, 1.02), abs=0.005)
    assert (fast.noise_sd, fast.rate_noise_sd) == pytest.approx((0.063, 4.7), abs=0.05)


def level(position_z: float, force: tuple[float, float, float]) -> StateEstimate:
    """A level estimate at height ``position_z`` (NED) with a bias-corrected specific force."""
    return StateEstimate(t=0.0, position=np.array([0.0, 0.0, position_z]),
                         quaternion=np.array([1.0, 0.0, 0.0, 0.0]), velocity_body=np.zeros(3),
                         omega=np.zeros(3), gyro_bias=np.zeros(3), acc_bias=np.zeros(3),
                         covariance_diag=np.zeros(16), specific_force=np.array(force))


def airborne(obs: ExternalForceObserver, f_z: float = 0.0) -> None:
    """Reset on the floor, then report a COMMAND ``f_z`` and a first estimate 1 m up."""
    obs.reset()
    obs.update(level(0.0, (0.0, 0.0, -PARAMS.g)))
    for _ in range(10):
        obs.sent(f_z, True)
        obs.update(level(-1.0, (0.0, 0.0, -PARAMS.g)))


def test_the_lift_model_is_the_delayed_lag() -> None:
    """A step of the lift sent reaches the rotors ``D`` later and follows a lag ``tau``:
    ``L(t) = u (1 - exp(-(t - D) / tau))`` for ``t > D`` at the sample instants."""
    D, tau, u = 0.0311, 0.02, -3.0
    obs = ExternalForceObserver(PARAMS, T, motor_tau_s=tau, delay_s=D)
    weight = PARAMS.mass * PARAMS.g
    obs.sent(u + weight, True)  # the step, sent at t = 0
    lifts = []
    for _ in range(12):
        obs.update(level(-1.0, (0.0, 0.0, -PARAMS.g)))
        lifts.append(obs.predicted_lift)
        obs.sent(u + weight, True)
    t = T * np.arange(1, 13)
    expected = np.where(t > D, u * -np.expm1(-(t - D) / tau), 0.0)
    assert lifts == pytest.approx(expected.tolist(), abs=1e-12)


def test_a_constant_external_acceleration_is_learnt_on_every_axis() -> None:
    obs = ExternalForceObserver(PARAMS, T)
    airborne(obs)  # hovering: F_z = 0, the lift holds the weight
    d = (0.4, -0.3, 1.5)  # wind, and a vehicle 15 % heavier
    force = (d[0], d[1], -PARAMS.g + d[2])
    for _ in range(1000):  # 20 s: the lift per newton's 1 s low-pass has settled too
        obs.sent(0.0, True)
        obs.update(level(-1.0, force))
    assert obs.estimate == pytest.approx(list(d), abs=1e-6)
    assert obs.rate == pytest.approx([0.0, 0.0, 0.0], abs=1e-4)


def test_the_noise_left_on_the_estimate_is_the_closed_form() -> None:
    rng = np.random.default_rng(7)
    obs = ExternalForceObserver(PARAMS, T)
    airborne(obs)
    sd = np.sqrt(np.array(ACC_VARIANCE_TABLE_6_3))
    values, fast = [], 0
    for k in range(40_000):
        n = rng.standard_normal(3) * sd
        obs.sent(0.0, True)
        obs.update(level(-1.0, (n[0], n[1], -PARAMS.g + n[2])))
        fast += obs.fast_steps[0] > 0 or obs.fast_steps[1] > 0
        if k > 500:
            values.append(list(obs.estimate))
    est = np.array(values)
    vertical = alpha_beta(10.0, SIGMA_Z, T)
    assert float(np.std(est[:, 2])) == pytest.approx(vertical.noise_sd, rel=0.05)
    a = obs.quiet_alpha  # the quiet horizontal low-pass: sigma^2 alpha / (2 - alpha)
    quiet = sd[0] * math.sqrt(a / (2.0 - a))
    assert float(np.std(est[:, 0])) < 1.5 * quiet  # the fast filter's few false switches
    assert fast / 40_000 < 0.05  # on 800 s: a few false switches of 25 steps each


def test_a_horizontal_step_switches_the_fast_filter_on_at_once() -> None:
    obs = ExternalForceObserver(PARAMS, T)
    airborne(obs)
    obs.sent(0.0, True)
    obs.update(level(-1.0, (1.0, 0.0, -PARAMS.g)))
    assert obs.fast_steps[0] > 0 and obs.fast_steps[1] == 0
    assert obs.estimate[0] > 0.9  # the fast filter takes (nearly) the sample at once
    for _ in range(60):  # 1.2 s later: back to the quiet filter, at the new level
        obs.sent(0.0, True)
        obs.update(level(-1.0, (1.0, 0.0, -PARAMS.g)))
    assert obs.fast_steps[0] == 0 and obs.estimate[0] == pytest.approx(1.0, abs=1e-3)


@pytest.mark.parametrize("case", ["floor", "pilot", "saturated", "nan"])
def test_it_holds_its_estimate_when_the_sample_cannot_be_trusted(case: str) -> None:
    obs = ExternalForceObserver(PARAMS, T)
    airborne(obs)
    z = -0.005 if case == "floor" else -1.0  # 5 mm above where it stood: maybe on the floor
    force = (0.0, 0.0, -14.0 if case == "saturated" else -PARAMS.g + 2.0)
    if case == "nan":
        force = (math.nan, 0.0, 0.0)
    before = list(obs.estimate)
    for _ in range(20):
        obs.sent(0.0, case != "pilot")
        obs.update(level(z, force))
        assert not obs.learning
    assert obs.estimate == before


def test_the_loop_through_a_mispredicted_lift_has_small_gain() -> None:
    """``|((1 + e) e^{-j w Delta} - 1) F(e^{j w T})| < 1`` at every frequency, ``F`` the
    vertical estimate taken ``vertical_lead_s`` ahead, for lift per newton asked 0.74-1.35
    times the model's (thrust map and mass 15 % off either way) and a delay 15 ms off.
    Necessary, not sufficient: it leaves out the vertical loop the path closes around (the
    flights of tests/test_evaluation_disturbances.py on the corners of the lift's size and
    timing are the proof)."""
    obs = ExternalForceObserver(PARAMS, T)
    f, lead = obs.fast[1], obs.vertical_lead_s
    w = np.linspace(1e-3, math.pi / T, 20_000)
    z = np.exp(1j * w * T)
    den = z * z + (f.alpha + f.beta - 2.0) * z + 1.0 - f.alpha
    value = z * (f.alpha * z + f.beta - f.alpha) / den
    rate = (f.beta / T) * z * (z - 1.0) / den  # r_k = r_k-1 + (beta / T) nu_k
    F = value + lead * rate
    worst = max(float(np.max(np.abs(((1.0 + e) * np.exp(-1j * w * delta) - 1.0) * F)))
                for e in (0.85 / 1.15 - 1.0, 1.15 / 0.85 - 1.0) for delta in (-0.015, 0.015))
    assert worst < 0.75


def hover_on(obs: ExternalForceObserver, effectiveness: float, f_z: float, steps: int
             ) -> list[float]:
    """Send ``f_z`` [N] for ``steps`` COMMANDs to a vehicle whose lift per newton is
    ``effectiveness`` times the model's, at once (``obs`` without delay or motor lag, so its
    prediction is the lift sent); the vertical estimate after each."""
    lift = f_z - PARAMS.mass * PARAMS.g
    out = []
    for _ in range(steps):
        obs.sent(f_z, True)
        obs.update(level(-1.0, (0.0, 0.0, effectiveness * lift / PARAMS.mass)))
        out.append(obs.estimate[2])
    return out


def instant(effectiveness_tau_s: float = 1.0) -> ExternalForceObserver:
    """An observer whose lift model is the lift sent, at once."""
    return ExternalForceObserver(PARAMS, T, motor_tau_s=0.0, delay_s=0.0,
                                 effectiveness_tau_s=effectiveness_tau_s)


@pytest.mark.parametrize(("truth", "learnt"), [(0.7, 0.7), (0.9, 0.9), (1.3, 1.0)])
def test_the_lift_per_newton_is_learnt_where_it_is_below_the_models(truth: float,
                                                                     learnt: float) -> None:
    """A vehicle that gives ``truth`` of the lift the model predicts: the estimate is that
    ratio, capped at the model's; and ``d`` holds the whole shortfall, ``(truth - 1) L / m``
    (``L`` = the weight, so ``(1 - truth) g`` down), as it does without the estimate."""
    obs = instant()
    airborne(obs)
    hover_on(obs, truth, 0.0, 1000)  # F_z = 0: the lift asked is the weight
    assert obs.effectiveness == pytest.approx(learnt, abs=1e-9)
    assert obs.estimate[2] == pytest.approx((1.0 - truth) * PARAMS.g, abs=1e-9)


def test_the_commands_own_change_returns_in_d_only_as_slowly_as_the_estimate_follows() -> None:
    """On a vehicle with 70 % of the model's lift per newton, a step of the thrust asked
    (1 N more lift) shows in ``d`` as the shortfall ``(k - 1) dL / m`` (0.5 m/s^2 down):
    through the vertical filter alone without the lift-per-newton estimate (0.2 s after
    the step more than 80 % of it, at the filter's overshoot); with it only through its 1 s
    low-pass, so 0.2 s after the step no more than ``1 - exp(-0.2)`` (18 %) of the
    shortfall has come back, and the next command does not add the rest around the
    vertical loop's 1 Hz."""
    k, step = 0.7, 1.0
    shortfall = (1.0 - k) * step / PARAMS.mass
    changes = []
    for tau in (0.0, 1.0):
        obs = instant(tau)
        airborne(obs)
        before = hover_on(obs, k, 0.0, 1000)[-1]
        after = hover_on(obs, k, -step, 10)  # F_z < 0: more lift up, for 0.2 s
        changes.append(after[-1] - before)
    without, with_estimate = changes
    assert 0.8 * shortfall < without < 1.25 * shortfall
    assert 0.0 < with_estimate <= -math.expm1(-0.2) * shortfall
