"""Fixed-size ring buffer of EKF checkpoints for re-propagating late Vicon poses.

One checkpoint per IMU sample: the time, the 16-state, the 15x15 error
covariance after everything up to that time was fused, and the IMU input at
that time. Storage is allocated once; ``push`` copies into it.
"""

from __future__ import annotations

import math

import numpy as np

from groundstation.types import FloatArray

__all__ = ["History"]


class History:
    """Ring buffer of ``capacity`` checkpoints, addressed by logical index 0 = oldest."""

    def __init__(self, capacity: int, n_state: int = 16, n_err: int = 15) -> None:
        if capacity < 2:
            raise ValueError(f"capacity must be >= 2, got {capacity}")
        self._cap = capacity
        self._t = np.full(capacity, math.nan)
        self._x = np.empty((capacity, n_state))
        self._P = np.empty((capacity, n_err, n_err))
        self._g = np.empty((capacity, 3))
        self._a = np.empty((capacity, 3))
        self._start = 0
        self._n = 0

    def __len__(self) -> int:
        return self._n

    def clear(self) -> None:
        """Forget every checkpoint."""
        self._start = 0
        self._n = 0

    def _phys(self, j: int) -> int:
        return (self._start + j) % self._cap

    def push(
        self, t: float, x: FloatArray, P: FloatArray, gyro: FloatArray, acc: FloatArray
    ) -> None:
        """Append a checkpoint, dropping the oldest when full."""
        if self._n < self._cap:
            i = self._phys(self._n)
            self._n += 1
        else:
            i = self._start
            self._start = (self._start + 1) % self._cap
        self._t[i] = t
        self._x[i] = x
        self._P[i] = P
        self._g[i] = gyro
        self._a[i] = acc

    def overwrite(self, j: int, x: FloatArray, P: FloatArray) -> None:
        """Replace the state and covariance of checkpoint ``j``."""
        i = self._phys(j)
        self._x[i] = x
        self._P[i] = P

    def overwrite_last(self, x: FloatArray, P: FloatArray) -> None:
        """Replace the state and covariance of the newest checkpoint."""
        self.overwrite(self._n - 1, x, P)

    def overwrite_input_last(self, gyro: FloatArray, acc: FloatArray) -> None:
        """Replace the IMU input stored with the newest checkpoint."""
        i = self._phys(self._n - 1)
        self._g[i] = gyro
        self._a[i] = acc

    def oldest_time(self) -> float:
        """Time of the oldest checkpoint [s] (``inf`` when empty)."""
        return float(self._t[self._start]) if self._n else math.inf

    def time(self, j: int) -> float:
        """Time of checkpoint ``j`` [s]."""
        return float(self._t[self._phys(j)])

    def gyro(self, j: int) -> FloatArray:
        """IMU gyro input (3,) stored with checkpoint ``j`` (a view)."""
        out: FloatArray = self._g[self._phys(j)]
        return out

    def acc(self, j: int) -> FloatArray:
        """IMU accelerometer input (3,) stored with checkpoint ``j`` (a view)."""
        out: FloatArray = self._a[self._phys(j)]
        return out

    def restore_before(
        self, t: float, x: FloatArray, P: FloatArray, gyro: FloatArray, acc: FloatArray
    ) -> int:
        """Copy the newest checkpoint with time <= ``t`` into the given arrays; return its index.

        Raises ``LookupError`` if every checkpoint is newer than ``t``.
        """
        for j in range(self._n - 1, -1, -1):
            i = self._phys(j)
            if self._t[i] <= t:
                x[:] = self._x[i]
                P[:] = self._P[i]
                gyro[:] = self._g[i]
                acc[:] = self._a[i]
                return j
        raise LookupError(f"no checkpoint at or before t={t}")

    def indices_after(self, j: int) -> range:
        """Logical indices of the checkpoints newer than ``j``."""
        return range(j + 1, self._n)
