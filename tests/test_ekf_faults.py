"""EKF fault handling (thesis Ch. 7.3), timing of Vicon poses, initialisation checks."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest
from ekf_truth import (
    SensorNoise,
    TruthSimulator,
    fly,
    hover_reference,
    square_reference,
)

from groundstation.errors import EstimatorError
from groundstation.estimation import Ekf, EkfParams, Estimator, PoseHoldEstimator
from groundstation.estimation.records import UpdateReason
from groundstation.types import ImuSample, Pose

BIASED = SensorNoise(gyro_bias=(0.02, -0.01, 0.03), acc_bias=(0.1, -0.2, 0.15))


def _started(seed: int = 1, steps: int = 500) -> tuple[Ekf, TruthSimulator]:
    """An EKF that has tracked the square for ``steps`` IMU samples with 100 Hz Vicon."""
    sim = TruthSimulator(square_reference(), noise=BIASED, seed=seed)
    ekf = Ekf()
    ekf.initialise(sim.pose(), [sim.imu()])
    for _ in range(steps):
        sim.step()
        ekf.predict(sim.imu())
        ekf.update(sim.pose())
    return ekf, sim


@pytest.mark.slow
@pytest.mark.parametrize("seed", [5, 6, 7])
def test_one_second_outage_has_bounded_error_growth(seed: int) -> None:
    sim = TruthSimulator(square_reference(), noise=BIASED, seed=seed)
    tr = fly(Ekf(), sim, 12.0, warmup=0.0, vicon_off=(8.0, 9.0))
    t, pe, ae = tr.t, tr.position_error, tr.attitude_error
    during = (t >= 8.0) & (t < 9.0)
    after = t >= 9.5
    print(f"seed {seed}: 1 s outage: max pos err {pe[during].max() * 1e3:.1f} mm, "
          f"att {ae[during].max() * 1e3:.2f} mrad")
    # Dead reckoning for 1 s: the filter's own position sigma reaches ~10 mm (Table 6.3
    # accelerometer noise, 6.8 mm/s/sqrt(s), plus the velocity and tilt uncertainty at the
    # start of the gap); bound at 4 sigma. Measured 10-19 mm and 4-8 mrad.
    assert pe[during].max() < 0.04
    assert ae[during].max() < 0.015
    assert pe[after].max() < 2e-3  # back to the 100 Hz level within 0.5 s
    assert tr.reasons.count("ok") == len(tr.reasons)


@pytest.mark.slow
def test_outage_visible_in_health() -> None:
    ekf, sim = _started(steps=200)
    tr0 = ekf.health().covariance_trace
    for _ in range(100):
        sim.step()
        ekf.predict(sim.imu())
    h = ekf.health()
    assert h.time_since_fix == pytest.approx(1.0, abs=1e-9)
    assert h.covariance_trace > tr0
    assert not h.diverged


@pytest.mark.slow
def test_outlier_is_gated_counted_and_does_not_move_the_estimate() -> None:
    ekf, sim = _started()
    sim.step()
    ekf.predict(sim.imu())
    before = ekf.state
    good = sim.pose()
    bad = Pose(good.t, good.position + np.array([0.3, 0.0, 0.0]), good.quaternion, good.frame)
    r = ekf.update(bad)
    assert (r.accepted, r.reason) == (False, "gated")
    assert r.nis > 1e3
    np.testing.assert_array_equal(ekf.state, before)
    h = ekf.health()
    assert h.gated == 1 and h.last_nis == r.nis
    # an attitude outlier (10 deg about z) is gated too
    q_bad = np.array([math.cos(0.0873), 0.0, 0.0, math.sin(0.0873)])
    sim.step()
    ekf.predict(sim.imu())
    assert ekf.update(Pose(sim.t, sim.x[0:3].copy(), q_bad, 0)).reason == "gated"
    assert ekf.health().gated == 2
    # and good poses are accepted again
    sim.step()
    ekf.predict(sim.imu())
    assert ekf.update(sim.pose()).reason == "ok"


def _wrong_start(offset_m: float) -> tuple[Ekf, TruthSimulator, list[UpdateReason]]:
    """A start ``offset_m`` off in x with an over-confident covariance, then 1.5 s of
    true poses at 100 Hz; the update reasons."""
    sim = TruthSimulator(hover_reference(), noise=BIASED, seed=3)
    p = EkfParams(initial_variance=(1e-8,) * 3 + (1e-4,) * 4 + (1e-2,) * 3 + (1e-3,) * 3
                  + (1e-1,) * 3)
    ekf = Ekf(p)
    wrong = sim.pose()
    off = wrong.position + np.array([offset_m, 0.0, 0.0])
    ekf.initialise(Pose(wrong.t, off, wrong.quaternion), [sim.imu()])
    reasons = []
    for _ in range(150):
        sim.step()
        ekf.predict(sim.imu())
        reasons.append(ekf.update(sim.pose()).reason)
    return ekf, sim, reasons


def test_persistent_gating_resets_to_vicon() -> None:
    # A start 15 cm off (within what the IMU may have missed: 5.3 sigma of
    # reset_position_sigma = 4 cm) gates every pose; after gate_reset_after (0.2 s) and
    # gate_reset_count consistent poses the filter re-anchors.
    ekf, sim, reasons = _wrong_start(0.15)
    assert reasons.count("reset") == 1
    first_reset = reasons.index("reset")
    assert set(reasons[:first_reset]) == {"gated"}
    assert first_reset >= ekf.params.gate_reset_count - 1
    assert ekf.health().resets == 1
    assert np.linalg.norm(ekf.state[0:3] - sim.x[0:3]) < 2e-3


@pytest.mark.slow
def test_an_unexplained_start_is_overruled_by_the_poses_after_evidence_after() -> None:
    # 0.5 m between Vicon and the estimate is more than the IMU may have missed (5.3 sigma
    # of reset_position_sigma = 4 cm is 21 cm), so it is no ordinary reset; but the poses
    # keep agreeing with each other, so after evidence_after (0.3 s) without a fix they
    # outrank the estimate: a forced re-anchoring, counted as overruled. The 0.15 m start
    # is an ordinary reset as soon as gate_reset_after (0.2 s) allows.
    small_ekf, _, small = _wrong_start(0.15)
    assert small_ekf.overruled[0] == 0 and small.count("reset") == 1
    ekf, sim, reasons = _wrong_start(0.5)
    first = reasons.index("reset")
    assert set(reasons[:first]) == {"gated"} and first > small.index("reset")
    assert 0.3 <= 0.01 * (first + 1) < 0.35  # the first pose 0.3 s after the start
    h = ekf.health()
    assert h.resets == 1 and h.forced_resets == 1
    count, why = ekf.overruled
    assert count == 1 and re.search(r"disagreed with the estimate for 0\.3\d s \(by 5\d cm", why)
    sigma = math.sqrt(float(np.trace(ekf.error_covariance[0:3, 0:3])))
    assert sigma < 0.01  # certain again after the reset
    assert np.linalg.norm(ekf.state[0:3] - sim.x[0:3]) < 2e-3


def _after_a_gap(gap_s: float = 1.5) -> tuple[Ekf, TruthSimulator]:
    """A tracking EKF, then ``gap_s`` of IMU samples without a pose (a Vicon pause)."""
    ekf, sim = _started()
    for _ in range(round(gap_s / 0.01)):
        sim.step()
        ekf.predict(sim.imu())
    return ekf, sim


@pytest.mark.slow
@pytest.mark.filterwarnings("error::RuntimeWarning")
@pytest.mark.parametrize("position", [(1e297, 0.0, -1.0), (0.0, -1e308, 0.0),
                                      (100.0, 0.0, -1.0), (0.0, 0.0, 3.0)],
                         ids=["1e297", "-1e308", "100m", "below-floor"])
def test_implausible_poses_are_refused_and_never_reset_the_filter(
        position: tuple[float, float, float]) -> None:
    """99 poses of absurd (or finite but impossible) positions after a 1.5 s
    gap. They are outside the plausible volume (safety volume + vicon margin), so they
    are refused before any arithmetic: no reset, no overflow warning, state untouched."""
    ekf, sim = _after_a_gap()
    q = sim.pose().quaternion
    for _ in range(99):
        sim.step()
        ekf.predict(sim.imu())
        before = ekf.state
        r = ekf.update(Pose(sim.t, np.array(position), q, 0))
        assert (r.accepted, r.reason) == (False, "implausible")
        np.testing.assert_array_equal(ekf.state, before)
    h = ekf.health()
    assert (h.implausible_poses, h.resets, h.updates, h.gated) == (99, 0, 500, 0)
    assert h.time_since_fix == pytest.approx(2.49, abs=0.02)
    for _ in range(20):
        sim.step()
        ekf.predict(sim.imu())
        assert ekf.update(sim.pose()).reason == "ok"  # 2.5 s of dead reckoning: within the gate
    assert ekf.health().resets == 0
    assert np.linalg.norm(ekf.state[0:3] - sim.x[0:3]) < 3e-3


def _jump_after_a_gap(gap_s: float, n: int) -> tuple[Ekf, TruthSimulator, list[UpdateReason]]:
    """``n`` poses 30 cm off the truth (consistent: Table 6.1-sized noise) after ``gap_s``
    without a pose; the update reasons."""
    ekf, sim = _after_a_gap(gap_s)
    rng = np.random.default_rng(4)
    reasons = []
    for _ in range(n):
        sim.step()
        ekf.predict(sim.imu())
        p = sim.pose()
        bad = p.position + np.array([0.3, 0.0, 0.0]) + rng.normal(0.0, 6e-4, 3)
        reasons.append(ekf.update(Pose(p.t, bad, p.quaternion, p.frame)).reason)
    return ekf, sim, reasons


@pytest.mark.slow
def test_a_consistent_jump_the_imu_did_not_see_outranks_the_estimate() -> None:
    """After a 1 s gap, poses 30 cm off that stay consistent. The IMU saw the vehicle fly
    the square, so the jump is far more than a missed velocity explains and no ordinary
    reset; but poses that keep agreeing with each other and not with the estimate mean
    the estimate is wrong: the run of gate_reset_count re-anchors it (the time since the
    last fix is past evidence_after already), and it is counted as overruled, which the
    supervisor treats as a failsafe. Refusing the truth indefinitely flew a vehicle away."""
    ekf, sim, reasons = _jump_after_a_gap(1.0, 50)
    n = ekf.params.gate_reset_count
    assert reasons[:n - 1] == ["gated"] * (n - 1) and reasons[n - 1] == "reset"
    assert ekf.health().forced_resets == 1 and ekf.overruled[0] == 1
    offset = ekf.state[0:3] - sim.x[0:3]  # on the poses, 30 cm off the truth
    assert abs(offset[0] - 0.3) < 0.02 and np.linalg.norm(offset[1:]) < 0.02


@pytest.mark.slow
def test_a_jump_the_dead_reckoned_covariance_covers_is_an_ordinary_reset() -> None:
    """The other side of the bound, which grows with the time since the last fix: a 5 cm
    jump after 1.5 s of dead reckoning is what the IMU may have missed: re-anchored at
    once, not counted as overruled."""
    ekf, sim = _after_a_gap(1.5)
    rng = np.random.default_rng(4)
    reasons = []
    for _ in range(100):
        sim.step()
        ekf.predict(sim.imu())
        p = sim.pose()
        bad = p.position + np.array([0.05, 0.0, 0.0]) + rng.normal(0.0, 6e-4, 3)
        reasons.append(ekf.update(Pose(p.t, bad, p.quaternion, p.frame)).reason)
    assert reasons[0] == "ok"  # within the dead-reckoned covariance: fused at once
    assert ekf.overruled[0] == 0 and ekf.health().forced_resets == 0


@pytest.mark.slow
def test_a_wrong_pose_between_true_ones_never_overrules_the_estimate() -> None:
    """A reflection or a second sender whose poses come between the true ones: each true
    pose is fused and clears the run of candidates, so no forced reset happens however
    long the wrong poses keep coming (the pose filter's rival-stream alarm handles them)."""
    ekf, sim = _started()
    rng = np.random.default_rng(5)
    for _ in range(200):
        sim.step()
        ekf.predict(sim.imu())
        p = sim.pose()
        bad = p.position + np.array([0.3, 0.0, 0.0]) + rng.normal(0.0, 6e-4, 3)
        assert ekf.update(Pose(p.t - 0.001, bad, p.quaternion, p.frame)).reason == "gated"
        assert ekf.update(p).reason in ("ok", "repeated")
    assert ekf.overruled[0] == 0 and ekf.health().resets == 0


@pytest.mark.slow
def test_a_reset_needs_poses_that_agree_with_each_other() -> None:
    """After a gap, poses alternately 15 cm either side of the truth. Each is
    within what the IMU may have missed, but no two in a row agree (30 cm in 10 ms is
    beyond max speed), so none re-anchors the filter."""
    ekf, sim = _after_a_gap(1.0)
    for k in range(40):
        sim.step()
        ekf.predict(sim.imu())
        p = sim.pose()
        side = 0.15 if k % 2 == 0 else -0.15
        r = ekf.update(Pose(p.t, p.position + np.array([side, 0.0, 0.0]), p.quaternion, 0))
        assert r.reason == "gated"
    h = ekf.health()
    assert h.resets == 0 and h.refused_resets == 39
    assert np.linalg.norm(ekf.state[0:3] - sim.x[0:3]) < 0.04


@pytest.mark.slow
def test_repeated_samples_are_ignored() -> None:
    ekf, sim = _started()
    sim.step()
    imu = sim.imu()
    ekf.predict(imu)
    pose = sim.pose()
    assert ekf.update(pose).reason == "ok"
    state = ekf.state
    # Algorithm 1: the same DATA counter again (even with a later time) is not new
    ekf.predict(ImuSample(imu.t + 0.01, imu.gyro, imu.acc, imu.counter))
    # identical values with a new counter are not new either (link held the last values)
    ekf.predict(ImuSample(imu.t + 0.01, imu.gyro.copy(), imu.acc.copy(), imu.counter + 1))
    # the same pose again (same frame number / identical values)
    r1 = ekf.update(pose)
    r2 = ekf.update(Pose(pose.t, pose.position.copy(), pose.quaternion.copy(), 0))
    assert (r1.reason, r2.reason) == ("repeated", "repeated")
    np.testing.assert_array_equal(ekf.state, state)
    h = ekf.health()
    assert (h.repeated_imu, h.repeated_poses) == (2, 2)


@pytest.mark.slow
def test_an_identity_attitude_is_a_pose_like_any_other() -> None:
    """Algorithm 2's lost-tracking encodings are the pose filter's to recognise, on the raw
    values (a held translation): to the filter an identity attitude is a level vehicle at
    heading 0, which a noise-free Vicon sender reports exactly."""
    ekf, sim = _started()
    sim.step()
    ekf.predict(sim.imu())
    level = Pose(sim.t, sim.pose().position, np.array([1.0, 0.0, 0.0, 0.0]), 0)
    r = ekf.update(level)
    assert r.accepted and r.reason == "ok"


def test_invalid_samples_are_counted_and_skipped() -> None:
    ekf, sim = _started(steps=50)
    state = ekf.state
    assert ekf.update(Pose(sim.t, np.array([np.nan, 0, 0]), np.array([1.0, 0, 0, 0]))).reason \
        == "invalid"
    assert ekf.update(Pose(sim.t, np.zeros(3), np.array([2.0, 0, 0, 0]))).reason == "invalid"
    ekf.predict(ImuSample(sim.t + 0.01, np.array([np.inf, 0, 0]), np.zeros(3), 9999))
    np.testing.assert_array_equal(ekf.state, state)
    h = ekf.health()
    assert (h.invalid_poses, h.invalid_imu) == (2, 1)
    # an IMU sample not newer than the filter time is stale
    ekf.predict(ImuSample(sim.t - 0.5, np.zeros(3), np.array([0, 0, -9.82]), 4242))
    assert ekf.health().stale_imu == 1


def _recorded(n: int, seed: int = 6) -> tuple[list[ImuSample], list[Pose]]:
    sim = TruthSimulator(square_reference(), noise=BIASED, seed=seed)
    for _ in range(200):
        sim.step()
    imus, poses = [], []
    for _ in range(n):
        imus.append(sim.imu())
        poses.append(sim.pose(0.0037))  # stamped between IMU samples
        sim.step()
    return imus, poses


@pytest.mark.slow
@pytest.mark.parametrize("delay", [1, 4, 15])
def test_late_pose_equals_in_order_pose(delay: int) -> None:
    # In order: each pose (stamped 3.7 ms after its IMU sample) is handed over before the
    # next IMU sample, waits ("deferred") and is applied inside the next predict.
    # Late: the same poses arrive `delay` IMU samples later and are applied by
    # re-propagating from the checkpoint before their time stamp.
    imus, poses = _recorded(120)
    a, b = Ekf(), Ekf()
    a.initialise(poses[0], [imus[0]])
    b.initialise(poses[0], [imus[0]])
    late: list[Pose] = []
    for k in range(1, 120):
        a.predict(imus[k])
        b.predict(imus[k])
        if k < 119:
            assert a.update(poses[k]).reason == "deferred"
        late.append(poses[k])
        if len(late) > delay:
            assert b.update(late.pop(0)).reason == "ok"
    # bring b up to date with the same poses a has applied (a: up to poses[118])
    for p in late:
        if p.t < imus[-1].t:
            assert b.update(p).reason == "ok"
    np.testing.assert_allclose(b.state, a.state, atol=1e-12, rtol=0)
    np.testing.assert_allclose(b.error_covariance, a.error_covariance, atol=1e-15, rtol=1e-9)
    assert a.health().updates == b.health().updates == 118  # poses[1..118]


def test_late_pose_at_an_imu_time_equals_immediate() -> None:
    sim = TruthSimulator(square_reference(), noise=BIASED, seed=9)
    imus, poses = [], []
    for _ in range(60):
        imus.append(sim.imu())
        poses.append(sim.pose())
        sim.step()
    a, b = Ekf(), Ekf()
    a.initialise(poses[0], [imus[0]])
    b.initialise(poses[0], [imus[0]])
    for k in range(1, 60):
        a.predict(imus[k])
        a.update(poses[k])
        b.predict(imus[k])
        if k >= 3:
            b.update(poses[k - 2])
    b.update(poses[58])
    b.update(poses[59])
    np.testing.assert_allclose(b.state, a.state, atol=1e-12, rtol=0)


def test_too_old_and_future_poses() -> None:
    ekf, sim = _started(steps=100)
    old = sim.pose(-0.3)  # beyond max_vicon_delay = 0.2 s
    assert ekf.update(Pose(old.t, old.position, old.quaternion, 0)).reason == "too_old"
    future = sim.pose(+0.5)
    assert ekf.update(Pose(future.t, future.position, future.quaternion, 0)).reason == "future"
    assert ekf.health().too_old == 2


def test_pose_before_initialise_and_imu_before_initialise() -> None:
    ekf = Ekf()
    assert ekf.update(Pose(0.0, np.zeros(3), np.array([1.0, 0, 0, 0]))).reason == "not_initialised"
    ekf.predict(ImuSample(0.0, np.zeros(3), np.zeros(3)))  # ignored, no exception
    assert not ekf.health().initialised


@pytest.mark.parametrize(
    ("what", "expect_ok"),
    [("correct", True), ("imu_z_flipped", False), ("vicon_rolled_90", False)],
)
def test_gravity_check_catches_a_wrong_frame(what: str, expect_ok: bool) -> None:
    sim = TruthSimulator(hover_reference((0.0, 0.0, 0.0)), noise=BIASED, seed=2, on_ground=True)
    samples = []
    for _ in range(100):
        s = sim.imu()
        if what == "imu_z_flipped":  # accelerometer mounted/configured upside down
            s = ImuSample(s.t, s.gyro, s.acc * np.array([1.0, 1.0, -1.0]), s.counter)
        samples.append(s)
        sim.step()
    pose = sim.pose()
    if what == "vicon_rolled_90":  # Vicon frame conversion off by 90 deg about x
        c = math.sqrt(0.5)
        pose = Pose(pose.t, pose.position, np.array([c, c, 0.0, 0.0]), pose.frame)
    report = Ekf().initialise(pose, samples)
    assert report.gravity_ok is expect_ok
    assert report.stationary
    if not expect_ok:
        assert report.gravity_angle_deg > 45.0
        np.testing.assert_array_equal(report.acc_bias, 0.0)  # not learnt from bad data


@pytest.mark.slow
def test_covariance_stays_symmetric_positive_definite_and_quaternion_unit() -> None:
    ekf, _ = _started(steps=300)
    P = ekf.error_covariance
    np.testing.assert_array_equal(P, P.T)
    assert np.linalg.eigvalsh(P).min() > 0.0
    assert np.linalg.norm(ekf.state[3:7]) == pytest.approx(1.0, abs=1e-14)
    est = ekf.estimate()
    assert est.covariance_diag.shape == (16,) and np.all(est.covariance_diag > 0)
    # quaternion variances map from the attitude error: small angle, var(q_i) ~ var(theta_i)/4
    np.testing.assert_allclose(est.covariance_diag[4:7], np.diag(P)[3:6] / 4, rtol=0.05)


def test_non_finite_covariance_raises_estimator_error() -> None:
    ekf, sim = _started(steps=10)
    ekf._P[5, 5] = np.nan  # simulate numerical breakdown
    sim.step()
    with pytest.raises(EstimatorError):
        ekf.predict(sim.imu())


def test_estimator_protocol_and_null_estimator() -> None:
    assert isinstance(Ekf(), Estimator)
    null = PoseHoldEstimator()
    assert isinstance(null, Estimator)
    pose = Pose(1.0, np.array([1.0, 2.0, -1.0]), np.array([1.0, 0, 0, 0]))
    null.initialise(pose, [ImuSample(1.0, np.array([0.1, 0, 0]), np.zeros(3))])
    est = null.estimate()
    np.testing.assert_array_equal(est.position, pose.position)
    np.testing.assert_array_equal(est.omega, [0.1, 0, 0])
    assert np.all(np.isnan(est.covariance_diag))
    assert null.update(pose).accepted


def test_estimate_record_matches_state() -> None:
    ekf, sim = _started(steps=50)
    sim.step()
    imu = sim.imu()
    ekf.predict(imu)
    est = ekf.estimate()
    x = ekf.state
    np.testing.assert_array_equal(est.position, x[0:3])
    np.testing.assert_array_equal(est.quaternion, x[3:7])
    np.testing.assert_array_equal(est.velocity_body, x[7:10])
    np.testing.assert_array_equal(est.gyro_bias, x[10:13])
    np.testing.assert_array_equal(est.acc_bias, x[13:16])
    # omega is the last gyro sample minus the estimated bias (true = measured - bias)
    np.testing.assert_allclose(est.omega, imu.gyro - x[10:13], rtol=0, atol=1e-15)
    assert est.t == imu.t


@pytest.mark.slow
def test_imu_gap_is_sub_stepped() -> None:
    # 0.1 s without IMU data (e.g. a radio drop-out): the next sample is integrated in
    # sub-steps of at most max_step with the input interpolated, and Vicon pulls it back.
    ekf, sim = _started(steps=300)
    for _ in range(10):
        sim.step()  # samples lost on the link
    sim.step()
    ekf.predict(sim.imu())
    assert np.linalg.norm(ekf.state[0:3] - sim.x[0:3]) < 5e-3
    assert ekf.health().t == pytest.approx(sim.t)
    for _ in range(50):
        sim.step()
        ekf.predict(sim.imu())
        assert ekf.update(sim.pose()).reason == "ok"
    assert np.linalg.norm(ekf.state[0:3] - sim.x[0:3]) < 1.5e-3


def test_velocity_error_the_imu_did_not_see_is_corrected_quickly() -> None:
    """A vehicle descending at 0.3 m/s stops at t = 2 s without the accelerometer seeing
    it (a touchdown that saturated it). Vicon at 10 Hz keeps reporting the true
    position; persistent gating must re-anchor the filter and forget its velocity."""
    rng = np.random.default_rng(11)
    # A small heading: exactly identity would be the lost-tracking encoding (Alg. 2);
    # sensor noise and frame numbers: bit-identical samples would be repeats (Alg. 1).
    attitude = np.array([math.cos(0.05), 0.0, 0.0, math.sin(0.05)])

    def imu(t: float, k: int) -> ImuSample:
        return ImuSample(t, rng.normal(0.0, 0.01, 3), np.array([0.0, 0.0, -9.82])
                         + rng.normal(0.0, 0.05, 3), k)

    def z_true(t: float) -> float:
        return -1.0 + 0.3 * min(t, 2.0)  # NED: descending, then stopped at -0.4 m

    ekf = Ekf()
    ekf.initialise(Pose(0.0, np.array([0.0, 0.0, -1.0]), attitude),
                   [imu(-0.01 * k, k) for k in range(20, 0, -1)])
    ekf._x[7:10] = (0.0, 0.0, 0.3)  # start with the true descent rate (white box)
    t = 0.01 * np.arange(1, 500)
    err = np.zeros(t.size)
    for i, ti in enumerate(t):
        ekf.predict(imu(float(ti), 100 + i))
        if (i + 1) % 10 == 0:  # Vicon: new frame number and Table 6.1-sized noise
            z = z_true(float(ti)) + rng.normal(0.0, 5e-4)
            ekf.update(Pose(float(ti), np.array([0.0, 0.0, z]), attitude, frame=i))
        err[i] = abs(ekf.estimate().position[2] - z_true(float(ti)))
    assert err[t < 2.0].max() < 0.01  # tracking the descent
    assert err.max() < 0.12  # the dead-reckoned overshoot stays bounded (~0.3 s at 0.3 m/s)
    assert err[t > 2.6].max() < 0.02  # re-anchored and the velocity re-learned
    assert abs(ekf.estimate().velocity_body[2]) < 0.05
    assert ekf.health().resets >= 1


@pytest.mark.slow
@pytest.mark.parametrize("gap", [1, 4])  # one sample ahead; 40 ms ahead (sub-stepped)
def test_estimate_ahead_is_the_prediction_without_moving_the_filter(gap: int) -> None:
    """``estimate_ahead`` must give exactly the nominal state ``predict`` would reach (the
    same RK4 steps and input interpolation), leave the filter where it is, and carry the
    filter's covariance, not a predicted one."""
    ekf, sim = _started(steps=200)
    for _ in range(gap):
        sim.step()
    imu = sim.imu()
    x0, p0, t0 = ekf.state, ekf.error_covariance, ekf.health().t
    ahead = ekf.estimate_ahead(imu)
    np.testing.assert_array_equal(ekf.state, x0)  # the filter did not move
    np.testing.assert_array_equal(ekf.error_covariance, p0)
    current = ekf.estimate()
    ekf.predict(imu)  # now move it: the state must be the one predicted
    moved = ekf.estimate()
    assert ahead.t == moved.t == pytest.approx(t0 + gap * 0.01)
    for field in ("position", "quaternion", "velocity_body", "omega", "gyro_bias", "acc_bias"):
        np.testing.assert_allclose(getattr(ahead, field), getattr(moved, field),
                                   atol=1e-14, rtol=0, err_msg=field)
    keep = np.r_[0:3, 7:16]  # the quaternion entries map the same attitude-error block
    np.testing.assert_array_equal(ahead.covariance_diag[keep], current.covariance_diag[keep])
    assert ahead.covariance_diag[3:7].sum() == pytest.approx(current.covariance_diag[3:7].sum(),
                                                             rel=1e-12)  # trace(P_tt) / 4
    assert ahead.t > current.t


def test_estimate_ahead_of_a_sample_predict_would_skip_is_the_estimate() -> None:
    ekf, sim = _started(steps=50)
    last = sim.imu()  # already predicted: not newer, same counter
    bad = ImuSample(last.t + 0.01, np.array([np.nan, 0.0, 0.0]), last.acc, last.counter + 1)
    for imu in (last, bad):
        ahead, now = ekf.estimate_ahead(imu), ekf.estimate()
        assert ahead.t == now.t
        np.testing.assert_array_equal(ahead.position, now.position)
    assert ekf.health().invalid_imu == 0  # counted when predict sees it, not here


@pytest.mark.slow
def test_late_poses_are_counted() -> None:
    imus, poses = _recorded(40)
    ekf = Ekf()
    ekf.initialise(poses[0], [imus[0]])
    for k in range(1, 40):
        ekf.predict(imus[k])
        if k >= 2:
            assert ekf.update(poses[k - 1]).reason == "ok"  # stamped before the filter time
    assert ekf.health().late_poses == 38


def test_a_repeated_pose_of_a_vehicle_standing_on_the_floor_is_fused() -> None:
    """A sender without noise repeats a still vehicle's pose exactly; told the vehicle
    stands, the filter fuses the repeat (its covariance shrinks as a fused pose's does)
    and counts nothing as repeated."""
    ekf, sim = _started()
    sim.step()
    ekf.predict(sim.imu())
    pose = sim.pose()
    assert ekf.update(pose).reason == "ok"
    before = np.trace(ekf.error_covariance[0:3, 0:3])
    again = ekf.update(Pose(pose.t, pose.position.copy(), pose.quaternion.copy(), 0),
                       still=True)
    assert again.reason == "ok" and again.accepted
    assert np.trace(ekf.error_covariance[0:3, 0:3]) < before
    assert ekf.health().repeated_poses == 0
