"""Parameters and result records of the IMU-driven EKF (thesis Ch. 6-7).

:class:`EkfParams` is a plain record, as PX4's ekf2 keeps its ``struct parameters``:
the estimator never sees the configuration. Its fields come from the ``vehicle``
(sensor variances) and ``estimator`` sections, with the gate reset's consistency
figures and the plausible volume from the ``vicon`` and ``safety`` sections, in one
place: :func:`groundstation.flight.assembly.ekf_params`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np

from groundstation.model.quadrotor import QuadrotorParams
from groundstation.model.sensors import (
    ACC_VARIANCE_TABLE_6_3,
    GRAVITY_CHECK_DEG,
    GYRO_VARIANCE_TABLE_6_3,
    INITIAL_STATE_VARIANCE,
    VICON_POSITION_VARIANCE_TABLE_6_1,
    VICON_QUATERNION_VARIANCE_TABLE_6_1,
)
from groundstation.types import FloatArray

_VEHICLE = QuadrotorParams()
"""The vehicle model's defaults (g)."""

__all__ = ["EkfHealth", "EkfParams", "InitReport", "UpdateReason", "UpdateResult"]

Vec3 = tuple[float, float, float]
Box = tuple[tuple[float, float], tuple[float, float], tuple[float, float]]

UpdateReason = Literal[
    "ok",  # applied at its time stamp
    "reset",  # applied as a re-initialisation after persistent gating (or forced: see Ekf)
    "deferred",  # newer than the last IMU sample: queued, applied when the IMU reaches it
    "gated",  # chi-square gate rejected the innovation (outlier)
    "repeated",  # Algorithm 1: same frame number or identical values as the previous pose
    "too_old",  # older than the re-propagation window
    "future",  # further ahead of the IMU than the window (clock problem)
    "invalid",  # non-finite values or a quaternion far from unit norm
    "implausible",  # a position outside the plausible volume (never fused, never reset to)
    "not_initialised",  # initialise() has not been called
]


