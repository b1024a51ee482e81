"""The estimator role: a small protocol and a null estimator as its template.

An estimator is pure computation: the loop feeds it IMU samples and Vicon
poses (each stamped with its monotonic time) and reads a
:class:`~groundstation.types.StateEstimate`. It owns no clock and no thread.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol, runtime_checkable

import numpy as np

from groundstation.estimation.records import UpdateResult
from groundstation.types import ImuSample, Pose, StateEstimate

__all__ = ["Estimator", "PoseHoldEstimator"]


@runtime_checkable
class Estimator(Protocol):
    """What the flight loop calls: initialise once, then predict/update as data arrive."""

    def initialise(self, pose: Pose, imu_samples: Sequence[ImuSample] = ()) -> object:
        """Start from a Vicon pose and IMU samples at rest; returns an init report."""
        ...

    def predict(self, imu: ImuSample) -> None:
        """Advance with one IMU sample."""
        ...

    def update(self, pose: Pose) -> UpdateResult:
        """Fuse one Vicon pose."""
        ...

    def estimate(self) -> StateEstimate:
        """The current estimate."""
        ...


class PoseHoldEstimator:
    """The template estimator: reports the last Vicon pose as the state.

    Velocity and biases are zero, ``omega`` is the raw gyro and the covariance is
    unknown (NaN). It shows the minimum an estimator provides and feeds the loop's
    plumbing tests; it cannot fly a vehicle (no velocity).
    """

    def __init__(self) -> None:
        self._pose: Pose | None = None
        self._t = float("nan")
        self._omega = np.zeros(3)

    def initialise(self, pose: Pose, imu_samples: Sequence[ImuSample] = ()) -> None:
        """Take the pose; remember the last gyro sample."""
        self._pose = pose
        self._t = float(pose.t)
        if imu_samples:
            self.predict(imu_samples[-1])

    def predict(self, imu: ImuSample) -> None:
        """Keep the latest gyro reading and time."""
        self._omega = np.array(imu.gyro, dtype=float)
        self._t = max(self._t, float(imu.t))

    def update(self, pose: Pose) -> UpdateResult:
        """Replace the held pose."""
        self._pose = pose
        return UpdateResult(True, float("nan"), "ok")

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
