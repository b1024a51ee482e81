"""Quaternions, rotation matrices and 3-2-1 Euler angles (thesis Ch. 2.3).

Conventions (see :mod:`groundstation` and DESIGN.md):

* A quaternion ``q`` is a ``(4,)`` float array, scalar first ``[q0, q1, q2, q3]``,
  Hamilton product, unit norm.
* ``q`` is the attitude of the body. Its rotation matrix ``dcm_from_quat(q)`` is
  ``eCb``: it maps body (FRD) coordinates to earth (NED) coordinates,
  ``v_e = eCb @ v_b``; ``bCe = eCb.T``. This equals scipy's
  ``Rotation.from_quat(q, scalar_first=True).as_matrix()``.
* Kinematics: ``q_dot = 0.5 * q ⊗ [0, omega] = 0.5 * omega_matrix(omega) @ q`` with
  ``omega`` the body rates in FRD axes [rad/s] (eq. 2.26/2.27).
* Euler angles are the 3-2-1 (yaw ``psi``, pitch ``theta``, roll ``phi``)
  sequence of eq. 2.4/2.6: ``eCb = Rz(psi) @ Ry(theta) @ Rx(phi)``.

Thesis errata resolved here (tested in ``tests/test_model_quaternion.py``): the
matrix printed as eq. 2.20 and labelled ``bCe`` is ``eCb`` in this convention,
and eq. 4.10 prints ``+q1^2`` where gravity in body axes has
``bCe @ [0, 0, g] = g * [2(q1 q3 - q0 q2), 2(q2 q3 + q0 q1), q0^2 - q1^2 - q2^2 + q3^2]``.
"""

from __future__ import annotations

import math

import numpy as np

from groundstation.types import FloatArray

__all__ = [
    "IDENTITY",
    "canonical",
    "conjugate",
    "dcm_from_euler",
    "dcm_from_quat",
    "euler_from_quat",
    "gravity_body",
    "multiply",
    "normalize",
    "omega_matrix",
    "quat_from_dcm",
    "quat_from_euler",
    "quat_from_rotvec",
    "rotate",
    "rotate_inverse",
    "rotvec_from_quat",
    "skew",
]

IDENTITY: FloatArray = np.array([1.0, 0.0, 0.0, 0.0])
"""The identity attitude ``[1, 0, 0, 0]`` (body axes aligned with NED)."""


def skew(v: FloatArray) -> FloatArray:
    """Cross-product matrix ``[v×]`` (eq. 2.19): ``skew(a) @ b == np.cross(a, b)``.

    v : (3,) vector. Returns a (3, 3) array.
    """
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def multiply(p: FloatArray, q: FloatArray) -> FloatArray:
    """Hamilton product ``p ⊗ q`` of two scalar-first quaternions, (4,) -> (4,)."""
    p0, p1, p2, p3 = p
    q0, q1, q2, q3 = q
    return np.array(
        [
            p0 * q0 - p1 * q1 - p2 * q2 - p3 * q3,
            p0 * q1 + p1 * q0 + p2 * q3 - p3 * q2,
            p0 * q2 - p1 * q3 + p2 * q0 + p3 * q1,
            p0 * q3 + p1 * q2 - p2 * q1 + p3 * q0,
        ]
    )


def conjugate(q: FloatArray) -> FloatArray:
    """Conjugate ``[q0, -q1, -q2, -q3]``; the inverse rotation for a unit quaternion."""
    return np.array([q[0], -q[1], -q[2], -q[3]])


def normalize(q: FloatArray) -> FloatArray:
    """Return ``q / |q|``. Raises ``ValueError`` for a zero or non-finite quaternion."""
    n = math.sqrt(float(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]))
    if not (n > 0.0 and math.isfinite(n)):
        raise ValueError(f"cannot normalise quaternion {q!r}")
    return np.asarray(q, dtype=float) / n


