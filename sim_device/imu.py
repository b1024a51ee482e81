"""The X-3D's on-board gyro, accelerometer and pressure sensor, as raw DATA counts.

Measurement model per axis (FRD body axes)::

    si_measured = clip((1 + e) * (truth + bias + noise), -saturation, +saturation)
    count       = clip(round(si_measured / K + zero), *count_range)

* ``truth``: body rates [rad/s] for the gyro; specific force [m/s^2] (non-
  gravitational force / m, about (0, 0, -9.82) at rest) for the accelerometer.
* ``K``, ``zero``: the nominal scaling of Table 6.2 and the configured zero
  offsets; the SI -> count step is :class:`groundstation.model.sensors.AxisScaling`,
  the same scaling the ground station inverts.
* ``e``: a constant per-axis scale error drawn once (seeded) in +/- ``scale_error``;
  ``bias``: constant; ``noise``: white Gaussian with the Table 6.3 variances.
* the accelerometer saturates physically near +/-14 m/s^2 (Ch. 6.2) before the
  ADC clips: ``count_range`` is the X-3D's 12 bits (0, 4095) or the AscTec LL
  dialect's int16 (-32768, 32767).

Noise is drawn in blocks (one generator call per 512 samples) to keep a sample cheap.
"""

from __future__ import annotations

import math

import numpy as np

from groundstation.model.quadrotor import QuadrotorParams
from groundstation.model.sensors import AxisScaling
from groundstation.types import FloatArray
from sim_device.params import ImuParams

SEA_LEVEL_PA = 101325.0
"""Pressure at the floor (z = 0) [Pa]."""
PRESSURE_GRADIENT_PA_PER_M = 1.2 * QuadrotorParams().g
"""Air density 1.2 kg/m^3 times g: pressure rises this much per metre of NED z [Pa/m]."""

_BLOCK = 512


class ImuModel:
    """Raw-count IMU with scale error, bias, white noise and saturation.

    params : sensor parameters; rng : the generator for this sensor (seeded by the lab).
    Attributes ``gyro_scale_true`` and ``acc_scale_true`` hold the drawn (1 + e) factors.
    """

    def __init__(self, params: ImuParams, rng: np.random.Generator) -> None:
        self.params = params
        self._rng = rng
        e = params.scale_error
        self.gyro_scale_true = tuple(float(x) for x in 1.0 + rng.uniform(-e, e, 3))
        self.acc_scale_true = tuple(float(x) for x in 1.0 + rng.uniform(-e, e, 3))
        self._gyro = AxisScaling(params.gyro_scale, params.gyro_zero, params.count_range)
        self._acc = AxisScaling(params.acc_scale, params.acc_zero, params.count_range)
        self._sigma = np.sqrt(np.array(params.gyro_variance + params.acc_variance, dtype=float))
        self._noise = np.empty((0, 6))
        self._next = 0
        self._gain = np.array(self.gyro_scale_true + self.acc_scale_true)
        self._bias = np.array(params.gyro_bias + params.acc_bias, dtype=float)
        gyro_sat = math.inf if params.gyro_saturation is None else params.gyro_saturation
        self._sat = np.array([gyro_sat] * 3 + [params.acc_saturation] * 3)

    def _noise_row(self) -> FloatArray:
        if self._next >= len(self._noise):
            self._noise = self._rng.standard_normal((_BLOCK, 6)) * self._sigma
            self._next = 0
        row: FloatArray = self._noise[self._next]
        self._next += 1
        return row

    def measure_si(self, omega: tuple[float, float, float],
                   specific_force: tuple[float, float, float]) -> FloatArray:
        """(6,) measured [gyro x, y, z (rad/s), acc x, y, z (m/s^2)] before the ADC."""
        truth = np.array(omega + specific_force)
        si: FloatArray = self._gain * (truth + self._bias + self._noise_row())
        np.maximum(si, -self._sat, out=si)  # np.clip's value, without its dispatch
        np.minimum(si, self._sat, out=si)
        return si

    def sample(
        self, omega: tuple[float, float, float], specific_force: tuple[float, float, float]
    ) -> tuple[tuple[int, int, int], tuple[int, int, int]]:
        """Raw (gyro, acc) counts for true body rates [rad/s] and specific force [m/s^2]."""
        si = self.measure_si(omega, specific_force)
        return self._gyro.to_counts_int(si[:3]), self._acc.to_counts_int(si[3:])

    def pressure(self, z: float) -> int:
        """Raw int32 pressure reading [Pa] at NED height ``z`` [m] (z < 0 above the floor)."""
        noise = self.params.pressure_noise * float(self._rng.standard_normal())
        return round(SEA_LEVEL_PA + PRESSURE_GRADIENT_PA_PER_M * z + noise)
