"""A small closed-loop simulator for controllers: the shipped test harness.

It flies a :class:`~groundstation.control.base.Controller` along a
:class:`~groundstation.control.trajectory.Trajectory` on the nonlinear model of
eq. 3.19-3.22 (:class:`groundstation.model.QuadrotorModel`), with the effects
the thesis's linear model leaves out and the real vehicle has:

* the on-board rate loop as a first-order lag (``rate_tau``, Fig. 3.8),
* a transport delay of the commands (``delay_s``),
* a wrong thrust map (``thrust_scale``: true lift / modelled lift) and wrong rate
  gains (``rate_gain_scale``),
* stick quantisation and saturation (the commands go through :func:`to_sticks`
  and back through eq. 3.7 and 3.22, as on the wire).

The controller sees the *true* state (no estimator, no sensor noise): this
isolates the controller. The full chain with the EKF and Vicon is the
virtual lab's job (``sim_device``). Time is simulated; nothing sleeps.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from groundstation.control.base import Controller
from groundstation.control.sticks import StickParams, to_sticks
from groundstation.control.trajectory import Trajectory
from groundstation.model import QuadrotorModel, QuadrotorParams, inputs_from_sticks
from groundstation.model.quaternion import dcm_from_quat
from groundstation.types import ControlOutput, FloatArray, StateEstimate

_VEHICLE = QuadrotorParams()
"""The vehicle model's defaults (the rate-loop time constant)."""


@dataclass(frozen=True, slots=True)
class SimPlant:
    """Plant options (see the module docstring); ``rate_tau = 0`` is an ideal rate loop."""

    rate_tau: float = _VEHICLE.rate_tau
    delay_s: float = 0.02
    thrust_scale: float = 1.0
    dt: float = 0.005
    rate_gain_scale: tuple[float, float, float] = (1.0, 1.0, 1.0)
    """True rate gains / modelled ones, per axis (1.3: the rate loop answers 30 % more)."""


@dataclass(frozen=True, slots=True)
class SimResult:
    """Time histories at the control rate, N samples.

    t (N,) [s]; position, velocity (N, 3) NED [m, m/s] (velocity in earth axes);
    quaternion (N, 4); reference, reference_velocity (N, 3) NED;
    omega_cmd (N, 3) [rad/s] and f_z (N,) [N] as the controller asked;
    sticks (N, 4) [roll, pitch, yaw, thrust] RC units as sent; saturated (N,) bool.
    """

    t: FloatArray
    position: FloatArray
    velocity: FloatArray
    quaternion: FloatArray
    reference: FloatArray
    reference_velocity: FloatArray
    omega_cmd: FloatArray
    f_z: FloatArray
    sticks: np.ndarray
    saturated: np.ndarray


def _estimate(t: float, x: FloatArray, omega: FloatArray) -> StateEstimate:
    return StateEstimate(
        t=t, position=x[0:3].copy(), quaternion=x[3:7].copy(), velocity_body=x[7:10].copy(),
        omega=omega.copy(), gyro_bias=np.zeros(3), acc_bias=np.zeros(3),
        covariance_diag=np.zeros(16),
    )


def simulate(
    controller: Controller,
    trajectory: Trajectory,
    duration: float,
    *,
    params: QuadrotorParams | None = None,
    plant: SimPlant | None = None,
    rate_hz: float = 50.0,
    x0: FloatArray | None = None,
) -> SimResult:
    """Fly ``controller`` along ``trajectory`` for ``duration`` seconds (simulated).

    x0 : initial ``[P, q, v]`` (10,); default: at rest, level, on the
    trajectory's starting point. The controller is reset first.
    """
    p = params if params is not None else QuadrotorParams()
    pl = plant if plant is not None else SimPlant()
    model = QuadrotorModel(p)
    sp = StickParams.from_quadrotor(p)
    n_sub = max(1, round(1.0 / (rate_hz * pl.dt)))
    h = 1.0 / (rate_hz * n_sub)
    lag = 1.0 - math.exp(-h / pl.rate_tau) if pl.rate_tau > 0.0 else 1.0
    delay_steps = round(pl.delay_s / h)
    x = np.array(x0, dtype=float) if x0 is not None else _start(trajectory)
    omega = np.zeros(3)
    pending: deque[FloatArray] = deque([np.zeros(4)] * delay_steps)
    weight = p.mass * p.g
    n = round(duration * rate_hz)
    rec = {k: np.zeros((n, 3)) for k in ("pos", "vel", "ref", "refv", "w")}
    quat, f_z, sat = np.zeros((n, 4)), np.zeros(n), np.zeros(n, dtype=bool)
    sticks = np.zeros((n, 4), dtype=int)
    controller.reset()
    for k in range(n):
        t = k / rate_hz
        ref = trajectory.sample(t)
        lead = controller.lead_s
        preview = trajectory.sample(t + lead) if lead > 0.0 else None
        out = controller.step(t, _estimate(t, x, omega), ref, preview)
        st, flags = to_sticks(out, sp)
        u = inputs_from_sticks(st, p)
        controller.sent(ControlOutput(omega=u[0:3].copy(), f_z=float(u[3])), True)
        u[3] = pl.thrust_scale * (u[3] - weight) + weight  # true lift = scale * modelled
        u[0:3] *= pl.rate_gain_scale  # true body-rate set point = scale * modelled
        _record(rec, k, x, ref.position, ref.velocity, out.omega)
        quat[k], f_z[k], sat[k] = x[3:7], out.f_z, flags.any
        sticks[k] = (st.roll, st.pitch, st.yaw, st.thrust)
        for _ in range(n_sub):
            pending.append(u)
            applied = pending.popleft()
            omega += lag * (applied[0:3] - omega)
            x = model.step(x, np.concatenate([omega, applied[3:4]]), h)
    return SimResult(np.arange(n) / rate_hz, rec["pos"], rec["vel"], quat, rec["ref"],
                     rec["refv"], rec["w"], f_z, sticks, sat)


def _start(trajectory: Trajectory) -> FloatArray:
    x = np.zeros(10)
    x[0:3] = trajectory.sample(0.0).position
    x[3] = 1.0
    return x


def _record(rec: dict[str, FloatArray], k: int, x: FloatArray, ref: FloatArray,
            refv: FloatArray, w: FloatArray) -> None:
    rec["pos"][k] = x[0:3]
    rec["vel"][k] = dcm_from_quat(x[3:7]) @ x[7:10]
    rec["ref"][k] = ref
    rec["refv"][k] = refv
    rec["w"][k] = w
