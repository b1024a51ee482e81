"""Conversion between Vicon's world/object frames and the project's NED/FRD pose.

Conventions (all pure functions; no state):

* **Vicon input.** Translation ``t = (x, y, z)`` [mm] of the object origin in the
  Vicon world frame (z up; x forward, y left by default). Rotation ``(rx, ry, rz)``
  [rad], Euler angles *intrinsic X then Y then Z*: the object's attitude in the
  Vicon world is ``R_ov = Rx(rx) @ Ry(ry) @ Rz(rz)``, which maps object
  coordinates to Vicon-world coordinates (scipy:
  ``Rotation.from_euler("XYZ", [rx, ry, rz]).as_matrix()``).
* **Configuration.** ``C_wn = world_to_ned`` (3, 3) maps Vicon-world coordinates
  to NED coordinates, ``v_ned = C_wn @ v_vicon``. ``C_bo = body_to_object`` (3, 3)
  maps FRD body coordinates to object coordinates, ``v_obj = C_bo @ v_body``.
  Both default to 180 degrees about x, ``diag(1, -1, -1)``: Vicon world x-forward,
  y-left, z-up becomes north, east, down, and an object defined x-forward,
  y-left, z-up (FLU) becomes FRD.
* **Output.** ``p_ned = C_wn @ t / 1000`` [m] and
  ``eCb = C_wn @ R_ov @ C_bo`` (body FRD -> earth NED), returned as a unit
  quaternion, scalar first ``[q0, q1, q2, q3]`` (Hamilton), ``R(q) = eCb``, sign
  chosen so that ``q0 >= 0`` (scipy:
  ``Rotation.from_quat(q, scalar_first=True).as_matrix() == eCb``).
* **Inverse** (for the virtual Vicon): ``t = 1000 * C_wn.T @ p_ned``,
  ``R_ov = C_wn.T @ eCb @ C_bo.T``, decomposed into Euler XYZ with
  ``rx, rz`` in ``(-pi, pi]`` and ``ry`` in ``[-pi/2, pi/2]``; at gimbal lock
  (``|ry| = pi/2``) ``rz = 0`` is chosen.

Example with the defaults: body x along Vicon +x and body z along Vicon -z is
level facing north, ``q = [1, 0, 0, 0]``; and Vicon then reports rotations
exactly ``(0, 0, 0)``, which the tracker reads as lost tracking if the position is
also held, so a noise-free simulator must not sit exactly level facing north.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from groundstation.errors import ConfigError
from groundstation.model.quaternion import dcm_from_quat, normalize, quat_from_dcm
from groundstation.types import FloatArray

Vector3 = tuple[float, float, float]
VectorLike = Sequence[float] | FloatArray
"""A (3,) or (4,) vector given as a float sequence or a numpy array."""

_ORTHONORMAL_TOL = 1e-4
_GIMBAL_EPS = 1e-12


def rotation_x(angle: float) -> FloatArray:
    """Return Rx(angle) (3, 3): the active rotation by ``angle`` [rad] about x."""
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def _read_only(m: FloatArray) -> FloatArray:
    m.setflags(write=False)
    return m


DEFAULT_WORLD_TO_NED: FloatArray = _read_only(np.diag([1.0, -1.0, -1.0]))
"""Vicon world (x forward, y left, z up) -> NED: Rx(180 deg) = ``diag(1, -1, -1)``."""
DEFAULT_BODY_TO_OBJECT: FloatArray = _read_only(np.diag([1.0, -1.0, -1.0]))
"""FRD body -> object defined x forward, y left, z up: Rx(180 deg) = ``diag(1, -1, -1)``."""


def check_rotation(name: str, matrix: npt.ArrayLike) -> FloatArray:
    """Validate a configured rotation matrix and return it exactly orthonormal.

    matrix : (3, 3), orthonormal to 1e-4 with determinant +1 (rounded entries
        such as 0.7071 are accepted and projected onto the nearest rotation).
    Raises ConfigError naming ``name`` and what was wrong.
    """
    m = np.asarray(matrix, dtype=np.float64)
    if m.shape != (3, 3):
        raise ConfigError(
            f"{name}: expected shape (3, 3), found {m.shape}", [(name, m.tolist(), "shape")]
        )
    if not np.all(np.isfinite(m)):
        raise ConfigError(f"{name}: non-finite entries", [(name, m.tolist(), "finite")])
    error = float(np.max(np.abs(m.T @ m - np.eye(3))))
    if error > _ORTHONORMAL_TOL or np.linalg.det(m) <= 0.0:
        raise ConfigError(
            f"{name}: not a rotation (|M^T M - I| = {error:.2g}, det = {np.linalg.det(m):.3g})",
            [(name, m.tolist(), "rotation matrix with det +1")],
        )
    u, _, vt = np.linalg.svd(m)
    return _read_only(u @ vt)


def euler_xyz_to_matrix(rx: float, ry: float, rz: float) -> FloatArray:
    """Return ``Rx(rx) @ Ry(ry) @ Rz(rz)`` (3, 3); angles [rad], intrinsic X-Y-Z."""
    cx, sx = math.cos(rx), math.sin(rx)
    cy, sy = math.cos(ry), math.sin(ry)
    cz, sz = math.cos(rz), math.sin(rz)
    return np.array(
        [
            [cy * cz, -cy * sz, sy],
            [cx * sz + sx * sy * cz, cx * cz - sx * sy * sz, -sx * cy],
            [sx * sz - cx * sy * cz, sx * cz + cx * sy * sz, cx * cy],
        ]
    )


def rotation_from_euler_deg(euler_xyz_deg: Sequence[float]) -> FloatArray:
    """The (3, 3) rotation ``Rx(a) @ Ry(b) @ Rz(c)`` of intrinsic X-Y-Z Euler angles
    ``(a, b, c)`` [deg], as the configuration gives ``vicon.world_to_ned`` and
    ``vicon.body_to_object`` (scipy's ``Rotation.from_euler("XYZ", ..., degrees=True)``)."""
    from scipy.spatial.transform import Rotation

    return np.asarray(Rotation.from_euler("XYZ", list(euler_xyz_deg), degrees=True).as_matrix())


def matrix_to_euler_xyz(m: FloatArray) -> Vector3:
    """Inverse of :func:`euler_xyz_to_matrix` for a rotation matrix ``m`` (3, 3).

    Returns ``(rx, ry, rz)`` [rad] with rx, rz in (-pi, pi], ry in [-pi/2, pi/2];
    at gimbal lock (cos ry = 0) rz = 0.
    """
    cos_ry = math.hypot(m[0, 0], m[0, 1])
    ry = math.atan2(m[0, 2], cos_ry)
    if cos_ry > _GIMBAL_EPS:
        return math.atan2(-m[1, 2], m[2, 2]), ry, math.atan2(-m[0, 1], m[0, 0])
    # Rows 1 and 2 of column 0/1 hold rx + rz (ry = +pi/2) or rx - rz (ry = -pi/2).
    return math.atan2(m[2, 1], m[1, 1]), ry, 0.0


def vicon_to_ned(
    translation_mm: VectorLike,
    rotation_xyz: VectorLike,
    world_to_ned: FloatArray,
    body_to_object: FloatArray,
) -> tuple[FloatArray, FloatArray]:
    """Convert one Vicon object pose to ``(p_ned (3,) [m], q (4,) scalar first, q0 >= 0)``.

    translation_mm : (3,) Vicon world [mm]; rotation_xyz : (rx, ry, rz) [rad]
    world_to_ned, body_to_object : (3, 3) rotations C_wn and C_bo (not validated
    here: pass them through :func:`check_rotation` once).
    """
    position = world_to_ned @ np.array(translation_mm, dtype=np.float64) * 1e-3
    r_ov = euler_xyz_to_matrix(rotation_xyz[0], rotation_xyz[1], rotation_xyz[2])
    return position, quat_from_dcm(world_to_ned @ r_ov @ body_to_object)


def ned_to_vicon(
    position: VectorLike,
    quaternion: VectorLike,
    world_to_ned: FloatArray,
    body_to_object: FloatArray,
) -> tuple[Vector3, Vector3]:
    """Inverse of :func:`vicon_to_ned`: NED pose -> (translation [mm], Euler XYZ [rad]).

    position : (3,) NED [m]; quaternion : (4,) scalar first, R(q) = eCb.
    """
    t = world_to_ned.T @ np.asarray(position, dtype=np.float64) * 1e3
    e_c_b = dcm_from_quat(normalize(np.asarray(quaternion, dtype=float)))
    r_ov = world_to_ned.T @ e_c_b @ body_to_object.T
    return (float(t[0]), float(t[1]), float(t[2])), matrix_to_euler_xyz(r_ov)


@dataclass(frozen=True, slots=True)
class FrameConversion:
    """The two configured rotations, validated once; thin wrappers around the functions.

    world_to_ned : (3, 3) C_wn, Vicon world -> NED coordinates
    body_to_object : (3, 3) C_bo, FRD body -> Vicon object coordinates
    """

    world_to_ned: FloatArray
    body_to_object: FloatArray

    @classmethod
    def create(
        cls,
        world_to_ned: npt.ArrayLike = DEFAULT_WORLD_TO_NED,
        body_to_object: npt.ArrayLike = DEFAULT_BODY_TO_OBJECT,
    ) -> FrameConversion:
        """Validate both matrices (ConfigError if not rotations) and build the conversion."""
        return cls(
            check_rotation("world_to_ned", world_to_ned),
            check_rotation("body_to_object", body_to_object),
        )

    def to_ned(
        self, translation_mm: VectorLike, rotation_xyz: VectorLike
    ) -> tuple[FloatArray, FloatArray]:
        """Vicon (mm, Euler XYZ rad) -> (p_ned (3,) [m], q (4,) scalar first)."""
        return vicon_to_ned(translation_mm, rotation_xyz, self.world_to_ned, self.body_to_object)

    def to_vicon(self, position: VectorLike, quaternion: VectorLike) -> tuple[Vector3, Vector3]:
        """NED pose -> (Vicon translation (x, y, z) [mm], Euler XYZ (rx, ry, rz) [rad])."""
        return ned_to_vicon(position, quaternion, self.world_to_ned, self.body_to_object)
