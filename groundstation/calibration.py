"""A vehicle's first day: ``gs calibrate imu`` and ``gs calibrate vicon``.

Both measure with the vehicle at rest on the floor, through the same link and Vicon
client a flight uses (either serial dialect; nothing is commanded: the link never sends
a command, so the vehicle stays the pilot's), and report in the configuration's own
field names, so the result pastes into the YAML:

* :func:`calibrate_imu`: gyro and accelerometer zeros [counts] and noise variances
  (thesis Table 6.3, [(rad/s)^2], [(m/s^2)^2]). The gyro reads zero rate at rest; the
  accelerometer reads the specific force of rest, ``R(q)^T (0, 0, -g)`` in the body
  frame, with ``q`` the Vicon attitude when Vicon is up (else level). The variances use
  the configured scales. Refused if the vehicle moves (Vicon or the gyro says so).
* :func:`calibrate_vicon`: position and quaternion noise variances (Table 6.1, [m^2],
  [1]), the stream's rate [Hz], its interval jitter [ms] and dropped frames, and a frame
  check: placed level with its nose along the lab's +x, the vehicle's attitude in NED
  must be the identity; if it is not, the ``vicon.body_to_object`` that would make it so
  is suggested (and ``vicon.world_to_ned`` must map Vicon's up to NED's up).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation
from scipy.stats import t as student_t

from groundstation.asctec.dialect import open_link
from groundstation.errors import GroundStationError
from groundstation.flight.params import FlightParams
from groundstation.types import FloatArray
from groundstation.vicon.receiver import ViconReceiver

MOVING_POSITION_M = 0.005
"""At rest, the mean Vicon position of a fifth of the measurement stays this close to the
first fifth's [m] (Table 6.1's noise, averaged, is far below), or within what the measured
noise reaches (:data:`STILL_FALSE_ALARM`), whichever is larger."""
MOVING_ATTITUDE_DEG = 1.0
"""At rest, the mean Vicon attitude of a fifth of the measurement stays this close to the
first fifth's [deg], or within what the measured noise reaches, whichever is larger."""
MOVING_GYRO_RAD_S = 0.05
"""At rest, the gyro's mean over a fifth of the measurement stays this close to the first
fifth's [rad/s] (Table 6.3's noise averages to a few mrad/s; a hand turning the vehicle
moves it by tenths), or within what the measured noise reaches, whichever is larger."""
STILL_FALSE_ALARM = 1e-6
"""Chance that white sensor noise alone makes a vehicle at rest look moved. A short
measurement of a noisy sensor has noisy window means (Vicon at 16 times Table 6.1's
attitude variance, 2 s at 80 Hz: 0.15 to 0.25 deg per axis, so a fixed 1 deg refused one
measurement at rest in 25); the limit grows with the noise so that this never happens.
How: a difference of two window means, one axis, divided by its standard deviation
estimated from the scatter inside the windows, is Student-t with N - 5 degrees of freedom
(white Gaussian noise: the scatter is independent of the means). If the norm of a
difference exceeds z times its estimated standard deviation, some axis exceeds z times its
own, so over d axes and 4 comparisons the chance is at most 4 d * 2 * t_sf(z, N - 5)
(Bonferroni), and z is chosen so that this bound is the rate."""
REST_FORCE_TOLERANCE = 0.2
"""At rest the accelerometer reads g within this fraction even through the configured
(perhaps uncalibrated) zeros and scales."""
FRAME_TOLERANCE_DEG = 5.0
"""A level vehicle with its nose along +x may read this far from identity [deg]."""


class CalibrationError(GroundStationError):
    """A calibration that cannot give a trustworthy answer (a moving vehicle, no data)."""


