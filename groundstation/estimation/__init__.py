"""State estimation: the IMU-driven EKF of thesis Ch. 7 with fault handling.

Pure numpy/scipy: no I/O, no clock, no threads; the loop passes time and data.
"""

from typing import TYPE_CHECKING

from groundstation.lazy import reexports

if TYPE_CHECKING:  # the names, imported from their modules on first use (groundstation.lazy)
    from groundstation.estimation.base import Estimator, PoseHoldEstimator
    from groundstation.estimation.ekf import Ekf
    from groundstation.estimation.init import gravity_check
    from groundstation.estimation.records import (
        EkfHealth,
        EkfParams,
        InitReport,
        UpdateReason,
        UpdateResult,
    )

__all__ = [
    "Ekf",
    "EkfHealth",
    "EkfParams",
    "Estimator",
    "InitReport",
    "PoseHoldEstimator",
    "UpdateReason",
    "UpdateResult",
    "gravity_check",
]

if not TYPE_CHECKING:
    __getattr__ = reexports(__name__)