@dataclass(frozen=True, slots=True)
class EkfParams:
    """EKF tuning. Units in brackets; defaults name their source.

    g : gravity [m/s^2] (eq. 3.8).
    gyro_var, acc_var : per-sample IMU noise variances at ``imu_period``
        [(rad/s)^2], [(m/s^2)^2] (Table 6.3). The continuous noise density is
        ``var * imu_period``.
    imu_period : IMU sample period the variances refer to [s] (100 Hz, Ch. 7.2).
    gyro_bias_walk, acc_bias_walk : bias random-walk densities [(rad/s)^2/s],
        [(m/s^2)^2/s] (a lab MEMS IMU's temperature drift; ``estimator`` in the
        configuration documents them).
    process_noise_scale : multiplies the IMU variances in Q.
    vicon_position_var : [m^2] (Table 6.1).
    vicon_quaternion_var : q0..q3 component variances (Table 6.1). The filter
        uses a 3-component attitude residual: ``var(dtheta_i) = 4 var(q_i)``
        (``q_i ~ dtheta_i / 2`` near the measured attitude); ``var(q0)`` is not
        independent (unit norm) and is not used.
    min_measurement_var : floor on every R diagonal entry [m^2 or rad^2].
    initial_variance : (16,) initial covariance diagonal in the state layout
        ``[P, q, v, b_g, b_a]``; the quaternion entries map to ``4 var(q1..q3)``.
    gate_probability : chi-square gate on the 6-dof innovation (1e-4 false rejects).
    max_vicon_delay : poses older than this behind the last IMU sample, or
        further ahead of it, are dropped [s]; also sets the history length.
    gate_reset_after, gate_reset_count : the gate reset. After ``gate_reset_after``
        [s] without an accepted fix, ``gate_reset_count`` consecutive gated poses that
        are *reset candidates* re-initialise position and attitude from the last of
        them and reset the velocity variance (one bad estimate cannot lock the gate).
        A candidate agrees with the one before it (``max_speed``, ``max_rotation_rate``
        plus the pose filter's slack, for their spacing) and with the IMU prediction:
        its innovation passes the same chi-square bound with the innovation covariance
        grown by what the IMU may have missed (``reset_position_sigma``,
        ``reset_attitude_sigma``); the prediction's own covariance has grown with the
        time since the last fused pose. Never one pose, never a pose outside the
        plausible volume. 0.2 s and 3 poses (``vicon.reanchor_poses``): an
        isolated outlier is still rejected, but a touchdown that left the velocity wrong
        is corrected within 0.2 s at 100 Hz Vicon and 0.3 s at 10 Hz.
    reset_position_sigma, reset_attitude_sigma : 1-sigma disagreement [m], [rad] the IMU
        may have missed and a reset may correct: a touchdown or knock that clipped the
        accelerometer (the landing test's 0.3 m/s stop leaves ~0.1 m after 0.3 s). With
        the 5.3 sigma of the gate that allows ~0.21 m and 15 deg; a larger disagreement is
        not the IMU's: a wrong Vicon pose (a reflection, another sender) or a wrong
        estimate. A single such pose is refused (counted); poses that keep agreeing with
        each other for ``evidence_after`` prove the estimate wrong (below).
    evidence_after : [s] without a fused pose after which ``gate_reset_count`` consecutive
        gated poses that agree with each other re-anchor the estimate even when the IMU
        prediction cannot explain them (counted as overruled; the supervisor lands). 0.3 s:
        below the supervisor's 0.5 s Vicon-loss hold, so refused truth never reads as a lost
        Vicon, and 3 poses at 10 Hz; long enough for an isolated burst of reflections.
    max_speed, max_rotation_rate : the consistency gate between reset candidates [m/s],
        [rad/s] (``vicon.max_speed_m_s``, ``vicon.max_rotation_rate_rad_s``).
    plausible_volume : where a pose can be, NED [m] ((x_min, x_max), (y_min, y_max),
        (z_min, z_max)); a pose outside is refused as "implausible" before any
        arithmetic, or None for no limit. Default: the configuration's flight volume
        grown by ``vicon.plausibility_margin_m``.
    divergence_trace : covariance trace [16-layout units] that flags divergence in health.
    max_step : longest single integration step [s]; longer IMU gaps are sub-stepped.
    imu_repeat_on_identical : Algorithm 1 also for identical values with a new counter.
    init_biases_from_imu : estimate initial biases from stationary IMU samples.
    stationary_gyro_std : per-axis gyro std [rad/s] below which samples count as at rest.
    gravity_check_deg : largest angle between measured and Vicon-predicted gravity.
    """

    g: float = _VEHICLE.g
    gyro_var: Vec3 = GYRO_VARIANCE_TABLE_6_3
    acc_var: Vec3 = ACC_VARIANCE_TABLE_6_3
    imu_period: float = 0.01
    gyro_bias_walk: float = 1e-8
    acc_bias_walk: float = 1e-7
    process_noise_scale: float = 1.0
    vicon_position_var: Vec3 = VICON_POSITION_VARIANCE_TABLE_6_1
    vicon_quaternion_var: tuple[float, float, float, float] = VICON_QUATERNION_VARIANCE_TABLE_6_1
    min_measurement_var: float = 1e-9
    initial_variance: tuple[float, ...] = INITIAL_STATE_VARIANCE
    gate_probability: float = 0.9999
    max_vicon_delay: float = 0.2
    gate_reset_after: float = 0.2
    gate_reset_count: int = 3
    evidence_after: float = 0.3
    reset_position_sigma: float = 0.04
    reset_attitude_sigma: float = 0.05
    max_speed: float = 5.0
    max_rotation_rate: float = 30.0
    plausible_volume: Box | None = ((-2.0, 2.0), (-2.0, 2.0), (-2.5, 0.55))
    divergence_trace: float = 10.0
    max_step: float = 0.025
    imu_repeat_on_identical: bool = True
    init_biases_from_imu: bool = True
    stationary_gyro_std: float = 0.1
    gravity_check_deg: float = GRAVITY_CHECK_DEG

    def __post_init__(self) -> None:
        """Validate once: shapes, positivity, probability range."""
        for name in ("gyro_var", "acc_var", "vicon_position_var"):
            _check_positive(name, getattr(self, name), 3)
        _check_positive("vicon_quaternion_var", self.vicon_quaternion_var, 4)
        _check_positive("initial_variance", self.initial_variance, 16)
        for name in ("g", "imu_period", "gyro_bias_walk", "acc_bias_walk", "process_noise_scale",
                     "min_measurement_var", "max_vicon_delay", "gate_reset_after", "evidence_after",
                     "divergence_trace", "max_step", "stationary_gyro_std",
                     "gravity_check_deg", "reset_position_sigma", "reset_attitude_sigma",
                     "max_speed", "max_rotation_rate"):  # fmt: skip
            _check_positive(name, (getattr(self, name),), 1)
        box = self.plausible_volume
        if box is not None and (len(box) != 3 or not all(
                math.isfinite(lo) and math.isfinite(hi) and lo < hi for lo, hi in box)):
            raise ValueError(f"plausible_volume must be three finite (min, max), got {box!r}")
        if not 0.5 < self.gate_probability < 1.0:
            raise ValueError(f"gate_probability must be in (0.5, 1), got {self.gate_probability}")
        if self.gate_reset_count < 1:
            raise ValueError(f"gate_reset_count must be >= 1, got {self.gate_reset_count}")

    def measurement_variance(self) -> FloatArray:
        """(6,) R diagonal for the residual ``[dP (3), dtheta (3)]`` [m^2, rad^2]."""
        r = np.r_[self.vicon_position_var, 4.0 * np.asarray(self.vicon_quaternion_var[1:])]
        out: FloatArray = np.maximum(r, self.min_measurement_var)
        return out

    def initial_error_variance(self) -> FloatArray:
        """(15,) initial error-state covariance diagonal ``[dP, dtheta, dv, db_g, db_a]``."""
        v = np.asarray(self.initial_variance, dtype=float)
        out: FloatArray = np.r_[v[0:3], 4.0 * v[4:7], v[7:16]]
        return out