def canonical(q: FloatArray) -> FloatArray:
    """Sign-canonical form: ``q`` and ``-q`` are the same attitude; return the one
    with ``q0 >= 0`` (and, when ``q0 == 0``, the first non-zero component positive)."""
    for c in q:
        if c != 0.0:
            return np.asarray(q, dtype=float) * (1.0 if c > 0.0 else -1.0)
    return np.asarray(q, dtype=float)


def dcm_from_quat(q: FloatArray) -> FloatArray:
    """Rotation matrix ``eCb`` (body FRD -> earth NED) of a unit quaternion, (3, 3).

    This is the matrix the thesis prints as eq. 2.20 (there mislabelled ``bCe``).
    """
    q0, q1, q2, q3 = q
    s0, s1, s2, s3 = q0 * q0, q1 * q1, q2 * q2, q3 * q3
    return np.array(
        [
            [s0 + s1 - s2 - s3, 2 * (q1 * q2 - q0 * q3), 2 * (q1 * q3 + q0 * q2)],
            [2 * (q1 * q2 + q0 * q3), s0 - s1 + s2 - s3, 2 * (q2 * q3 - q0 * q1)],
            [2 * (q1 * q3 - q0 * q2), 2 * (q2 * q3 + q0 * q1), s0 - s1 - s2 + s3],
        ]
    )


