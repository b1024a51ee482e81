"""Vicon -> NED/FRD conversion, checked against scipy's Rotation and physical set-ups.

Independent answers: scipy.spatial.transform.Rotation for Euler XYZ and
quaternions; hand-worked vectors for the physical cases (body axes written down
in the Vicon world frame, then checked where they land in NED).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from groundstation.errors import ConfigError
from groundstation.model.quaternion import dcm_from_quat, quat_from_dcm
from groundstation.types import FloatArray
from groundstation.vicon.frames import (
    DEFAULT_BODY_TO_OBJECT,
    DEFAULT_WORLD_TO_NED,
    FrameConversion,
    check_rotation,
    euler_xyz_to_matrix,
    matrix_to_euler_xyz,
    ned_to_vicon,
    vicon_to_ned,
)

RNG_SEED = 20240601


def columns(*vectors: list[float]) -> FloatArray:
    return np.array(vectors, dtype=float).T


def euler_of(r_ov: FloatArray) -> list[float]:
    """What Tracker would send for an object attitude: scipy's intrinsic XYZ angles."""
    return [float(a) for a in Rotation.from_matrix(r_ov).as_euler("XYZ")]


def assert_same_quaternion(q: FloatArray, expected: FloatArray) -> None:
    """Equal as rotations (q and -q), and q itself is in the canonical q0 >= 0 half."""
    assert q[0] >= 0.0
    assert abs(np.linalg.norm(q) - 1.0) < 1e-12
    sign = 1.0 if np.dot(q, expected) >= 0 else -1.0
    np.testing.assert_allclose(q, sign * expected, atol=1e-12)


# --- physical cases with the default configuration -----------------------------


def vicon_object_from_body_axes(bx: list[float], bz: list[float]) -> list[float]:
    """Euler XYZ Tracker reports for body axes given in Vicon world coordinates.

    The default object frame is x forward, y left, z up on the vehicle, so the
    object axes are (bx, -by, -bz) with by = bz x bx (FRD is right-handed).
    """
    x, z = np.array(bx, float), np.array(bz, float)
    y = np.cross(z, x)
    return euler_of(columns(list(x), list(-y), list(-z)))


def test_level_facing_north_is_identity() -> None:
    rot = vicon_object_from_body_axes(bx=[1, 0, 0], bz=[0, 0, -1])
    p, q = vicon_to_ned([0.0, 0.0, 1000.0], rot, DEFAULT_WORLD_TO_NED, DEFAULT_BODY_TO_OBJECT)
    np.testing.assert_allclose(q, [1, 0, 0, 0], atol=1e-15)
    np.testing.assert_allclose(p, [0, 0, -1.0])  # 1 m above the floor is z = -1 in NED


def test_nose_up_in_the_lab_is_positive_pitch() -> None:
    theta = 0.3
    # Nose forward (+x Vicon) and up (+z Vicon); belly forward-down; right wing along -y.
    bx = [math.cos(theta), 0.0, math.sin(theta)]
    bz = [math.sin(theta), 0.0, -math.cos(theta)]
    _, q = vicon_to_ned(
        [0, 0, 0], vicon_object_from_body_axes(bx, bz), DEFAULT_WORLD_TO_NED, DEFAULT_BODY_TO_OBJECT
    )
    e_cb = Rotation.from_quat(q, scalar_first=True).as_matrix()
    np.testing.assert_allclose(e_cb @ [1, 0, 0], [math.cos(theta), 0, -math.sin(theta)], atol=1e-12)
    np.testing.assert_allclose(e_cb @ [0, 1, 0], [0, 1, 0], atol=1e-12)  # right wing east
    yaw, pitch, roll = Rotation.from_quat(q, scalar_first=True).as_euler("ZYX")
    assert pitch == pytest.approx(theta, abs=1e-12)
    assert yaw == pytest.approx(0.0, abs=1e-12)
    assert roll == pytest.approx(0.0, abs=1e-12)


