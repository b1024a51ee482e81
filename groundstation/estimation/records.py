"""Parameters and result records of the IMU-driven EKF (thesis Ch. 6-7).

:class:`EkfParams` maps one to one onto the ``vehicle`` (sensor variances) and
``estimator`` sections of the configuration; see :meth:`EkfParams.from_config`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Literal

import numpy as np

from groundstation.types import FloatArray

if TYPE_CHECKING:  # pragma: no cover - import only for the type checker
    from groundstation.config import EstimatorConfig, VehicleConfig

__all__ = ["EkfHealth", "EkfParams", "InitReport", "UpdateReason", "UpdateResult"]

Vec3 = tuple[float, float, float]

UpdateReason = Literal[
    "ok",  # applied at its time stamp
    "reset",  # applied as a re-initialisation after persistent gating
    "deferred",  # newer than the last IMU sample: queued, applied when the IMU reaches it
    "gated",  # chi-square gate rejected the innovation (outlier)
    "repeated",  # Algorithm 1: same frame number or identical values as the previous pose
    "lost_tracking",  # Algorithm 2: identity quaternion = Vicon lost the object
    "too_old",  # older than the re-propagation window
    "future",  # further ahead of the IMU than the window (clock problem)
    "invalid",  # non-finite values or a quaternion far from unit norm
    "not_initialised",  # initialise() has not been called
]


def _default_p0() -> tuple[float, ...]:
    return (1e-4,) * 3 + (1e-4,) * 4 + (1e-2,) * 3 + (1e-3,) * 3 + (1e-1,) * 3


@dataclass(frozen=True, slots=True)
class EkfParams:
    """EKF tuning. Units in brackets; defaults name their source.

    g : gravity [m/s^2] (eq. 3.8).
    gyro_var, acc_var : per-sample IMU noise variances at ``imu_period``
        [(rad/s)^2], [(m/s^2)^2] (Table 6.3). The continuous noise density is
        ``var * imu_period``.
    imu_period : IMU sample period the variances refer to [s] (100 Hz, Ch. 7.2).
    gyro_bias_walk, acc_bias_walk : bias random-walk densities [(rad/s)^2/s],
        [(m/s^2)^2/s] (tuned; the thesis tuned Q by hand).
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
    gate_reset_after : after this long [s] without an accepted fix and at
        least ``gate_reset_count`` consecutive gated poses, the next pose
        re-initialises position and attitude and resets the velocity variance (one
        bad estimate cannot lock the gate). 0.2 s and 3 poses: an isolated outlier
        is still rejected, but a touchdown that left the velocity wrong is corrected
        within 0.2 s at 100 Hz Vicon and 0.3 s at 10 Hz.
    divergence_trace : covariance trace [16-layout units] that flags divergence in health.
    max_step : longest single integration step [s]; longer IMU gaps are sub-stepped.
    imu_repeat_on_identical : Algorithm 1 also for identical values with a new counter.
    init_biases_from_imu : estimate initial biases from stationary IMU samples.
    stationary_gyro_std : per-axis gyro std [rad/s] below which samples count as at rest.
    gravity_tolerance_deg : largest angle between measured and Vicon-predicted gravity.
    """

    g: float = 9.82
    gyro_var: Vec3 = (1.24e-4, 1.94e-4, 8.54e-4)
    acc_var: Vec3 = (4.60e-3, 2.62e-3, 3.54e-3)
    imu_period: float = 0.01
    gyro_bias_walk: float = 1e-6
    acc_bias_walk: float = 1e-4
    process_noise_scale: float = 1.0
    vicon_position_var: Vec3 = (4.16e-7, 3.28e-9, 2.91e-7)
    vicon_quaternion_var: tuple[float, float, float, float] = (1.09e-9, 5.17e-6, 9.74e-6, 3.62e-6)
    min_measurement_var: float = 1e-9
    initial_variance: tuple[float, ...] = field(default_factory=_default_p0)
    gate_probability: float = 0.9999
    max_vicon_delay: float = 0.2
    gate_reset_after: float = 0.2
    gate_reset_count: int = 3
    divergence_trace: float = 10.0
    max_step: float = 0.025
    imu_repeat_on_identical: bool = True
    init_biases_from_imu: bool = True
    stationary_gyro_std: float = 0.1
    gravity_tolerance_deg: float = 10.0

    def __post_init__(self) -> None:
        """Validate once: shapes, positivity, probability range."""
        for name in ("gyro_var", "acc_var", "vicon_position_var"):
            _check_positive(name, getattr(self, name), 3)
        _check_positive("vicon_quaternion_var", self.vicon_quaternion_var, 4)
        _check_positive("initial_variance", self.initial_variance, 16)
        for name in ("g", "imu_period", "gyro_bias_walk", "acc_bias_walk", "process_noise_scale",
                     "min_measurement_var", "max_vicon_delay", "gate_reset_after",
                     "divergence_trace", "max_step", "stationary_gyro_std",
                     "gravity_tolerance_deg"):  # fmt: skip
            _check_positive(name, (getattr(self, name),), 1)
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

    @classmethod
    def from_config(cls, vehicle: VehicleConfig, estimator: EstimatorConfig) -> EkfParams:
        """Build from the ``vehicle`` and ``estimator`` configuration sections.

        ``estimator.r_override`` (7x7 or diagonal 7 over ``[P, q0..q3]``) replaces
        Table 6.1; only its diagonal is used (``q0`` dropped, see above).
        """
        pos_var = tuple(vehicle.vicon_position_variance)
        q_var = tuple(vehicle.vicon_quaternion_variance)
        if estimator.r_override is not None:
            r = np.asarray(estimator.r_override, dtype=float)
            d = np.diag(r) if r.ndim == 2 else r
            pos_var, q_var = tuple(d[0:3]), tuple(d[3:7])
        p0 = np.asarray(estimator.initial_covariance, dtype=float)
        p0d = np.diag(p0) if p0.ndim == 2 else p0
        return cls(
            g=vehicle.gravity,
            gyro_var=_vec3(vehicle.gyro_variance),
            acc_var=_vec3(vehicle.acc_variance),
            gyro_bias_walk=estimator.gyro_bias_walk,
            acc_bias_walk=estimator.acc_bias_walk,
            process_noise_scale=estimator.process_noise_scale,
            vicon_position_var=_vec3(pos_var),
            vicon_quaternion_var=(
                float(q_var[0]), float(q_var[1]), float(q_var[2]), float(q_var[3])
            ),
            initial_variance=tuple(float(v) for v in p0d),
            gate_probability=estimator.gate_probability,
            max_vicon_delay=estimator.max_vicon_delay_s,
            divergence_trace=estimator.divergence_trace,
        )


def _vec3(v: object) -> Vec3:
    a = [float(x) for x in v]  # type: ignore[attr-defined]  # any iterable of 3 numbers
    return (a[0], a[1], a[2])


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
    updates, gated, repeated_poses, lost_tracking, too_old (also counts poses too
    far ahead of the IMU), invalid_poses, resets, late_poses (older than the
    filter time: fused by restoring a checkpoint and re-propagating) : pose counters;
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
    lost_tracking: int
    too_old: int
    invalid_poses: int
    resets: int
    late_poses: int
    repeated_imu: int
    invalid_imu: int
    stale_imu: int