@dataclass(frozen=True)
class ImuCalibration:
    """What :func:`calibrate_imu` measured.

    gyro_zero, acc_zero : (3,) counts at zero rate / zero specific force, FRD axes
    gyro_zero_se, acc_zero_se : (3,) their standard errors [counts] (noise / sqrt(N))
    gyro_variance, acc_variance : (3,) [(rad/s)^2], [(m/s^2)^2] (Table 6.3's quantities)
    samples, seconds : IMU samples used and the measurement's length [s]
    attitude_from_vicon : the accelerometer's expected reading used the Vicon attitude
    expected_force : (3,) the specific force at rest the zeros were fitted to [m/s^2]
    counts : (N, 6) the raw gyro and acc counts, for the figure
    """

    gyro_zero: tuple[float, float, float]
    acc_zero: tuple[float, float, float]
    gyro_zero_se: tuple[float, float, float]
    acc_zero_se: tuple[float, float, float]
    gyro_variance: tuple[float, float, float]
    acc_variance: tuple[float, float, float]
    samples: int
    seconds: float
    attitude_from_vicon: bool
    expected_force: tuple[float, float, float]
    counts: FloatArray = field(repr=False)

    def config_fields(self) -> dict[str, Any]:
        """The result under the configuration's own field names."""
        return {"vehicle.gyro_zero": list(self.gyro_zero), "vehicle.acc_zero": list(self.acc_zero),
                "vehicle.gyro_variance": list(self.gyro_variance),
                "vehicle.acc_variance": list(self.acc_variance)}

    def summary(self) -> str:
        """Human-readable lines with units."""
        source = "the Vicon attitude" if self.attitude_from_vicon else "a level vehicle (no Vicon)"
        f = self.expected_force
        return "\n".join([
            f"IMU at rest: {self.samples} samples over {self.seconds:.1f} s; accelerometer "
            f"fitted to ({f[0]:.3f}, {f[1]:.3f}, {f[2]:.3f}) m/s^2 from {source}",
            "  gyro zero      " + _vec(self.gyro_zero, "{:8.2f}") + " counts (standard error "
            + _vec(self.gyro_zero_se, "{:.2f}") + ")",
            "  acc zero       " + _vec(self.acc_zero, "{:8.2f}") + " counts (standard error "
            + _vec(self.acc_zero_se, "{:.2f}") + ")",
            "  gyro variance  " + _vec(self.gyro_variance, "{:8.2e}") + " (rad/s)^2 (Table 6.3)",
            "  acc variance   " + _vec(self.acc_variance, "{:8.2e}") + " (m/s^2)^2 (Table 6.3)",
        ])

    def figure(self, path: Path) -> Path:
        """Counts per axis against time with the fitted zeros (PNG)."""
        from groundstation.evaluation.plotting import pyplot, save

        plt = pyplot()
        fig, axes = plt.subplots(2, 3, figsize=(12, 6), sharex=True)
        t = np.arange(len(self.counts)) * self.seconds / max(1, len(self.counts))
        for k, (sensor, zero) in enumerate((("gyro", self.gyro_zero), ("acc", self.acc_zero))):
            for j, axis in enumerate("xyz"):
                ax = axes[k, j]
                ax.plot(t, self.counts[:, 3 * k + j], lw=0.6, color="C0", label="counts")
                ax.axhline(zero[j], color="C3", lw=1.0, label=f"zero {zero[j]:.2f}")
                ax.set(title=f"{sensor} {axis}", ylabel="counts")
                ax.grid(True, alpha=0.3)
                ax.legend(fontsize=7, loc="lower right", framealpha=0.6)
        for ax in axes[1]:
            ax.set_xlabel("time [s]")
        fig.suptitle("gs calibrate imu: raw counts at rest and the fitted zeros")
        return save(fig, path)


