"""One declaration per parameter.

The thesis's numbers are declared once, in the model package, and every default
elsewhere (the configuration, the EKF, the controllers' design model, the virtual
lab) is taken from there. Checked three ways: the declarations equal the thesis's
printed values (typed here as the independent answer); the source tree holds each of
those numbers in exactly one code definition (tokens, not comments); and the keys that
did nothing before (``safety.gravity_check_deg``, the IMU period) reach the estimator.
"""

from __future__ import annotations

import functools
import io
import math
import tokenize
from pathlib import Path

import pytest

from groundstation.config import GroundStationConfig, load_config, validate_config
from groundstation.errors import ConfigError
from groundstation.estimation.records import EkfParams
from groundstation.flight.assembly import assemble
from groundstation.flight.core import FlightCore
from groundstation.model.quadrotor import QuadrotorParams
from groundstation.model.sensors import (
    ACC_SATURATION_M_S2,
    ACC_VARIANCE_TABLE_6_3,
    GYRO_VARIANCE_TABLE_6_3,
    K_ACC_TABLE_6_2,
    K_GYRO_TABLE_6_2,
    VICON_POSITION_VARIANCE_TABLE_6_1,
    VICON_QUATERNION_VARIANCE_TABLE_6_1,
)
from groundstation.model.thrust import THRUST_POLY_EQ37
from sim_device.params import LabParams

ROOT = Path(__file__).resolve().parents[1]

THESIS = {
    # Table 6.1 (Vicon noise), Table 6.2 (scales), Table 6.3 (IMU noise), eq. 3.7, eq. C.8
    "VICON_POSITION_VARIANCE_TABLE_6_1": ((4.16e-7, 3.28e-9, 2.91e-7),
                                          VICON_POSITION_VARIANCE_TABLE_6_1),
    "VICON_QUATERNION_VARIANCE_TABLE_6_1": ((1.09e-9, 5.17e-6, 9.74e-6, 3.62e-6),
                                            VICON_QUATERNION_VARIANCE_TABLE_6_1),
    "K_GYRO_TABLE_6_2": ((0.0144, 0.0143, 0.0127), K_GYRO_TABLE_6_2),
    "K_ACC_TABLE_6_2": ((0.0086, 0.0077, 0.0111), K_ACC_TABLE_6_2),
    "GYRO_VARIANCE_TABLE_6_3": ((1.24e-4, 1.94e-4, 8.54e-4), GYRO_VARIANCE_TABLE_6_3),
    "ACC_VARIANCE_TABLE_6_3": ((4.60e-3, 2.62e-3, 3.54e-3), ACC_VARIANCE_TABLE_6_3),
    "THRUST_POLY_EQ37": ((2.073e-10, -1.143e-6, -1.054e-3, -0.903), THRUST_POLY_EQ37),
    "inflow (eq. C.8)": ((-0.423,), (QuadrotorParams().inflow,)),
    "g (eq. 3.8)": ((9.82,), (QuadrotorParams().g,)),
    "acc saturation (Ch. 6.2)": ((14.0,), (ACC_SATURATION_M_S2,)),
}


@pytest.mark.parametrize("name", sorted(THESIS))
def test_the_declarations_are_the_thesis_values(name: str) -> None:
    printed, declared = THESIS[name]
    assert declared == pytest.approx(printed, rel=0, abs=0)


def test_every_default_takes_the_one_declaration() -> None:
    cfg, quad, ekf = GroundStationConfig(), QuadrotorParams(), EkfParams()
    lab = LabParams.from_config(validate_config({"sim": {}}))
    default_lab = LabParams()
    v = cfg.vehicle
    assert (v.mass_kg, v.gravity, tuple(v.k_rate), v.induced_inflow, v.rate_loop_tau_s) == (
        quad.mass, quad.g, quad.k_rate, quad.inflow, quad.rate_tau)
    assert tuple(v.thrust_poly) == THRUST_POLY_EQ37 == quad.thrust_poly
    assert tuple(v.gyro_variance) == ekf.gyro_var == default_lab.imu.gyro_variance
    assert tuple(v.acc_variance) == ekf.acc_var == default_lab.imu.acc_variance
    assert tuple(v.vicon_position_variance) == ekf.vicon_position_var \
        == default_lab.vicon.position_variance
    assert tuple(v.vicon_quaternion_variance) == ekf.vicon_quaternion_var \
        == default_lab.vicon.quaternion_variance
    assert tuple(v.gyro_scale) == default_lab.imu.gyro_scale == K_GYRO_TABLE_6_2
    assert default_lab.plant.rate_tau == lab.plant.rate_tau == quad.rate_tau
    assert default_lab.plant.mass == lab.plant.mass == quad.mass
    assert cfg.safety.gravity_check_deg == ekf.gravity_check_deg