def test_right_side_down_is_positive_roll_and_facing_east_is_yaw_90() -> None:
    phi = 0.4
    # Facing north; right wing (-y Vicon) tilted down (-z Vicon).
    by = [0.0, -math.cos(phi), -math.sin(phi)]
    bx = [1.0, 0.0, 0.0]
    bz = list(np.cross(bx, by))
    _, q = vicon_to_ned(
        [0, 0, 0], vicon_object_from_body_axes(bx, bz), DEFAULT_WORLD_TO_NED, DEFAULT_BODY_TO_OBJECT
    )
    np.testing.assert_allclose(
        Rotation.from_quat(q, scalar_first=True).as_euler("ZYX"), [0, 0, phi], atol=1e-12
    )
    # Level, nose toward Vicon -y (east, since Vicon y points west with the default).
    _, q = vicon_to_ned(
        [0, 0, 0],
        vicon_object_from_body_axes([0, -1, 0], [0, 0, -1]),
        DEFAULT_WORLD_TO_NED,
        DEFAULT_BODY_TO_OBJECT,
    )
    np.testing.assert_allclose(q, [math.cos(math.pi / 4), 0, 0, math.sin(math.pi / 4)], atol=1e-12)


def test_position_default_and_enu_world() -> None:
    p, _ = vicon_to_ned([1000.0, 2000.0, 500.0], [0.1, 0.2, 0.3], DEFAULT_WORLD_TO_NED,
                        DEFAULT_BODY_TO_OBJECT)  # fmt: skip
    np.testing.assert_allclose(p, [1.0, -2.0, -0.5])  # x north, y left = west, z up
    # A lab whose Vicon world is x east, y north, z up (ENU): C_wn swaps x and y, flips z.
    enu_to_ned = columns([0, 1, 0], [1, 0, 0], [0, 0, -1])
    conv = FrameConversion.create(world_to_ned=enu_to_ned)
    p, q = conv.to_ned([1000.0, 0.0, 0.0], vicon_object_from_body_axes([0, 1, 0], [0, 0, -1]))
    np.testing.assert_allclose(p, [0.0, 1.0, 0.0])  # 1 m east
    np.testing.assert_allclose(q, [1, 0, 0, 0], atol=1e-12)  # nose along Vicon y = north


# --- random attitudes against scipy --------------------------------------------


def test_euler_xyz_matches_scipy() -> None:
    angles = np.random.default_rng(RNG_SEED).uniform(-math.pi, math.pi, (200, 3))
    for a in angles:
        expected = Rotation.from_euler("XYZ", a).as_matrix()
        np.testing.assert_allclose(euler_xyz_to_matrix(*a), expected, atol=1e-14)


@pytest.mark.parametrize("defaults", [True, False])
def test_random_attitudes_against_scipy_composition(defaults: bool) -> None:
    rng = np.random.default_rng(RNG_SEED)
    if defaults:
        c_wn, c_bo = DEFAULT_WORLD_TO_NED, DEFAULT_BODY_TO_OBJECT
    else:  # random, non-symmetric configuration: catches transposed or swapped factors
        c_wn = Rotation.random(random_state=rng).as_matrix()
        c_bo = Rotation.random(random_state=rng).as_matrix()
    for _ in range(200):
        rot = rng.uniform(-math.pi, math.pi, 3)
        t_mm = rng.uniform(-3000, 3000, 3)
        p, q = vicon_to_ned(t_mm, rot, c_wn, c_bo)
        r_expected = (
            Rotation.from_matrix(c_wn)
            * Rotation.from_euler("XYZ", rot)
            * Rotation.from_matrix(c_bo)
        )
        assert_same_quaternion(q, r_expected.as_quat(scalar_first=True))
        # Vectors: a body-frame vector goes body -> object -> Vicon world -> NED.
        v_body = rng.normal(size=3)
        v_vicon = Rotation.from_euler("XYZ", rot).apply(c_bo @ v_body)
        e_cb = Rotation.from_quat(q, scalar_first=True)
        np.testing.assert_allclose(e_cb.apply(v_body), c_wn @ v_vicon, atol=1e-12)
        np.testing.assert_allclose(p, c_wn @ t_mm / 1000.0, atol=1e-12)


@pytest.mark.parametrize(
    "rotvec",
    [
        [math.pi, 0, 0],  # trace -1: each Shepperd branch in turn
        [0, math.pi, 0],
        [0, 0, math.pi],
        [2.0, -2.0, 1.0],
        [0, 0, 0],
        [1e-9, 0, 0],
    ],
)
def test_quat_from_dcm_every_branch(rotvec: list[float]) -> None:
    r = Rotation.from_rotvec(rotvec)
    q = quat_from_dcm(r.as_matrix())
    assert_same_quaternion(q, r.as_quat(scalar_first=True))
    np.testing.assert_allclose(dcm_from_quat(q), r.as_matrix(), atol=1e-14)


