"""`gs calibrate imu` and `gs calibrate vicon` against the virtual lab.

The virtual vehicle runs in its own process, in real time over a pty and UDP, with
planted values that differ from the defaults the ground station's configuration holds:
gyro and accelerometer biases (so the true zeros are off 2048), noise variances four
and nine times Table 6.3's, Vicon noise and rate, and a wrong ``vicon.body_to_object``
on the ground station's side. The commands must recover the planted truth (rate within
2 %; zeros and variances within what their sampling noise reaches with a chance of 1e-6,
:func:`noise_bound`) and refuse a moving vehicle.
"""

from __future__ import annotations

import json
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from groundstation.config import GroundStationConfig, apply_overrides, dump_config, load_config
from groundstation.endpoints import free_udp_port
from groundstation.model.sensors import (
    ACC_VARIANCE_TABLE_6_3,
    GYRO_VARIANCE_TABLE_6_3,
    VICON_POSITION_VARIANCE_TABLE_6_1,
    VICON_QUATERNION_VARIANCE_TABLE_6_1,
)
from sim_device.realtime import SimDeviceProcess

ROOT = Path(__file__).resolve().parents[1]
GYRO_BIAS = (0.05, -0.03, 0.02)  # rad/s
ACC_BIAS = (0.2, -0.1, 0.15)  # m/s^2
GYRO_VAR = tuple(4 * v for v in GYRO_VARIANCE_TABLE_6_3)
ACC_VAR = tuple(2 * v for v in ACC_VARIANCE_TABLE_6_3)
# (a larger accelerometer noise would need a longer measurement for a zero within 1 count:
# its standard error is sigma / sqrt(n) counts, about 0.3 counts here)
VICON_POS_VAR = tuple(25 * v for v in VICON_POSITION_VARIANCE_TABLE_6_1)
VICON_Q_VAR = tuple(16 * v for v in VICON_QUATERNION_VARIANCE_TABLE_6_1)
VICON_RATE = 80.0
FALSE_ALARM = 1e-6
"""Chance that the sampling noise alone fails one of a test's comparisons of an estimate
with the planted truth (the lab's noise starts wherever the measurement starts)."""


def noise_bound(comparisons: int) -> float:
    """Standard deviations that a normal estimate's error exceeds with probability at most
    :data:`FALSE_ALARM` in any of ``comparisons`` two-sided comparisons (Bonferroni)."""
    from scipy.stats import norm

    return float(norm.isf(FALSE_ALARM / (2 * comparisons)))


def gs(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "groundstation", *args], capture_output=True,
                          text=True, timeout=90, cwd=ROOT)


IMU_PLANTED: dict[str, object] = {
    "sim.gyro_bias": list(GYRO_BIAS), "sim.acc_bias": list(ACC_BIAS), "sim.scale_error": 0.0,
    "sim.seed": 11,
    "vehicle.gyro_variance": list(GYRO_VAR), "vehicle.acc_variance": list(ACC_VAR)}
VICON_PLANTED: dict[str, object] = {
    "vehicle.vicon_position_variance": list(VICON_POS_VAR),
    "vehicle.vicon_quaternion_variance": list(VICON_Q_VAR), "sim.vicon.rate_hz": VICON_RATE}


def planted_lab(ground: GroundStationConfig, extra: dict[str, object]) -> GroundStationConfig:
    """The virtual vehicle's configuration: the ground station's plus the planted values."""
    return apply_overrides(ground, {**IMU_PLANTED, **extra})


@pytest.fixture(scope="module")
def lab(request: pytest.FixtureRequest,
        tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[Path, GroundStationConfig]]:
    """(the ground station's configuration file, the lab's configuration), lab running,
    one per parameter for the tests that ask for it, each measuring in turn. The IMU's
    planted values always; Vicon's for the Vicon test (its 16-fold attitude noise would
    blur the attitude the accelerometer's zero is fitted to)."""
    tmp_path = tmp_path_factory.mktemp(f"lab-{request.param}")
    ground = apply_overrides(load_config(ROOT / "config" / "sim.yaml"),
                             {"vicon.port": free_udp_port()})
    lab_cfg = planted_lab(ground, VICON_PLANTED if request.param == "vicon" else {})
    lab_file = tmp_path / "lab.yaml"
    lab_file.write_text(dump_config(lab_cfg), encoding="utf-8")
    with SimDeviceProcess(lab_file, tmp_path / "truth.npz") as device:
        ground_file = tmp_path / "ground.yaml"
        ground_file.write_text(dump_config(apply_overrides(
            ground, {"serial.port": device.pty_path})), encoding="utf-8")
        yield ground_file, lab_cfg


