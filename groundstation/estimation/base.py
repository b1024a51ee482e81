"""The estimator role: a small protocol and a null estimator as its template.

An estimator is pure computation: the loop feeds it IMU samples and Vicon
poses (each stamped with its monotonic time) and reads a
:class:`~groundstation.types.StateEstimate`. It owns no clock and no thread.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import replace
from typing import Protocol, runtime_checkable

import numpy as np

from groundstation.estimation.records import EkfHealth, InitReport, UpdateResult
from groundstation.types import ImuSample, Pose, StateEstimate

__all__ = ["Estimator", "PoseHoldEstimator"]


@runtime_checkable
class Estimator(Protocol):
    """What the flight core (:class:`~groundstation.flight.core.FlightCore`) calls: initialise
    once, then update with poses and predict with IMU samples as they arrive; the core
    reads the estimate one IMU sample ahead of the filter (:meth:`estimate_ahead`), the
    failsafe figures (:attr:`diverged`, :attr:`time_since_fix`) every tick and
    :meth:`health` for telemetry. :class:`~groundstation.estimation.ekf.Ekf` is the one
    that flies; :class:`PoseHoldEstimator` is the smallest one that satisfies this."""

    def initialise(self, pose: Pose, imu_samples: Sequence[ImuSample] = ()) -> InitReport:
        """Start from a Vicon pose and IMU samples at rest; report what they showed
        (``gravity_ok`` gates take-off)."""
        ...

    def predict(self, imu: ImuSample) -> None:
        """Advance with one IMU sample."""
        ...

    def update(self, pose: Pose, *, still: bool = False) -> UpdateResult:
        """Fuse one Vicon pose; ``still``: the vehicle stands on the floor, so a pose
        repeated exactly is a measurement of a vehicle that does not move."""
        ...

    def estimate(self) -> StateEstimate:
        """The current estimate."""
        ...

    def estimate_ahead(self, imu: ImuSample) -> StateEstimate:
        """The estimate at ``imu.t``, predicted without moving the filter."""
        ...

    @property
    def diverged(self) -> bool:
        """True when the estimate can no longer be trusted (a failsafe lands)."""
        ...

    @property
    def time_since_fix(self) -> float:
        """Time since the last fused pose [s] (inf before :meth:`initialise`)."""
        ...

    @property
    def overruled(self) -> tuple[int, str]:
        """How often Vicon poses that agreed with each other but not with the estimate
        re-anchored it (the estimate was wrong: a failsafe), and a line on the last time."""
        ...

    def health(self) -> EkfHealth:
        """Counters and consistency figures for telemetry."""
        ...

    @property
    def verdicts(self) -> tuple[int, int, float]:
        """Poses judged against the estimate so far (fused or gated: those with a NIS),
        poses refused so far (for any reason), and the NIS of the last one judged (NaN
        before one): the cheap running counts the flight log records per tick."""
        ...


class PoseHoldEstimator:
    """The template estimator: reports the last Vicon pose as the state.

    Velocity and biases are zero, ``omega`` is the raw gyro and the covariance is
    unknown (NaN). It shows the minimum an estimator provides and feeds the loop's
    plumbing tests; it cannot fly a vehicle (no velocity), and it checks no gravity
    (``gravity_ok`` None), so the preflight refuses to take off with it.
    """

    def __init__(self) -> None:
        self._pose: Pose | None = None
        self._t = float("nan")
        self._omega = np.zeros(3)
        self._updates = 0

    def initialise(self, pose: Pose, imu_samples: Sequence[ImuSample] = ()) -> InitReport:
        """Take the pose; remember the last gyro sample."""
        self._pose = pose
        self._t = float(pose.t)
        if imu_samples:
            self.predict(imu_samples[-1])
        return InitReport(t=self._t, n_imu=len(imu_samples), stationary=None, gravity_ok=None,
                          gravity_angle_deg=math.nan, acc_norm=math.nan,
                          gyro_bias=np.zeros(3), acc_bias=np.zeros(3))

    def predict(self, imu: ImuSample) -> None:
        """Keep the latest gyro reading and time."""
        self._omega = np.array(imu.gyro, dtype=float)
        self._t = max(self._t, float(imu.t))

    def update(self, pose: Pose, *, still: bool = False) -> UpdateResult:
        """Replace the held pose (``still`` changes nothing here)."""
        self._pose = pose
        self._updates += 1
        return UpdateResult(True, float("nan"), "ok")

    @property
    def verdicts(self) -> tuple[int, int, float]:
        """No innovations: every pose is taken as it is."""
        return 0, 0, float("nan")

    def estimate(self) -> StateEstimate:
        """The held pose as an estimate (raises ``LookupError`` before a pose)."""
        if self._pose is None:
            raise LookupError("no pose yet: call initialise() first")
        return StateEstimate(
            t=self._t,
            position=self._pose.position.copy(),
            quaternion=self._pose.quaternion.copy(),
            velocity_body=np.zeros(3),
            omega=self._omega.copy(),
            gyro_bias=np.zeros(3),
            acc_bias=np.zeros(3),
            covariance_diag=np.full(16, np.nan),
        )

    def estimate_ahead(self, imu: ImuSample) -> StateEstimate:
        """The held pose at ``imu.t`` with this sample's gyro (nothing to predict)."""
        est = self.estimate()
        return replace(est, t=max(est.t, float(imu.t)), omega=np.array(imu.gyro, dtype=float))

    @property
    def diverged(self) -> bool:
        """Never: a held pose has no covariance to grow."""
        return False

    @property
    def overruled(self) -> tuple[int, str]:
        """Never: every pose is taken as it is."""
        return 0, ""

    @property
    def time_since_fix(self) -> float:
        """Time of the newest IMU sample minus the held pose's [s] (inf before a pose)."""
        return self._t - self._pose.t if self._pose is not None else math.inf

    def health(self) -> EkfHealth:
        """The pose counter; the figures a filter has are NaN."""
        return EkfHealth(
            t=self._t, initialised=self._pose is not None, time_since_fix=self.time_since_fix,
            covariance_trace=math.nan, diverged=False, last_nis=math.nan, updates=self._updates,
            gated=0, repeated_poses=0, forced_resets=0, too_old=0, invalid_poses=0, resets=0,
            late_poses=0, repeated_imu=0, invalid_imu=0, stale_imu=0, implausible_poses=0,
            refused_resets=0)
