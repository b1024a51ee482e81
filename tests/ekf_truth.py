"""In-process truth simulator for the estimator's tests and ``benchmarks/bench_ekf.py``
(test-only: not part of the package; the virtual lab, with the full plant, lives in
``sim_device``).

:class:`TruthSimulator` flies the nonlinear model of
:class:`~groundstation.model.quadrotor.QuadrotorModel` along a trajectory with a
simple geometric controller that reads the *true* state, so the truth does not
depend on the estimator. It produces what the ground station would receive:

* IMU samples at every step: body rates and specific force of the truth, plus
  constant biases and white noise of Table 6.3 variances (``measured = true + bias``);
* Vicon poses: truth position and attitude with Table 6.1 noise (attitude noise
  as a body-frame rotation of variance ``4 var(q_i)``), random quaternion sign.

The body-rate and thrust inputs ramp linearly over each step from the previous
command to the new one (a one-step-delayed, continuous input), so the IMU
samples at the step ends describe the input exactly as a linear interpolation.
Deterministic: every random draw comes from the seeded generator.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from groundstation.estimation.ekf import Ekf
from groundstation.estimation.imu_model import boxminus
from groundstation.model.quadrotor import QuadrotorModel, QuadrotorParams
from groundstation.model.quaternion import (
    canonical,
    dcm_from_quat,
    gravity_body,
    multiply,
    quat_from_dcm,
    quat_from_rotvec,
    rotvec_from_quat,
)
from groundstation.model.sensors import (
    ACC_VARIANCE_TABLE_6_3,
    GYRO_VARIANCE_TABLE_6_3,
    VICON_POSITION_VARIANCE_TABLE_6_1,
    VICON_QUATERNION_VARIANCE_TABLE_6_1,
)
from groundstation.types import FloatArray, ImuSample, Pose

_Q_VAR_1_3 = VICON_QUATERNION_VARIANCE_TABLE_6_1[1:]

__all__ = [
    "SensorNoise",
    "Tracking",
    "TruthSimulator",
    "attitude_error",
    "fly",
    "hover_reference",
    "square_reference",
]

RefFn = Callable[[float], tuple[FloatArray, FloatArray, FloatArray]]


def hover_reference(position: tuple[float, float, float] = (0.0, 0.0, -1.0)) -> RefFn:
    """Reference ``t -> (p, v, a)`` holding ``position`` (NED [m])."""
    p = np.array(position, dtype=float)
    zero = np.zeros(3)
    return lambda t: (p, zero, zero)


def square_reference(side: float = 0.75, lap_time: float = 20.0, height: float = 1.0) -> RefFn:
    """Reference ``t -> (p, v, a)`` around a square of ``side`` [m] at ``height`` [m],
    one lap per ``lap_time`` [s], each side a minimum-jerk (quintic) move."""
    corners = np.array([[0, 0], [side, 0], [side, side], [0, side], [0, 0]], dtype=float)
    t_side = lap_time / 4.0

    def ref(t: float) -> tuple[FloatArray, FloatArray, FloatArray]:
        k = int(t // t_side) % 4
        s = (t % t_side) / t_side
        pos = 10 * s**3 - 15 * s**4 + 6 * s**5
        vel = (30 * s**2 - 60 * s**3 + 30 * s**4) / t_side
        acc = (60 * s - 180 * s**2 + 120 * s**3) / t_side**2
        d = corners[k + 1] - corners[k]
        p = np.r_[corners[k] + pos * d, -height]
        return p, np.r_[vel * d, 0.0], np.r_[acc * d, 0.0]

    return ref


@dataclass(frozen=True, slots=True)
class SensorNoise:
    """Noise and bias of the simulated sensors (defaults: Tables 6.1 and 6.3, no bias).

    The biases start at ``gyro_bias``/``acc_bias`` and random-walk with the given densities.
    """

    gyro_var: tuple[float, float, float] = GYRO_VARIANCE_TABLE_6_3
    acc_var: tuple[float, float, float] = ACC_VARIANCE_TABLE_6_3
    gyro_bias: tuple[float, float, float] = (0.0, 0.0, 0.0)
    acc_bias: tuple[float, float, float] = (0.0, 0.0, 0.0)
    position_var: tuple[float, float, float] = VICON_POSITION_VARIANCE_TABLE_6_1
    quaternion_var: tuple[float, float, float] = _Q_VAR_1_3  # q1..q3
    random_sign: bool = True
    gyro_bias_walk: float = 0.0  # bias random-walk densities [(rad/s)^2/s], [(m/s^2)^2/s]
    acc_bias_walk: float = 0.0

    @staticmethod
    def none() -> SensorNoise:
        """Noise-free sensors (variances zero, no bias, no sign flips)."""
        z = (0.0, 0.0, 0.0)
        return SensorNoise(z, z, z, z, z, z, False, 0.0, 0.0)


class TruthSimulator:
    """The true vehicle, its controller and its sensors, stepped at ``dt`` [s].

    on_ground : the vehicle rests level on the floor at ``start`` (IMU reads -g_b).
    """

    def __init__(
        self,
        reference: RefFn | None = None,
        noise: SensorNoise | None = None,
        params: QuadrotorParams | None = None,
        seed: int = 0,
        dt: float = 0.01,
        start: FloatArray | None = None,
        on_ground: bool = False,
    ) -> None:
        self.model = QuadrotorModel(params)
        self.params = self.model.params
        self.reference = reference if reference is not None else hover_reference()
        self.noise = noise if noise is not None else SensorNoise()
        self.rng = np.random.default_rng(seed)
        self.dt = dt
        self.on_ground = on_ground
        self.t = 0.0
        self.counter = 0
        self.x = np.zeros(10)
        p0 = self.reference(0.0)[0] if start is None else np.asarray(start, dtype=float)
        self.x[0:3] = p0
        self.x[3] = 1.0
        self.u = np.zeros(4)  # input at the current time (rates, F_z)
        self._sd = {k: np.sqrt(np.asarray(getattr(self.noise, k))) for k in
                    ("gyro_var", "acc_var", "position_var", "quaternion_var")}  # fmt: skip
        self._bg = np.array(self.noise.gyro_bias, dtype=float)
        self._ba = np.array(self.noise.acc_bias, dtype=float)

    @property
    def gyro_bias(self) -> FloatArray:
        """The true gyro bias now [rad/s]."""
        return self._bg.copy()

    @property
    def acc_bias(self) -> FloatArray:
        """The true accelerometer bias now [m/s^2]."""
        return self._ba.copy()

    def true_omega(self) -> FloatArray:
        """True body rate now [rad/s]."""
        return self.u[0:3].copy()

    def imu(self) -> ImuSample:
        """The IMU sample at the current time."""
        if self.on_ground:
            omega, f = np.zeros(3), -gravity_body(self.x[3:7], self.params.g)
        else:
            omega, f = self.u[0:3], self.model.specific_force(self.x, self.u)
        gyro = omega + self._bg + self._sd["gyro_var"] * self.rng.standard_normal(3)
        acc = f + self._ba + self._sd["acc_var"] * self.rng.standard_normal(3)
        return ImuSample(self.t, gyro, acc, self.counter)

    def pose(self, t_offset: float = 0.0) -> Pose:
        """A Vicon pose of the current truth, stamped ``t + t_offset``."""
        p = self.x[0:3] + self._sd["position_var"] * self.rng.standard_normal(3)
        n = 2.0 * self._sd["quaternion_var"] * self.rng.standard_normal(3)
        q = multiply(self.x[3:7], quat_from_rotvec(n))
        if self.noise.random_sign and self.rng.random() < 0.5:
            q = -q
        return Pose(self.t + t_offset, p, q, frame=self.counter + 1)

    def step(self) -> None:
        """Advance the truth by ``dt``: new command, input ramps to it over the step."""
        self.counter = (self.counter + 1) % 65536
        if self.noise.gyro_bias_walk > 0.0:
            self._bg += math.sqrt(self.noise.gyro_bias_walk * self.dt) * self.rng.standard_normal(3)
        if self.noise.acc_bias_walk > 0.0:
            self._ba += math.sqrt(self.noise.acc_bias_walk * self.dt) * self.rng.standard_normal(3)
        if self.on_ground:
            self.t += self.dt
            return
        u0 = self.u.copy()
        u1 = self._control(self.t)
        self.x = self._rk4(self.x, u0, u1, self.dt)
        self.u = u1
        self.t += self.dt

    def _rk4(self, x: FloatArray, u0: FloatArray, u1: FloatArray, dt: float) -> FloatArray:
        f = self.model.derivative
        um = 0.5 * (u0 + u1)
        k1 = f(x, u0)
        k2 = f(x + 0.5 * dt * k1, um)
        k3 = f(x + 0.5 * dt * k2, um)
        k4 = f(x + dt * k3, u1)
        out: FloatArray = x + (dt / 6.0) * (k1 + 2 * k2 + 2 * k3 + k4)
        out[3:7] /= np.linalg.norm(out[3:7])
        return out

    def _control(self, t: float) -> FloatArray:
        """Geometric position controller on the true state -> ``[omega, F_z]``."""
        m, g = self.params.mass, self.params.g
        p_ref, v_ref, a_ref = self.reference(t)
        R = dcm_from_quat(self.x[3:7])
        a_cmd = a_ref + 1.5 * (p_ref - self.x[0:3]) + 2.0 * (v_ref - R @ self.x[7:10])
        f_d = a_cmd - np.array([0.0, 0.0, g])  # desired specific force, NED
        zb = -f_d / np.linalg.norm(f_d)
        yb = np.cross(zb, [1.0, 0.0, 0.0])
        yb /= np.linalg.norm(yb)
        R_d = np.column_stack((np.cross(yb, zb), yb, zb))
        q_d = canonical(quat_from_dcm(R_d))
        q_err = multiply(np.r_[self.x[3], -self.x[4:7]], q_d)
        omega = np.clip(5.0 * rotvec_from_quat(q_err), -2.0, 2.0)
        s = float(f_d @ R[:, 2])
        f_z = m * s + m * g - self.params.inflow * float(self.x[9])
        u: FloatArray = np.r_[omega, f_z]
        return u


def attitude_error(q_est: FloatArray, q_true: FloatArray) -> float:
    """Angle [rad] of the rotation between two attitudes (sign-independent)."""
    d = multiply(np.r_[q_true[0], -q_true[1:4]], q_est)
    return 2.0 * math.atan2(float(np.linalg.norm(d[1:4])), abs(float(d[0])))


@dataclass
class Tracking:
    """Per-step errors of an estimator run against the truth (after the warm-up).

    position_error [m], attitude_error [rad], velocity_error [m/s] : (n,) norms;
    nees : (n,) normalised estimation error squared of the 15-dof error state;
    nis : NIS of every applied update; results : reasons of every update.
    """

    t: FloatArray
    position_error: FloatArray
    attitude_error: FloatArray
    velocity_error: FloatArray
    nees: FloatArray
    nis: FloatArray
    reasons: list[str]

    def rms(self, name: str) -> float:
        """RMS of one error series, e.g. ``rms("position_error")``."""
        a = np.asarray(getattr(self, name), dtype=float)
        return float(np.sqrt(np.mean(a * a)))


def fly(
    ekf: Ekf,
    sim: TruthSimulator,
    duration: float,
    vicon_every: int = 1,
    warmup: float = 5.0,
    vicon_offset: float = 0.0,
    vicon_off: tuple[float, float] | None = None,
    init_samples: int = 1,
) -> Tracking:
    """Initialise ``ekf`` from ``sim`` and run both for ``duration`` [s] of sim time.

    vicon_every : one pose per this many IMU samples (1 = 100 Hz at dt 0.01);
    vicon_offset : added to each pose's time stamp [s] (negative = a latency the
    pose is stamped with; positive poses wait for the IMU);
    vicon_off : ``(t_start, t_end)`` with no poses (an outage).
    """
    samples = []
    for _ in range(init_samples):
        samples.append(sim.imu())
        sim.step()
    ekf.initialise(sim.pose(), [*samples[1:], sim.imu()] if init_samples > 1 else [sim.imu()])
    rows: list[tuple[float, float, float, float, float]] = []
    nis: list[float] = []
    reasons: list[str] = []
    k = 0
    t_end = sim.t + duration
    while sim.t < t_end:
        sim.step()
        k += 1
        ekf.predict(sim.imu())
        off = vicon_off is not None and vicon_off[0] <= sim.t < vicon_off[1]
        if k % vicon_every == 0 and not off:
            r = ekf.update(sim.pose(vicon_offset))
            reasons.append(r.reason)
            if r.reason == "ok":
                nis.append(r.nis)
        if sim.t >= warmup:
            rows.append(_errors(ekf, sim))
    a = np.array(rows).reshape(-1, 5)
    return Tracking(a[:, 0], a[:, 1], a[:, 2], a[:, 3], a[:, 4], np.array(nis), reasons)


def _errors(ekf: Ekf, sim: TruthSimulator) -> tuple[float, float, float, float, float]:
    x = ekf.state
    truth = np.r_[sim.x, sim.gyro_bias, sim.acc_bias]
    e = boxminus(truth, x)
    nees = float(e @ np.linalg.solve(ekf.error_covariance, e))
    return (sim.t, float(np.linalg.norm(e[0:3])), float(np.linalg.norm(e[3:6])),
            float(np.linalg.norm(e[6:9])), nees)  # fmt: skip