@pytest.mark.virtual_vehicle
@pytest.mark.slow
@pytest.mark.parametrize("lab", ["imu"], indirect=True)
def test_calibrate_imu_recovers_the_planted_zeros_and_noise(
        lab: tuple[Path, GroundStationConfig], tmp_path: Path) -> None:
    ground_file, lab_cfg = lab
    out = gs("calibrate", "imu", "--config", str(ground_file), "--json",  # 10 s, the default
             "--out", str(tmp_path))
    assert out.returncode == 0, out.stdout + out.stderr
    got = json.loads(out.stdout)
    k_gyro = np.asarray(lab_cfg.vehicle.gyro_scale)
    k_acc = np.asarray(lab_cfg.vehicle.acc_scale)
    # counts = zero + (truth + bias) / K: at rest the gyro truth is 0 and the
    # accelerometer's is the specific force of rest, which the fit takes out. A zero is a
    # mean of n samples: its standard error is the noise in counts (plus the rounding to
    # whole counts, 1/12 count^2) over sqrt(n), 0.05-0.35 counts here; a variance's relative
    # standard error is sqrt(2 / (n - 1)), 4.5 % at n = 1000 (12 comparisons in all).
    n = got["samples"]
    assert n > 900  # 10 s of 100 Hz DATA
    z = noise_bound(12)
    for key, var, bias, k in (("gyro", GYRO_VAR, GYRO_BIAS, k_gyro),
                              ("acc", ACC_VAR, ACC_BIAS, k_acc)):
        se = np.sqrt((np.asarray(var) / k**2 + 1 / 12) / n)  # [counts]
        error = np.asarray(got[f"vehicle.{key}_zero"]) - (2048 + np.asarray(bias) / k)
        assert np.all(np.abs(error) <= z * se), (key, error, z * se)
        np.testing.assert_allclose(got[f"vehicle.{key}_variance"], var,
                                   rtol=z * np.sqrt(2 / (n - 1)))
    assert (tmp_path / "calibrate-imu.png").stat().st_size > 10_000


@pytest.mark.virtual_vehicle
@pytest.mark.slow
@pytest.mark.parametrize("lab", ["imu"], indirect=True)
def test_calibrate_imu_prints_what_to_paste(lab: tuple[Path, GroundStationConfig],
                                            tmp_path: Path) -> None:
    ground_file, _ = lab
    human = gs("calibrate", "imu", "--config", str(ground_file), "--seconds", "2",
               "--out", str(tmp_path))
    assert human.returncode == 0, human.stdout + human.stderr
    assert "paste into the configuration" in human.stdout and "gyro_zero:" in human.stdout
    assert (tmp_path / "calibrate-imu.png").stat().st_size > 10_000


@pytest.mark.virtual_vehicle
@pytest.mark.slow
@pytest.mark.parametrize("lab", ["vicon"], indirect=True)
def test_calibrate_vicon_recovers_the_noise_and_finds_a_wrong_frame(
        lab: tuple[Path, GroundStationConfig], tmp_path: Path) -> None:
    ground_file, _ = lab
    out = gs("calibrate", "vicon", "--config", str(ground_file), "--seconds", "10", "--json",
             "--out", str(tmp_path))
    assert out.returncode == 0, out.stdout + out.stderr
    got = json.loads(out.stdout)
    # a variance of n poses has a relative standard error of sqrt(2 / (n - 1)): 5 % for
    # 10 s at 80 Hz (6 comparisons)
    rtol = noise_bound(6) * np.sqrt(2 / (10 * VICON_RATE - 1))
    np.testing.assert_allclose(got["vehicle.vicon_position_variance"], VICON_POS_VAR, rtol=rtol)
    # q1..q3 carry the attitude noise; q0 = cos(angle / 2) is second order near identity
    np.testing.assert_allclose(got["vehicle.vicon_quaternion_variance"][1:], VICON_Q_VAR[1:],
                               rtol=rtol)
    assert got["vicon.expected_rate_hz"] == pytest.approx(VICON_RATE, rel=0.02)
    # a datagram may be lost on a loaded machine (UDP), a handful of 800 at most
    assert got["frames_dropped"] <= 8 and got["frames_ok"]
    # the same lab seen through a wrong body_to_object (identity instead of 180 deg about x)
    wrong = tmp_path / "wrong.yaml"
    wrong.write_text(dump_config(apply_overrides(load_config(ground_file), {
        "vicon.body_to_object.euler_xyz_deg": [0.0, 0.0, 0.0]})), encoding="utf-8")
    bad = gs("calibrate", "vicon", "--config", str(wrong), "--seconds", "2", "--json",
             "--out", str(tmp_path))
    assert bad.returncode == 0, bad.stderr
    check = json.loads(bad.stdout)
    assert not check["frames_ok"] and check["attitude_error_deg"] == pytest.approx(180, abs=2)
    suggested = check["vicon.body_to_object"]["euler_xyz_deg"]
    from scipy.spatial.transform import Rotation

    assert Rotation.from_euler("XYZ", suggested, degrees=True).as_matrix() == pytest.approx(
        Rotation.from_euler("XYZ", [180, 0, 0], degrees=True).as_matrix(), abs=0.03)


