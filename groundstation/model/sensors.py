"""IMU sensor scaling: raw 12-bit ADC counts <-> SI (thesis Table 6.2, spec §3.3).

``SI = K * (count - zero)`` per axis, counts 0..4095, zero 2048 by default
(``docs/protocol.md``: the thesis's 0..1023 range cannot hold hover
gravity at these scales). Body axes FRD; the accelerometer reads specific
force, about (0, 0, -9.82) m/s^2 at rest (z count ~1163).

K_gyro = (0.0144, 0.0143, 0.0127) rad/s per count,
K_acc  = (0.0086, 0.0077, 0.0111) m/s^2 per count (Table 6.2).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from groundstation.types import FloatArray, ImuSample

__all__ = [
    "ADC_MAX",
    "K_ACC_TABLE_6_2",
    "K_GYRO_TABLE_6_2",
    "AxisScaling",
    "ImuScaling",
    "scale_imu",
]

ADC_MAX = 4095
"""Largest raw count of the 12-bit ADC."""

K_GYRO_TABLE_6_2: tuple[float, float, float] = (0.0144, 0.0143, 0.0127)
"""Gyro scale per axis [rad/s per count] (Table 6.2)."""

K_ACC_TABLE_6_2: tuple[float, float, float] = (0.0086, 0.0077, 0.0111)
"""Accelerometer scale per axis [m/s^2 per count] (Table 6.2)."""

GYRO_VARIANCE_TABLE_6_3: tuple[float, float, float] = (1.24e-4, 1.94e-4, 8.54e-4)
"""Gyro white-noise variance per sample at 100 Hz, per axis [(rad/s)^2] (Table 6.3)."""

ACC_VARIANCE_TABLE_6_3: tuple[float, float, float] = (4.60e-3, 2.62e-3, 3.54e-3)
"""Accelerometer white-noise variance per sample at 100 Hz, per axis [(m/s^2)^2]
(Table 6.3)."""

VICON_POSITION_VARIANCE_TABLE_6_1: tuple[float, float, float] = (4.16e-7, 3.28e-9, 2.91e-7)
"""Vicon position noise variance, x y z [m^2] (Table 6.1)."""

VICON_QUATERNION_VARIANCE_TABLE_6_1: tuple[float, float, float, float] = (
    1.09e-9, 5.17e-6, 9.74e-6, 3.62e-6)
"""Vicon attitude noise variance of q0..q3 [-] (Table 6.1)."""

ACC_SATURATION_M_S2 = 14.0
"""The accelerometer saturates near this specific force [m/s^2] (Ch. 6.2)."""

INITIAL_STATE_VARIANCE: tuple[float, ...] = (
    (1e-4,) * 3 + (1e-4,) * 4 + (1e-2,) * 3 + (1e-3,) * 3 + (1e-1,) * 3)
"""How far the state may be off when the estimator starts, as variances of the 16 states
``[P (3), q (4), v (3), gyro bias (3), acc bias (3)]``: position and attitude from a
Vicon pose (1 cm, 0.01) and the vehicle at rest (0.1 m/s), the gyro's and the
accelerometer's bias spread (0.03 rad/s, 0.3 m/s^2). Loose enough for the biases to
settle in about 3 s (Ch. 7.4)."""

GRAVITY_CHECK_DEG = 10.0
"""Largest angle between the gravity the accelerometer measures at rest and the one the
Vicon attitude predicts [deg]: a wrong frame configuration (Vicon or IMU axes) or a
moving vehicle, not the 0.3 m/s^2 bias spread above (2 deg) or a mounting tilt."""


@dataclass(frozen=True, slots=True)
class AxisScaling:
    """Linear scaling of one three-axis sensor: ``SI = scale * (count - zero)``.

    scale : (3,) SI units per count (x, y, z body axes); zero : (3,) count at 0 SI.
    """

    scale: tuple[float, float, float]
    zero: tuple[float, float, float] = (2048.0, 2048.0, 2048.0)
    count_range: tuple[int, int] = (0, ADC_MAX)
    """The ADC's output range [counts]: the X-3D's 12 bits, or the AscTec LL dialect's
    int16 (-32768, 32767); only :meth:`to_counts` uses it (a vehicle model's saturation)."""
    _k: FloatArray = field(init=False, repr=False, compare=False)
    _z: FloatArray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        """Validate once and cache the arrays used per sample."""
        k = np.asarray(self.scale, dtype=float)
        z = np.asarray(self.zero, dtype=float)
        if k.shape != (3,) or z.shape != (3,):
            raise ValueError(f"scale and zero must have 3 entries, got {self.scale}, {self.zero}")
        if not (np.all(np.isfinite(k)) and np.all(k != 0.0) and np.all(np.isfinite(z))):
            raise ValueError(f"scale must be finite and non-zero, zero finite: {self!r}")
        object.__setattr__(self, "_k", k)
        object.__setattr__(self, "_z", z)

    def to_si(self, counts: FloatArray) -> FloatArray:
        """(3,) counts -> (3,) SI values."""
        return self._k * (np.asarray(counts, dtype=float) - self._z)

    def to_counts(self, si: FloatArray) -> FloatArray:
        """(3,) SI values -> (3,) integer counts (as floats), rounded and clipped to
        :attr:`count_range`.

        Clipping models ADC saturation; use :meth:`to_counts_int` for wire values.
        """
        raw = np.rint(np.asarray(si, dtype=float) / self._k + self._z)
        lo, hi = self.count_range
        # np.clip's value, without its Python-level dispatch (called for every IMU sample)
        return np.minimum(np.maximum(raw, float(lo)), float(hi))

    def to_counts_int(self, si: FloatArray) -> tuple[int, int, int]:
        """Like :meth:`to_counts` but as a tuple of Python ints (for packing)."""
        c = self.to_counts(si)
        return int(c[0]), int(c[1]), int(c[2])


@dataclass(frozen=True, slots=True)
class ImuScaling:
    """Gyro and accelerometer scalings of the X-3D (defaults: Table 6.2, zero 2048)."""

    gyro: AxisScaling = field(default_factory=lambda: AxisScaling(K_GYRO_TABLE_6_2))
    acc: AxisScaling = field(default_factory=lambda: AxisScaling(K_ACC_TABLE_6_2))

    def scale(
        self, t: float, gyro_counts: FloatArray, acc_counts: FloatArray, counter: int = 0
    ) -> ImuSample:
        """Raw counts -> :class:`ImuSample` (gyro [rad/s], acc [m/s^2], FRD)."""
        return ImuSample(t, self.gyro.to_si(gyro_counts), self.acc.to_si(acc_counts), counter)


_DEFAULT = ImuScaling()


def scale_imu(
    t: float,
    gyro_counts: FloatArray,
    acc_counts: FloatArray,
    counter: int = 0,
    scaling: ImuScaling | None = None,
) -> ImuSample:
    """Scale one DATA sample's raw counts to an :class:`ImuSample`.

    t : receive time [s]; gyro_counts, acc_counts : (3,) raw counts (x, y, z);
    counter : DATA sample counter; scaling : default Table 6.2 with zero 2048.
    """
    return (scaling or _DEFAULT).scale(t, gyro_counts, acc_counts, counter)
