"""The flight core's estimator arrangement: the filter one IMU sample behind, the output ahead."""

from __future__ import annotations

import numpy as np
import pytest
from ekf_truth import SensorNoise, TruthSimulator, square_reference

from groundstation.config import validate_config
from groundstation.estimation import Ekf, Estimator, PoseHoldEstimator
from groundstation.flight.assembly import assemble, ekf_params
from groundstation.flight.core import INIT_IMU_SAMPLES, FlightCore
from groundstation.types import ImuSample, Pose


def _real_time_stream(n: int) -> list[tuple[ImuSample, Pose]]:
    """What the daemon sees each tick: the new IMU sample and the Vicon pose that arrived
    since the last tick. As in a real-time flight against the virtual lab, the pose came
    in shortly after the previous DATA frame and its stamp (receive time minus the Vicon
    latency) lies before that frame's: here 2.3 ms before the previous sample."""
    sim = TruthSimulator(square_reference(),
                         noise=SensorNoise(gyro_bias=(0.02, -0.01, 0.03),
                                           acc_bias=(0.1, -0.2, 0.15)), seed=11)
    out = []
    pose = sim.pose(-0.0023)
    for _ in range(n):
        sim.step()
        out.append((sim.imu(), pose))
        pose = sim.pose(-0.0023)  # arrives with the next sample
    return out


@pytest.mark.slow
def test_held_sample_fuses_every_pose_in_order_and_matches_replay() -> None:
    """The old arrangement (filter at the newest sample) fuses each of these poses by
    re-propagation; the flight core's must give the same estimate without any."""
    cfg = validate_config({})
    core = FlightCore(assemble(cfg))
    stream = _real_time_stream(400)
    # the same initialisation as the core: first pose with the first 20 IMU samples
    first = stream[:INIT_IMU_SAMPLES]
    for imu, pose in first:
        assert core.estimate_step(imu, [pose]) is None
    ref = Ekf(ekf_params(cfg))
    ref.initialise(first[-1][1], [imu for imu, _ in first])
    worst = 0.0
    for imu, pose in stream[INIT_IMU_SAMPLES:]:
        est = core.estimate_step(imu, [pose])
        ref.update(pose)
        ref.predict(imu)
        expect = ref.estimate()
        assert est is not None and est.t == expect.t == imu.t
        worst = max(worst, float(np.abs(est.position - expect.position).max()))
        np.testing.assert_allclose(est.quaternion, expect.quaternion, atol=1e-9, rtol=0)
        np.testing.assert_allclose(est.velocity_body, expect.velocity_body, atol=1e-9, rtol=0)
    assert worst < 1e-9, worst
    assert ref.health().late_poses > 350  # the old arrangement re-propagated nearly all
    assert core.ekf.health().late_poses == 0
    assert core.ekf.health().updates == ref.health().updates


def test_the_core_flies_any_estimator_of_the_protocol() -> None:
    """FlightCore is typed and run against the Estimator protocol, not the EKF: the
    smallest estimator that satisfies it passes through initialisation, updates and the
    per-tick failsafe figures; it checks no gravity, so the preflight would refuse."""
    core = FlightCore(assemble(validate_config({})), estimator=PoseHoldEstimator())
    assert isinstance(core.ekf, Estimator)
    stream = _real_time_stream(INIT_IMU_SAMPLES + 30)
    for imu, pose in stream[:INIT_IMU_SAMPLES]:
        assert core.estimate_step(imu, [pose]) is None
    assert core.init_report is not None and core.init_report.gravity_ok is None
    for imu, pose in stream[INIT_IMU_SAMPLES:]:
        est = core.estimate_step(imu, [pose])
        assert est is not None and est.t == imu.t
        np.testing.assert_array_equal(est.position, pose.position)
        np.testing.assert_array_equal(est.omega, imu.gyro)
    assert not core.ekf.diverged
    # the filter runs one sample behind: at the previous sample, after the newest pose
    assert core.ekf.time_since_fix == stream[-2][0].t - stream[-1][1].t
    assert core.ekf.health().updates == 30