@pytest.mark.virtual_vehicle
@pytest.mark.slow
@pytest.mark.parametrize(("lab_overrides", "what"), [
    # The pilot lifts it off slowly: 1.6-4 cm/s for half a minute (the battery droops),
    # inside the tracked volume however late the measurement starts on a loaded machine
    # (at stick 2050 it climbed out of the volume in 6 s, and a late start saw no Vicon).
    ({"sim.pilot_thrust": 1996}, "Vicon position drifted"),
    # An accelerometer half a g from gravity: what a vehicle accelerating throughout the
    # measurement reads. (A vehicle that falls or climbs does not: within seconds drag
    # holds it at a steady speed, and then its accelerometer reads g as at rest.)
    ({"sim.acc_bias": [0.0, 0.0, 5.0]}, "accelerometer reads"),
])
def test_a_moving_vehicle_is_refused(tmp_path: Path, lab_overrides: dict[str, object],
                                     what: str) -> None:
    ground = apply_overrides(load_config(ROOT / "config" / "sim.yaml"),
                             {"vicon.port": free_udp_port()})
    lab_cfg = planted_lab(ground, lab_overrides)
    lab_file = tmp_path / "lab.yaml"
    lab_file.write_text(dump_config(lab_cfg), encoding="utf-8")
    with SimDeviceProcess(lab_file, tmp_path / "truth.npz") as device:
        ground_file = tmp_path / "ground.yaml"
        ground_file.write_text(dump_config(apply_overrides(
            ground, {"serial.port": device.pty_path})), encoding="utf-8")
        out = gs("calibrate", "imu", "--config", str(ground_file), "--seconds", "1.5")
    assert out.returncode == 1, out.stdout
    assert "not at rest" in out.stderr or "moved during the measurement" in out.stderr
    assert what in out.stderr


@pytest.mark.slow
def test_no_vehicle_is_a_clear_error(tmp_path: Path) -> None:
    out = gs("calibrate", "imu", "--config", str(ROOT / "config" / "sim.yaml"),
             "--serial-port", str(tmp_path / "no-such-port"), "--seconds", "1")
    assert out.returncode == 1 and "no-such-port" in out.stderr and "Traceback" not in out.stderr


def _vicon_at_rest(rng: np.random.Generator, n: int, turn_deg: float = 0.0) -> np.ndarray:
    """(n, 4) scalar-first quaternions as the virtual Vicon makes them at 16 times Table
    6.1's variance (independent noise on q0..q3 of the level vehicle, normalised), turning
    about z by ``turn_deg`` in all, then seen through a body_to_object 180 deg off about x
    (the wrong frame of the test above, where the attitude sits near 180 deg of roll)."""
    from scipy.spatial.transform import Rotation

    q = np.array([1.0, 0.0, 0.0, 0.0]) + np.sqrt(VICON_Q_VAR) * rng.standard_normal((n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    turn = Rotation.from_euler("z", np.linspace(0.0, turn_deg, n)[:, None], degrees=True)
    seen = turn * Rotation.from_quat(np.roll(q, -1, axis=1)) * Rotation.from_euler(
        "x", 180.0, degrees=True)
    return np.roll(seen.as_quat(), 1, axis=1)


@pytest.mark.slow
def test_the_stillness_check_tells_noise_from_motion() -> None:
    """2 s at 80 Hz of a noisy Vicon at rest: the window means scatter by 0.15 to 0.25 deg
    per axis, so a fixed 1 deg limit refused about one such measurement in 25 (counted here
    with the fixed limit, computed independently); the limit that grows with the measured
    noise (false-alarm rate 1e-6) refuses none of 400, yet refuses a 6 deg turn, a 10 mm
    drift and a turning gyro under the same noise."""
    from scipy.spatial.transform import Rotation

    from groundstation.calibration import CalibrationError, _check_still

    rng = np.random.default_rng(20240611)  # a fixed seed: the draw is not the point
    fixed_limit_refusals = 0
    for _ in range(400):
        q = _vicon_at_rest(rng, 160)
        _check_still(None, q, None)  # never raises at rest
        windows = [Rotation.from_quat(np.roll(w, -1, axis=1)).mean()
                   for w in np.array_split(q * np.sign(q @ q[0])[:, None], 5)]
        worst = max(np.degrees((w * windows[0].inv()).magnitude()) for w in windows)
        fixed_limit_refusals += bool(worst > 1.0)
    assert 4 <= fixed_limit_refusals <= 40  # about 4 % of 400: the defect this replaces
    with pytest.raises(CalibrationError, match="attitude changed by"):
        _check_still(None, _vicon_at_rest(rng, 160, turn_deg=6.0), None)
    drift = np.linspace(0.0, 0.01, 160)[:, None] * np.array([1.0, 0.0, 0.0])
    noise = np.sqrt(VICON_POS_VAR) * rng.standard_normal((160, 3))
    _check_still(noise, None, None)
    with pytest.raises(CalibrationError, match="position drifted"):
        _check_still(noise + drift, None, None)
    gyro_noise = np.sqrt(GYRO_VAR) * rng.standard_normal((200, 3))
    _check_still(None, None, gyro_noise)
    with pytest.raises(CalibrationError, match="gyro's mean changed"):
        _check_still(None, None, gyro_noise + np.linspace(0.0, 0.3, 200)[:, None])
