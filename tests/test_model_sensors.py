"""IMU count <-> SI scaling against Table 6.2 and the spec's worked DATA frame."""

from __future__ import annotations

import numpy as np
import pytest

from groundstation.model import AxisScaling, ImuScaling, scale_imu
from groundstation.model.sensors import K_ACC_TABLE_6_2, K_GYRO_TABLE_6_2


def test_worked_data_frame_from_spec() -> None:
    # spec/x3d-serial-protocol.md §5: gyro (2048, 2050, 2046), acc (2048, 2048, 1163), counter 1234
    s = scale_imu(12.5, np.array([2048, 2050, 2046]), np.array([2048, 2048, 1163]), 1234)
    assert s.t == 12.5 and s.counter == 1234
    np.testing.assert_allclose(s.gyro, [0.0, 2 * 0.0143, -2 * 0.0127])
    assert s.acc[2] == pytest.approx(-9.82, abs=0.0111)  # within one count of -g
    np.testing.assert_allclose(s.acc[:2], 0.0)


def test_roundtrip_within_half_a_count_and_clipping() -> None:
    sc = ImuScaling()
    rng = np.random.default_rng(3)
    for _ in range(200):
        w = rng.uniform(-20, 20, size=3)
        counts = sc.gyro.to_counts(w)
        assert np.all(counts == np.rint(counts))
        np.testing.assert_array_less(np.abs(sc.gyro.to_si(counts) - w),
                                     0.5 * np.array(K_GYRO_TABLE_6_2) + 1e-12)
    assert sc.acc.to_counts_int(np.array([0.0, 0.0, -9.82])) == (2048, 2048, 1163)
    # saturation: far beyond the ADC range clips to 0..4095
    np.testing.assert_array_equal(sc.acc.to_counts(np.array([100.0, -100.0, 0.0])), [4095, 0, 2048])
    np.testing.assert_allclose(sc.acc.to_si(np.array([2049, 2049, 2049])), K_ACC_TABLE_6_2)


def test_custom_zero_and_validation() -> None:
    ax = AxisScaling((0.01, 0.01, 0.01), zero=(2000.0, 2048.0, 2100.0))
    np.testing.assert_allclose(ax.to_si(np.array([2000, 2048, 2100])), 0.0)
    with pytest.raises(ValueError):
        AxisScaling((0.01, 0.0, 0.01))
    with pytest.raises(ValueError):
        AxisScaling((0.01, 0.01))  # type: ignore[arg-type]
