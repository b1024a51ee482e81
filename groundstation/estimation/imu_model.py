"""The IMU-driven model of thesis Ch. 7.2 and its error-state linearisation.

Nominal state ``x`` (16,) = ``[P (3), q (4), v (3), b_g (3), b_a (3)]``:
position NED [m], attitude quaternion (scalar first, ``R(q) = eCb``), velocity in
body FRD axes [m/s], gyro bias [rad/s] and accelerometer bias [m/s^2].

Bias convention (thesis eq. 7.18 writes ``a_bar + a_b``; ours is explicit):
``true = measured - bias``, i.e. ``omega = gyro - b_g`` and ``a = acc - b_a``, so an
IMU that reads 0.02 rad/s at rest has ``b_g = +0.02``.

Continuous model (eq. 7.17-7.21, ``a`` the specific force the accelerometer measures)::

    P_dot = eCb v
    q_dot = 0.5 q ⊗ [0, omega]
    v_dot = a + bCe [0, 0, g] - omega × v
    b_g_dot = w_bg,   b_a_dot = w_ba       (random walks)

Error state ``dx`` (15,) = ``[dP, dtheta, dv, db_g, db_a]`` with the attitude error
a body-frame rotation vector: ``q_true = q ⊗ exp(dtheta)`` (``exp`` is
:func:`~groundstation.model.quaternion.quat_from_rotvec`). Its Jacobian ``F``::

    dP_dot     = -R [v×] dtheta + R dv
    dtheta_dot = -[omega×] dtheta - db_g                       - n_g
    dv_dot     = [g_b×] dtheta - [omega×] dv - [v×] db_g - db_a  - [v×] n_g - n_a

with ``R = eCb``, ``g_b = bCe [0, 0, g]``, ``n_g, n_a`` the gyro/accelerometer noise.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

from groundstation.model.quaternion import multiply, quat_from_rotvec, rotvec_from_quat
from groundstation.types import FloatArray

__all__ = [
    "N_ERR",
    "N_STATE",
    "boxminus",
    "boxplus",
    "derivative",
    "error_jacobian",
    "jacobian_flat_index",
    "propagate",
]

N_STATE = 16
N_ERR = 15

IndexArray = npt.NDArray[np.intp]


def _f(y: Sequence[float], u: Sequence[float], g: float) -> tuple[float, ...]:
    """Derivative of ``[P, q, v]`` (10 floats) at ``y = (q0..q3, v1..v3)`` for the
    bias-corrected input ``u = (w1, w2, w3, a1, a2, a3)``."""
    q0, q1, q2, q3, v1, v2, v3 = y
    w1, w2, w3, a1, a2, a3 = u
    s0, s1, s2, s3 = q0 * q0, q1 * q1, q2 * q2, q3 * q3
    r11, r22, r33 = s0 + s1 - s2 - s3, s0 - s1 + s2 - s3, s0 - s1 - s2 + s3
    r12, r21 = 2 * (q1 * q2 - q0 * q3), 2 * (q1 * q2 + q0 * q3)
    r13, r31 = 2 * (q1 * q3 + q0 * q2), 2 * (q1 * q3 - q0 * q2)
    r23, r32 = 2 * (q2 * q3 - q0 * q1), 2 * (q2 * q3 + q0 * q1)
    return (
        r11 * v1 + r12 * v2 + r13 * v3,
        r21 * v1 + r22 * v2 + r23 * v3,
        r31 * v1 + r32 * v2 + r33 * v3,
        0.5 * (-w1 * q1 - w2 * q2 - w3 * q3),
        0.5 * (w1 * q0 + w3 * q2 - w2 * q3),
        0.5 * (w2 * q0 - w3 * q1 + w1 * q3),
        0.5 * (w3 * q0 + w2 * q1 - w1 * q2),
        a1 + g * r31 - (w2 * v3 - w3 * v2),
        a2 + g * r32 - (w3 * v1 - w1 * v3),
        a3 + g * r33 - (w1 * v2 - w2 * v1),
    )


def derivative(x: FloatArray, gyro: FloatArray, acc: FloatArray, g: float) -> FloatArray:
    """``x_dot`` (16,) of the nominal model for measured ``gyro`` [rad/s] and ``acc`` [m/s^2]."""
    u = np.concatenate((gyro - x[10:13], acc - x[13:16])).tolist()
    d = _f(x[3:10].tolist(), u, g)
    out = np.zeros(N_STATE)
    out[:10] = d
    return out


def propagate(
    x: FloatArray,
    gyro0: FloatArray,
    acc0: FloatArray,
    gyro1: FloatArray,
    acc1: FloatArray,
    dt: float,
    g: float,
    out: FloatArray,
) -> None:
    """One RK4 step of the nominal model over ``dt`` [s], written into ``out`` (16,).

    The measured inputs vary linearly from ``(gyro0, acc0)`` at the start to
    ``(gyro1, acc1)`` at the end of the step; biases are constant over it. The
    quaternion is renormalised. ``out`` may be ``x``.
    """
    P1, P2, P3, q0, q1, q2, q3, v1, v2, v3, bg1, bg2, bg3, ba1, ba2, ba3 = x.tolist()
    gx, gy, gz = gyro0.tolist()
    ax, ay, az = acc0.tolist()
    hx, hy, hz = gyro1.tolist()
    bx, by, bz = acc1.tolist()
    ua = (gx - bg1, gy - bg2, gz - bg3, ax - ba1, ay - ba2, az - ba3)
    ub = (hx - bg1, hy - bg2, hz - bg3, bx - ba1, by - ba2, bz - ba3)
    um = (0.5 * (ua[0] + ub[0]), 0.5 * (ua[1] + ub[1]), 0.5 * (ua[2] + ub[2]),
          0.5 * (ua[3] + ub[3]), 0.5 * (ua[4] + ub[4]), 0.5 * (ua[5] + ub[5]))  # fmt: skip
    h = 0.5 * dt
    k1 = _f((q0, q1, q2, q3, v1, v2, v3), ua, g)
    k2 = _f((q0 + h * k1[3], q1 + h * k1[4], q2 + h * k1[5], q3 + h * k1[6],
             v1 + h * k1[7], v2 + h * k1[8], v3 + h * k1[9]), um, g)  # fmt: skip
    k3 = _f((q0 + h * k2[3], q1 + h * k2[4], q2 + h * k2[5], q3 + h * k2[6],
             v1 + h * k2[7], v2 + h * k2[8], v3 + h * k2[9]), um, g)  # fmt: skip
    k4 = _f((q0 + dt * k3[3], q1 + dt * k3[4], q2 + dt * k3[5], q3 + dt * k3[6],
             v1 + dt * k3[7], v2 + dt * k3[8], v3 + dt * k3[9]), ub, g)  # fmt: skip
    c = dt / 6.0
    inc = [c * (a + 2.0 * (b + d) + e) for a, b, d, e in zip(k1, k2, k3, k4, strict=True)]
    nq0, nq1, nq2, nq3 = q0 + inc[3], q1 + inc[4], q2 + inc[5], q3 + inc[6]
    n = (nq0 * nq0 + nq1 * nq1 + nq2 * nq2 + nq3 * nq3) ** -0.5
    out[:10] = (
        P1 + inc[0], P2 + inc[1], P3 + inc[2],
        nq0 * n, nq1 * n, nq2 * n, nq3 * n,
        v1 + inc[7], v2 + inc[8], v3 + inc[9],
    )  # fmt: skip
    if out is not x:
        out[10:16] = x[10:16]


def jacobian_flat_index() -> tuple[IndexArray, FloatArray]:
    """Flat indices into a (15, 15) array of the entries :func:`error_jacobian` writes,
    and the constant ``-I`` entries (``d dtheta/d db_g``, ``d dv/d db_a``) as a (15, 15) array."""
    idx: list[int] = []
    for r0, c0 in ((0, 3), (0, 6), (3, 3), (6, 3), (6, 6), (6, 9)):
        idx += [(r0 + i) * N_ERR + c0 + j for i in range(3) for j in range(3)]
    const = np.zeros((N_ERR, N_ERR))
    const[3:6, 9:12] = -np.eye(3)
    const[6:9, 12:15] = -np.eye(3)
    return np.array(idx, dtype=np.intp), const


_FIDX, _FCONST = jacobian_flat_index()


def error_jacobian(
    x: FloatArray, omega: tuple[float, float, float], g: float, F: FloatArray,
    flat_index: IndexArray = _FIDX,
) -> None:  # fmt: skip
    """Fill the variable entries of the error-state Jacobian ``F`` (15, 15) in place.

    x : nominal state (16,); omega : bias-corrected body rate [rad/s] over the step.
    ``F`` must already hold the constant ``-I`` blocks (see :func:`jacobian_flat_index`).
    """
    _, _, _, q0, q1, q2, q3, v1, v2, v3 = x[:10].tolist()
    w1, w2, w3 = omega
    s0, s1, s2, s3 = q0 * q0, q1 * q1, q2 * q2, q3 * q3
    r11, r22, r33 = s0 + s1 - s2 - s3, s0 - s1 + s2 - s3, s0 - s1 - s2 + s3
    r12, r21 = 2 * (q1 * q2 - q0 * q3), 2 * (q1 * q2 + q0 * q3)
    r13, r31 = 2 * (q1 * q3 + q0 * q2), 2 * (q1 * q3 - q0 * q2)
    r23, r32 = 2 * (q2 * q3 - q0 * q1), 2 * (q2 * q3 + q0 * q1)
    gb1, gb2, gb3 = g * r31, g * r32, g * r33
    F.flat[flat_index] = (
        # dP/dtheta = -R [v×]
        r13 * v2 - r12 * v3, r11 * v3 - r13 * v1, r12 * v1 - r11 * v2,
        r23 * v2 - r22 * v3, r21 * v3 - r23 * v1, r22 * v1 - r21 * v2,
        r33 * v2 - r32 * v3, r31 * v3 - r33 * v1, r32 * v1 - r31 * v2,
        # dP/dv = R
        r11, r12, r13, r21, r22, r23, r31, r32, r33,
        # dtheta/dtheta = -[omega×]
        0.0, w3, -w2, -w3, 0.0, w1, w2, -w1, 0.0,
        # dv/dtheta = [g_b×]
        0.0, -gb3, gb2, gb3, 0.0, -gb1, -gb2, gb1, 0.0,
        # dv/dv = -[omega×]
        0.0, w3, -w2, -w3, 0.0, w1, w2, -w1, 0.0,
        # dv/db_g = -[v×]
        0.0, v3, -v2, -v3, 0.0, v1, v2, -v1, 0.0,
    )  # fmt: skip


def boxplus(x: FloatArray, dx: FloatArray) -> FloatArray:
    """``x ⊞ dx``: add an error state (15,) to a nominal state (16,) -> (16,)."""
    out = x.copy()
    out[0:3] += dx[0:3]
    out[3:7] = multiply(x[3:7], quat_from_rotvec(dx[3:6]))
    out[7:16] += dx[6:15]
    return out


def boxminus(x1: FloatArray, x0: FloatArray) -> FloatArray:
    """``x1 ⊟ x0``: the error state (15,) with ``x0 ⊞ (x1 ⊟ x0) == x1``."""
    dq = multiply(np.array([x0[3], -x0[4], -x0[5], -x0[6]]), x1[3:7])
    return np.concatenate((x1[0:3] - x0[0:3], rotvec_from_quat(dq), x1[7:16] - x0[7:16]))