@dataclass(frozen=True)
class ViconCalibration:
    """What :func:`calibrate_vicon` measured.

    position_variance : (3,) [m^2]; quaternion_variance : (4,) [1] (Table 6.1)
    rate_hz : poses per second; jitter_ms : standard deviation of the pose intervals [ms]
    frames_dropped : frame numbers missing from the stream
    samples, seconds : poses used, measurement length [s]
    attitude_error_deg : angle of the measured NED attitude from the identity [deg]
    frames_ok : level with the nose along +x reads as identity (within 5 deg) and
        world_to_ned maps Vicon's up to NED's up
    suggestions : configuration fields that would fix the frames, if not ok
    positions, quaternions : (N, 3), (N, 4) the poses, for the figure
    """

    position_variance: tuple[float, float, float]
    quaternion_variance: tuple[float, float, float, float]
    rate_hz: float
    jitter_ms: float
    frames_dropped: int
    samples: int
    seconds: float
    attitude_error_deg: float
    frames_ok: bool
    suggestions: dict[str, Any]
    positions: FloatArray = field(repr=False)
    quaternions: FloatArray = field(repr=False)

    def config_fields(self) -> dict[str, Any]:
        """The result under the configuration's own field names (plus the stream's
        figures and the frame check)."""
        out: dict[str, Any] = {
            "vehicle.vicon_position_variance": list(self.position_variance),
            "vehicle.vicon_quaternion_variance": list(self.quaternion_variance),
            "vicon.expected_rate_hz": round(self.rate_hz, 1),
            "jitter_ms": self.jitter_ms, "frames_dropped": self.frames_dropped,
            "attitude_error_deg": self.attitude_error_deg, "frames_ok": self.frames_ok,
        }
        out.update(self.suggestions)
        return out

    def summary(self) -> str:
        """Human-readable lines with units."""
        lines = [
            f"Vicon at rest: {self.samples} poses over {self.seconds:.1f} s, {self.rate_hz:.1f} Hz "
            f"(interval jitter {self.jitter_ms:.2f} ms), {self.frames_dropped} frames dropped",
            "  position variance    " + _vec(self.position_variance, "{:9.2e}")
            + " m^2 (Table 6.1)",
            "  quaternion variance  " + _vec(self.quaternion_variance, "{:9.2e}") + " (Table 6.1)",
        ]
        if self.frames_ok:
            lines.append(f"  frames: OK (level, nose along +x reads {self.attitude_error_deg:.1f} "
                         "deg from the identity)")
        else:
            lines.append(f"  frames: WRONG: the vehicle reads {self.attitude_error_deg:.1f} deg "
                         "from level-nose-along-+x; suggested:")
            lines += [f"    {k}: {v}" for k, v in self.suggestions.items()]
        return "\n".join(lines)

    def figure(self, path: Path) -> Path:
        """Position and attitude deviations from their means against time (PNG)."""
        from groundstation.evaluation.plotting import pyplot, save

        plt = pyplot()
        fig, (pos, att) = plt.subplots(2, 1, figsize=(10, 6), sharex=True)
        t = np.arange(len(self.positions)) / max(self.rate_hz, 1e-9)
        dev = 1e3 * (self.positions - self.positions.mean(axis=0))
        for j, axis in enumerate("xyz"):
            pos.plot(t, dev[:, j], lw=0.7, label=axis)
        pos.set(ylabel="position - mean [mm]", title="position (NED) at rest")
        q = self.quaternions - self.quaternions.mean(axis=0)
        for j in range(4):
            att.plot(t, q[:, j], lw=0.7, label=f"q{j}")
        att.set(xlabel="time [s]", ylabel="quaternion - mean [1]",
                title="attitude quaternion (body to NED) at rest")
        for ax in (pos, att):
            ax.grid(True, alpha=0.3)
            ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.0, 1.0))
        fig.suptitle(f"gs calibrate vicon: {self.samples} poses at {self.rate_hz:.1f} Hz, "
                     f"{self.frames_dropped} dropped")
        return save(fig, path)


def _vec(values: tuple[float, ...], fmt: str) -> str:
    return " ".join(fmt.format(v) for v in values)


def _collect_poses(client: ViconReceiver, seconds: float) -> list[Any]:
    poses = []
    end = time.monotonic() + seconds
    while (left := end - time.monotonic()) > 0:
        pose = client.get(min(left, 0.1))
        if pose is not None:
            poses.append(pose)
    return poses


def _aligned_quaternions(quaternions: FloatArray) -> FloatArray:
    """(N, 4) quaternions with the sign of the first (q and -q are one attitude)."""
    q = np.array(quaternions, dtype=float)
    flip = q @ q[0] < 0
    q[flip] *= -1.0
    return q


def _mean_rotation(quaternions: FloatArray) -> Rotation:
    q = _aligned_quaternions(quaternions)
    return Rotation.from_quat(np.roll(q, -1, axis=1)).mean()  # scipy is scalar-last


def _windows(values: FloatArray, n: int = 5) -> list[FloatArray]:
    return [w for w in np.array_split(np.asarray(values, dtype=float), n) if len(w)]


def _change_and_limit(windows: list[FloatArray], floor: float) -> tuple[float, float]:
    """(largest change of a window's mean from the first window's, the change allowed at
    rest). ``windows``: (n_i, d) samples each; the allowed change is the larger of
    ``floor`` and what noise alone reaches with :data:`STILL_FALSE_ALARM`, from the
    scatter inside the windows (so a slow drift does not inflate it)."""
    means = np.array([w.mean(axis=0) for w in windows])
    dof = sum(len(w) - 1 for w in windows)
    if dof < 1 or len(windows) < 2:
        return 0.0, floor
    scatter = sum(((w - w.mean(axis=0)) ** 2).sum(axis=0) for w in windows)
    variance = np.asarray(scatter, dtype=float) / dof  # (d,) per sample
    tests = 2 * means.shape[1] * (len(windows) - 1)  # two-sided, per axis and comparison
    z = float(student_t.isf(STILL_FALSE_ALARM / tests, dof))
    change, limit = 0.0, floor
    for w, m in zip(windows[1:], means[1:], strict=True):
        sd = math.sqrt(float(variance.sum()) * (1.0 / len(w) + 1.0 / len(windows[0])))
        change = max(change, float(np.linalg.norm(m - means[0])))
        limit = max(limit, z * sd)
    return change, limit