def quat_from_dcm(eCb: FloatArray) -> FloatArray:
    """Unit quaternion (canonical sign, ``q0 >= 0``) of a rotation matrix ``eCb``.

    Shepperd's method: pivots on the largest of ``q0^2 .. q3^2`` so it is
    accurate for every attitude, including 180° rotations.
    """
    m = eCb
    tr = m[0, 0] + m[1, 1] + m[2, 2]
    cands = (tr, m[0, 0], m[1, 1], m[2, 2])
    i = int(np.argmax(cands))
    if i == 0:
        s = 2.0 * math.sqrt(1.0 + tr)
        q = [0.25 * s, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s]
    elif i == 1:
        s = 2.0 * math.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2])
        q = [(m[2, 1] - m[1, 2]) / s, 0.25 * s, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s]
    elif i == 2:
        s = 2.0 * math.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2])
        q = [(m[0, 2] - m[2, 0]) / s, (m[0, 1] + m[1, 0]) / s, 0.25 * s, (m[1, 2] + m[2, 1]) / s]
    else:
        s = 2.0 * math.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1])
        q = [(m[1, 0] - m[0, 1]) / s, (m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, 0.25 * s]
    return canonical(normalize(np.array(q, dtype=float)))


def rotate(q: FloatArray, v: FloatArray) -> FloatArray:
    """Body -> earth: ``eCb @ v`` (vector part of ``q ⊗ [0, v] ⊗ q*``), (3,) -> (3,)."""
    return dcm_from_quat(q) @ v


def rotate_inverse(q: FloatArray, v: FloatArray) -> FloatArray:
    """Earth -> body: ``bCe @ v = eCb.T @ v``, (3,) -> (3,)."""
    return dcm_from_quat(q).T @ v


def gravity_body(q: FloatArray, g: float) -> FloatArray:
    """Gravity acceleration in body axes, ``bCe @ [0, 0, g]`` [m/s^2], (3,).

    Equals ``g * [2(q1 q3 - q0 q2), 2(q2 q3 + q0 q1), q0^2 - q1^2 - q2^2 + q3^2]``
    (eq. 4.10 with its sign typo on ``q1^2`` corrected).
    """
    q0, q1, q2, q3 = q
    return g * np.array(
        [2 * (q1 * q3 - q0 * q2), 2 * (q2 * q3 + q0 * q1), q0 * q0 - q1 * q1 - q2 * q2 + q3 * q3]
    )


def omega_matrix(omega: FloatArray) -> FloatArray:
    """``Ω(ω)`` of eq. 2.27, (4, 4): ``q_dot = 0.5 * Ω(ω) @ q == 0.5 * q ⊗ [0, ω]``.

    omega : (3,) body rates, FRD [rad/s].
    """
    w1, w2, w3 = omega
    return np.array(
        [
            [0.0, -w1, -w2, -w3],
            [w1, 0.0, w3, -w2],
            [w2, -w3, 0.0, w1],
            [w3, w2, -w1, 0.0],
        ]
    )


def dcm_from_euler(phi: float, theta: float, psi: float) -> FloatArray:
    """``eCb = Rz(psi) @ Ry(theta) @ Rx(phi)`` for 3-2-1 Euler angles [rad] (eq. 2.6)."""
    cf, sf = math.cos(phi), math.sin(phi)
    ct, st = math.cos(theta), math.sin(theta)
    cp, sp = math.cos(psi), math.sin(psi)
    return np.array(
        [
            [ct * cp, -cf * sp + sf * st * cp, sf * sp + cf * st * cp],
            [ct * sp, cf * cp + sf * st * sp, -sf * cp + cf * st * sp],
            [-st, sf * ct, cf * ct],
        ]
    )


def quat_from_euler(phi: float, theta: float, psi: float) -> FloatArray:
    """Unit quaternion of 3-2-1 Euler angles roll ``phi``, pitch ``theta``, yaw ``psi`` [rad].

    ``q = qz(psi) ⊗ qy(theta) ⊗ qx(phi)``, so ``dcm_from_quat(q) == dcm_from_euler(...)``.
    """
    cf, sf = math.cos(phi / 2), math.sin(phi / 2)
    ct, st = math.cos(theta / 2), math.sin(theta / 2)
    cp, sp = math.cos(psi / 2), math.sin(psi / 2)
    return np.array(
        [
            cp * ct * cf + sp * st * sf,
            cp * ct * sf - sp * st * cf,
            cp * st * cf + sp * ct * sf,
            sp * ct * cf - cp * st * sf,
        ]
    )


def euler_from_quat(q: FloatArray) -> tuple[float, float, float]:
    """3-2-1 Euler angles ``(phi, theta, psi)`` [rad] of a unit quaternion.

    ``phi, psi`` in (-pi, pi], ``theta`` in [-pi/2, pi/2]; at gimbal lock
    (``|theta| = pi/2``) the split between ``phi`` and ``psi`` is arbitrary.
    """
    q0, q1, q2, q3 = (float(c) for c in q)
    phi = math.atan2(2 * (q2 * q3 + q0 * q1), q0 * q0 - q1 * q1 - q2 * q2 + q3 * q3)
    theta = math.asin(max(-1.0, min(1.0, -2 * (q1 * q3 - q0 * q2))))
    psi = math.atan2(2 * (q1 * q2 + q0 * q3), q0 * q0 + q1 * q1 - q2 * q2 - q3 * q3)
    return phi, theta, psi


def quat_from_rotvec(rv: FloatArray) -> FloatArray:
    """Exponential map: rotation vector ``rv`` (axis * angle [rad]) -> unit quaternion.

    ``q ⊗ quat_from_rotvec(omega * dt)`` integrates a constant body rate exactly.
    """
    x, y, z = float(rv[0]), float(rv[1]), float(rv[2])
    a2 = x * x + y * y + z * z
    if a2 < 1e-12:  # series: cos(a/2) ~ 1 - a^2/8, sin(a/2)/a ~ 1/2 - a^2/48
        c, s = 1.0 - a2 / 8.0, 0.5 - a2 / 48.0
    else:
        a = math.sqrt(a2)
        c, s = math.cos(0.5 * a), math.sin(0.5 * a) / a
    return np.array([c, s * x, s * y, s * z])


def rotvec_from_quat(q: FloatArray) -> FloatArray:
    """Logarithm map: unit quaternion -> rotation vector [rad], angle in [0, pi].

    Uses the sign-canonical quaternion, so ``q`` and ``-q`` give the same vector.
    """
    w, x, y, z = (float(c) for c in q)
    if w < 0.0:
        w, x, y, z = -w, -x, -y, -z
    n = math.sqrt(x * x + y * y + z * z)
    # small angles: atan2(n, w)/n -> 1/w (w ~ 1), avoiding 0/0
    k = 2.0 * math.atan2(n, w) / n if n >= 1e-12 else (2.0 / w if w > 0.0 else 0.0)
    return np.array([k * x, k * y, k * z])