def test_quaternions_random_against_scipy() -> None:
    for r in Rotation.random(500, random_state=RNG_SEED):
        q = quat_from_dcm(r.as_matrix())
        assert_same_quaternion(q, r.as_quat(scalar_first=True))
        np.testing.assert_allclose(dcm_from_quat(q), r.as_matrix(), atol=1e-14)


# --- inverse ------------------------------------------------------------------


@pytest.mark.parametrize("defaults", [True, False])
def test_ned_to_vicon_to_ned_round_trip(defaults: bool) -> None:
    rng = np.random.default_rng(RNG_SEED + 1)
    if defaults:
        conv = FrameConversion.create()
    else:
        conv = FrameConversion.create(
            Rotation.random(random_state=rng).as_matrix(),
            Rotation.random(random_state=rng).as_matrix(),
        )
    for r in Rotation.random(300, random_state=rng):
        p = rng.uniform(-2, 2, 3)
        q = r.as_quat(scalar_first=True)
        q = q if q[0] >= 0 else -q
        t_mm, rot = conv.to_vicon(p, q)
        p2, q2 = conv.to_ned(t_mm, rot)
        np.testing.assert_allclose(p2, p, atol=1e-12)
        assert_same_quaternion(q2, q)
        # The Euler angles are exactly what scipy extracts for the same object attitude.
        r_ov = conv.world_to_ned.T @ r.as_matrix() @ conv.body_to_object.T
        np.testing.assert_allclose(rot, euler_of(r_ov), atol=1e-9)


def test_vicon_to_ned_to_vicon_round_trip_in_principal_range() -> None:
    rng = np.random.default_rng(RNG_SEED + 2)
    for _ in range(300):
        rot = (rng.uniform(-3.1, 3.1), rng.uniform(-1.5, 1.5), rng.uniform(-3.1, 3.1))
        t_mm = tuple(rng.uniform(-3000, 3000, 3))
        p, q = vicon_to_ned(t_mm, rot, DEFAULT_WORLD_TO_NED, DEFAULT_BODY_TO_OBJECT)
        t2, rot2 = ned_to_vicon(p, q, DEFAULT_WORLD_TO_NED, DEFAULT_BODY_TO_OBJECT)
        np.testing.assert_allclose(t2, t_mm, atol=1e-9)
        np.testing.assert_allclose(rot2, rot, atol=1e-9)


@pytest.mark.parametrize("ry", [math.pi / 2, -math.pi / 2])
def test_gimbal_lock_gives_the_same_attitude(ry: float) -> None:
    m = euler_xyz_to_matrix(0.7, ry, -0.2)
    rx2, ry2, rz2 = matrix_to_euler_xyz(m)
    assert rz2 == 0.0
    assert ry2 == pytest.approx(ry)
    np.testing.assert_allclose(euler_xyz_to_matrix(rx2, ry2, rz2), m, atol=1e-12)


# --- configuration ------------------------------------------------------------


@pytest.mark.parametrize(
    "matrix",
    [
        np.eye(2),
        np.diag([1.0, 1.0, -1.0]),  # a reflection, det -1
        np.diag([1.0, 1.0, 1.1]),  # not orthonormal
        np.full((3, 3), np.nan),
    ],
)
def test_check_rotation_refuses_non_rotations(matrix: FloatArray) -> None:
    with pytest.raises(ConfigError, match="world_to_ned"):
        check_rotation("world_to_ned", matrix)


def test_check_rotation_accepts_rounded_entries_and_orthonormalises() -> None:
    rounded = [[0.7071, -0.7071, 0.0], [0.7071, 0.7071, 0.0], [0.0, 0.0, 1.0]]  # 45 deg about z
    m = check_rotation("body_to_object", rounded)
    np.testing.assert_allclose(m.T @ m, np.eye(3), atol=1e-15)
    np.testing.assert_allclose(
        m, Rotation.from_euler("z", 45, degrees=True).as_matrix(), atol=1e-12
    )
    assert not m.flags.writeable