def _rotation_vectors(quaternions: FloatArray) -> FloatArray:
    """(N, 3) rotation vectors [rad] of (N, 4) scalar-first quaternions about their mean
    rotation: R_j = exp(v_j) R_mean, so differences of means are small angles [rad]."""
    aligned = _aligned_quaternions(quaternions)
    rotations = Rotation.from_quat(np.roll(aligned, -1, axis=1))  # scipy is scalar-last
    return np.asarray((rotations * _mean_rotation(aligned).inv()).as_rotvec(), dtype=float)


def _check_still(positions: FloatArray | None, quaternions: FloatArray | None,
                 gyro: FloatArray | None) -> None:
    """CalibrationError naming what moved. The measurement is cut in five windows and
    their means compared, so sensor noise (which averages out) is not taken for motion."""
    if positions is not None and len(positions) >= 10:
        change, limit = _change_and_limit(_windows(positions), MOVING_POSITION_M)
        if change > limit:
            raise CalibrationError(f"the vehicle moved during the measurement: its Vicon "
                                   f"position drifted {1e3 * change:.1f} mm (at rest < "
                                   f"{1e3 * limit:.0f} mm); keep it still and retry")
    if quaternions is not None and len(quaternions) >= 10:
        change, limit = _change_and_limit(_windows(_rotation_vectors(quaternions)),
                                          math.radians(MOVING_ATTITUDE_DEG))
        if change > limit:
            raise CalibrationError(f"the vehicle moved during the measurement: its attitude "
                                   f"changed by {math.degrees(change):.1f} deg (at rest < "
                                   f"{math.degrees(limit):.1f} deg); keep it still and retry")
    if gyro is not None and len(gyro) >= 10:
        change, limit = _change_and_limit(_windows(gyro), MOVING_GYRO_RAD_S)
        if change > limit:
            raise CalibrationError(f"the vehicle moved during the measurement: the gyro's "
                                   f"mean changed by {change:.2f} rad/s (at rest < "
                                   f"{limit:.2f} rad/s); keep it still and retry")


def calibrate_imu(params: FlightParams, seconds: float = 10.0,
                  use_vicon: bool = True) -> ImuCalibration:
    """Measure the IMU zeros and noise with the vehicle at rest (see the module docstring).

    CalibrationError if no IMU data arrives, too few samples, or the vehicle moves;
    LinkError/ViconError if the port or the Vicon socket cannot be opened.
    """
    scaling = params.imu
    g = params.vehicle.g
    with open_link(params.link) as link:
        vicon = ViconReceiver.from_params(params.vicon).start() if use_vicon else None
        try:
            link.start_stream()
            counts = []
            poses = []
            end = time.monotonic() + seconds
            while (left := end - time.monotonic()) > 0:
                rx = link.get(timeout=min(left, 0.1))
                if rx is not None and rx.msg.gyro is not None and rx.msg.acc is not None:
                    gy, ac = rx.msg.gyro, rx.msg.acc
                    counts.append((gy.x, gy.y, gy.z, ac.x, ac.y, ac.z))
                while vicon is not None and (pose := vicon.get(0.0)) is not None:
                    poses.append(pose)
        finally:
            if vicon is not None:
                vicon.close()
    if len(counts) < 50:
        raise CalibrationError(f"only {len(counts)} IMU samples in {seconds:g} s on "
                               f"{params.link.port} (is the vehicle on and the link up?)")
    c = np.asarray(counts, dtype=float)
    gyro_si = np.array([scaling.gyro.to_si(row) for row in c[:, :3]])
    positions = np.array([p.position for p in poses]) if poses else None
    quaternions = np.array([p.quaternion for p in poses]) if poses else None
    _check_still(positions, quaternions, gyro_si)
    acc_norm = float(np.linalg.norm(np.mean([scaling.acc.to_si(row) for row in c[:, 3:]], axis=0)))
    if abs(acc_norm - g) > REST_FORCE_TOLERANCE * g:
        raise CalibrationError(f"the vehicle is not at rest on the floor: its accelerometer "
                               f"reads {acc_norm:.2f} m/s^2, not g = {g:g} m/s^2 (within "
                               f"{100 * REST_FORCE_TOLERANCE:.0f} %)")
    if quaternions is not None and len(quaternions) >= 10:
        r = _mean_rotation(quaternions)  # body -> NED
        force = r.inv().apply([0.0, 0.0, -g])
    else:
        force = np.array([0.0, 0.0, -g])
    gyro_scale = np.asarray(scaling.gyro.scale, dtype=float)
    acc_scale = np.asarray(scaling.acc.scale, dtype=float)
    gyro_zero = c[:, :3].mean(axis=0)
    acc_zero = c[:, 3:].mean(axis=0) - force / acc_scale
    se = np.std(c, axis=0, ddof=1) / math.sqrt(len(c))
    return ImuCalibration(
        gyro_zero=_t3(gyro_zero), acc_zero=_t3(acc_zero), gyro_zero_se=_t3(se[:3]),
        acc_zero_se=_t3(se[3:]),
        gyro_variance=_t3(np.var(c[:, :3], axis=0, ddof=1) * gyro_scale**2),
        acc_variance=_t3(np.var(c[:, 3:], axis=0, ddof=1) * acc_scale**2),
        samples=len(c), seconds=seconds, attitude_from_vicon=quaternions is not None
        and len(quaternions) >= 10, expected_force=_t3(force), counts=c)