def _check_positive(name: str, values: tuple[float, ...], n: int) -> None:
    if len(values) != n or not all(math.isfinite(v) and v > 0.0 for v in values):
        raise ValueError(f"{name} must be {n} finite positive numbers, got {values!r}")


@dataclass(frozen=True, slots=True)
class UpdateResult:
    """Outcome of :meth:`Ekf.update`.

    accepted : the pose is (or, for ``deferred``, will be) fused into the estimate.
    nis : normalised innovation squared ``y^T S^-1 y`` (6 dof), NaN if not computed.
    reason : see :data:`UpdateReason`.
    """

    accepted: bool
    nis: float
    reason: UpdateReason


@dataclass(frozen=True, slots=True)
class InitReport:
    """What :meth:`Ekf.initialise` found in the first samples.

    n_imu : IMU samples used; stationary : gyro quiet (None without samples).
    gravity_ok : the mean accelerometer reading points where the Vicon attitude
        says gravity is and has magnitude g within 15 % (None without samples).
        False means a wrong frame configuration (Vicon or IMU axes) or a moving vehicle.
    gravity_angle_deg : angle between measured and predicted specific force [deg].
    acc_norm : |mean accelerometer| [m/s^2].
    gyro_bias, acc_bias : (3,) initial bias estimates [rad/s], [m/s^2].
    """

    t: float
    n_imu: int
    stationary: bool | None
    gravity_ok: bool | None
    gravity_angle_deg: float
    acc_norm: float
    gyro_bias: FloatArray
    acc_bias: FloatArray


@dataclass(frozen=True, slots=True)
class EkfHealth:
    """Filter health for the supervisor and telemetry.

    t : filter time (last IMU sample) [s]; initialised : initialise() done.
    time_since_fix : filter time minus the last accepted Vicon pose's time [s].
    covariance_trace : trace of the covariance in the 16-state layout.
    diverged : trace above ``divergence_trace``.
    last_nis : NIS of the last applied or gated update (NaN before one).
    updates, gated, repeated_poses, forced_resets (re-anchorings on poses the IMU could not
    explain: the estimate was wrong), too_old (also counts poses too
    far ahead of the IMU), invalid_poses, resets, late_poses (older than the
    filter time: fused by restoring a checkpoint and re-propagating),
    implausible_poses (outside the plausible volume), refused_resets (gated poses that
    could not count towards a reset: inconsistent with the one before or with the IMU
    prediction) : pose counters;
    repeated_imu, invalid_imu, stale_imu : IMU counters (stale = not newer than
    the filter time).
    """

    t: float
    initialised: bool
    time_since_fix: float
    covariance_trace: float
    diverged: bool
    last_nis: float
    updates: int
    gated: int
    repeated_poses: int
    forced_resets: int
    too_old: int
    invalid_poses: int
    resets: int
    late_poses: int
    repeated_imu: int
    invalid_imu: int
    stale_imu: int
    implausible_poses: int
    refused_resets: int
