"""EKF initialisation from a Vicon fix and IMU samples at rest, with the gravity check."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from groundstation.estimation.records import EkfParams, InitReport
from groundstation.model.quaternion import canonical, gravity_body
from groundstation.types import FloatArray, ImuSample, Pose

__all__ = ["gravity_check", "initial_state"]


def gravity_check(
    acc_mean: FloatArray, q: FloatArray, g: float, tolerance_deg: float
) -> tuple[bool, float, float]:
    """Compare a mean accelerometer reading with the specific force expected at rest.

    At rest the accelerometer reads ``-bCe [0, 0, g]`` (body FRD, m/s^2). Returns
    ``(ok, angle_deg, norm)``: ``ok`` when the angle between measured and expected
    is within ``tolerance_deg`` and ``|acc_mean|`` within 15 % of ``g``.
    """
    expected = -gravity_body(q, g)
    norm = float(np.linalg.norm(acc_mean))
    if norm == 0.0:
        return False, 180.0, 0.0
    cosang = float(acc_mean @ expected) / (norm * g)
    angle = math.degrees(math.acos(max(-1.0, min(1.0, cosang))))
    return angle <= tolerance_deg and abs(norm - g) <= 0.15 * g, angle, norm


def initial_state(
    pose: Pose, imu_samples: Sequence[ImuSample], params: EkfParams
) -> tuple[FloatArray, InitReport]:
    """Initial 16-state and report: pose from Vicon, zero velocity, biases from the IMU.

    Biases are taken from the samples only if they look stationary (per-axis gyro
    std below ``stationary_gyro_std``) and the gravity check passes; otherwise 0.
    """
    x = np.zeros(16)
    x[0:3] = pose.position
    q = canonical(pose.quaternion / np.linalg.norm(pose.quaternion))
    x[3:7] = q
    n = len(imu_samples)
    if n == 0:
        return x, InitReport(float(pose.t), 0, None, None, math.nan, math.nan,
                             np.zeros(3), np.zeros(3))  # fmt: skip
    gyros = np.array([s.gyro for s in imu_samples], dtype=float)
    accs = np.array([s.acc for s in imu_samples], dtype=float)
    g_mean, a_mean = gyros.mean(axis=0), accs.mean(axis=0)
    stationary = bool(n >= 2 and np.all(gyros.std(axis=0) < params.stationary_gyro_std))
    ok, angle, norm = gravity_check(a_mean, q, params.g, params.gravity_check_deg)
    if params.init_biases_from_imu and stationary and ok:
        x[10:13] = g_mean
        x[13:16] = a_mean + gravity_body(q, params.g)  # measured - expected(-g_b)
    t = max(float(pose.t), float(imu_samples[-1].t))
    report = InitReport(t, n, stationary, ok, angle, norm, x[10:13].copy(), x[13:16].copy())
    return x, report