def _t3(v: FloatArray) -> tuple[float, float, float]:
    return (float(v[0]), float(v[1]), float(v[2]))


def calibrate_vicon(params: FlightParams, seconds: float = 10.0) -> ViconCalibration:
    """Measure Vicon's noise and stream with the object at rest, and check the frames
    (see the module docstring). CalibrationError without poses or if the object moves."""
    vicon = params.vicon
    with ViconReceiver.from_params(vicon).start() as client:
        poses = _collect_poses(client, seconds)
    if len(poses) < 20:
        raise CalibrationError(f"only {len(poses)} Vicon poses of {vicon.filter.object_name!r} "
                               f"in {seconds:g} s on UDP port {vicon.port} (is Tracker "
                               "streaming to this PC, and the object name right?)")
    positions = np.array([p.position for p in poses])
    quaternions = _aligned_quaternions(np.array([p.quaternion for p in poses]))
    _check_still(positions, quaternions, None)
    t = np.array([p.t for p in poses])
    frames = np.array([p.frame for p in poses], dtype=np.int64)
    steps = np.diff(frames)
    dropped = int(np.sum(np.where(steps > 1, steps - 1, 0)))
    interval = np.diff(t)
    rate = (len(t) - 1) / float(t[-1] - t[0]) if t[-1] > t[0] else math.nan
    measured = _mean_rotation(quaternions)  # body -> NED as the configuration maps it
    error_deg = float(np.degrees(measured.magnitude()))
    world = np.asarray(vicon.filter.world_to_ned)
    up_ok = bool(np.allclose(world @ np.array([0.0, 0.0, 1.0]), [0.0, 0.0, -1.0], atol=1e-6))
    suggestions: dict[str, Any] = {}
    if not up_ok:
        suggestions["vicon.world_to_ned"] = {"euler_xyz_deg": [180.0, 0.0, 0.0]}
    if error_deg > FRAME_TOLERANCE_DEG:
        body = Rotation.from_matrix(np.asarray(vicon.filter.body_to_object))
        fixed = body * measured.inv()  # W R_obj B' = I with W R_obj = M B^T
        angles = [round(float(a), 1) + 0.0 for a in fixed.as_euler("XYZ", degrees=True)]
        suggestions["vicon.body_to_object"] = {"euler_xyz_deg": angles}
    return ViconCalibration(
        position_variance=_t3(np.var(positions, axis=0, ddof=1)),
        quaternion_variance=tuple(float(v) for v in np.var(quaternions, axis=0, ddof=1)),  # type: ignore[arg-type]
        rate_hz=float(rate), jitter_ms=float(1e3 * np.std(interval)), frames_dropped=dropped,
        samples=len(poses), seconds=seconds, attitude_error_deg=error_deg,
        frames_ok=up_ok and error_deg <= FRAME_TOLERANCE_DEG, suggestions=suggestions,
        positions=positions, quaternions=quaternions)