def _number_tokens(path: Path) -> list[tuple[str, int]]:
    """The numeric literals of a Python file as written, with their line (comments and
    strings skipped)."""
    tokens = tokenize.generate_tokens(io.StringIO(path.read_text(encoding="utf-8")).readline)
    return [(tok.string.replace("_", ""), tok.start[0]) for tok in tokens
            if tok.type == tokenize.NUMBER]


SOURCES = sorted(p for d in ("groundstation", "sim_device", "benchmarks")
                 for p in (ROOT / d).rglob("*.py"))


@functools.cache
def _decimal_tokens() -> tuple[tuple[float, str], ...]:
    """Every decimal literal of :data:`SOURCES` with where it is written ('file:line'),
    tokenized once for all the numbers checked."""
    return tuple((value, f"{path.relative_to(ROOT)}:{line}") for path in SOURCES
                 for token, line in _number_tokens(path)
                 if (value := _decimal(token)) is not None)

UNIQUE = [
    # Tables 6.1-6.3 and eq. 3.7 (their every entry is distinctive), and the model's
    # mass, rate gain, inflow and rate-loop time constant
    "4.16e-7", "3.28e-9", "2.91e-7", "1.09e-9", "5.17e-6", "9.74e-6", "3.62e-6",
    "0.0144", "0.0143", "0.0127", "0.0086", "0.0077", "0.0111",
    "1.24e-4", "1.94e-4", "8.54e-4", "4.60e-3", "2.62e-3", "3.54e-3",
    "2.073e-10", "1.143e-6", "1.054e-3", "0.903", "0.423", "9.82", "1.1e-3", "0.064",
]


@pytest.mark.parametrize("literal", UNIQUE)
def test_each_thesis_number_is_written_once(literal: str) -> None:
    value = float(literal)
    found = {where for number, where in _decimal_tokens()
             if math.isclose(number, value, rel_tol=1e-12)}
    assert len(found) == 1, f"{literal} written in {sorted(found)}"  # one definition


def _decimal(token: str) -> float | None:
    """A decimal literal's value; None for hex, octal, binary and imaginary literals."""
    try:
        return float(token)
    except ValueError:
        return None


def test_the_token_scan_ignores_comments_and_finds_numbers(tmp_path: Path) -> None:
    source = tmp_path / "m.py"
    source.write_text('x = 9.82  # 0.064\ny = "1.24e-4"\nz = 1_000\n')
    assert _number_tokens(source) == [("9.82", 1), ("1000", 3)]


@pytest.mark.slow
def test_the_gravity_check_key_reaches_the_estimator() -> None:
    base = load_config(ROOT / "config" / "sim.yaml")
    data = base.model_dump(mode="json")
    data["safety"]["gravity_check_deg"] = 4.0
    data["serial"]["data_period_ms"] = 5
    changed = validate_config(data)
    core = FlightCore(assemble(changed))
    assert core.ekf.params.gravity_check_deg == 4.0
    assert core.ekf.params.imu_period == 0.005
    default = FlightCore(assemble(base))
    assert default.ekf.params.gravity_check_deg == 10.0
    assert default.ekf.params.imu_period == base.serial.data_period_ms / 1000.0


def test_the_removed_key_is_refused_not_ignored() -> None:
    with pytest.raises(ConfigError, match=r"estimator\.ignore_variance"):
        validate_config({"estimator": {"ignore_variance": 1e8}})
