"""Quaternion and frame helpers against scipy's Rotation and the thesis's equations."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from groundstation.model import quaternion as Q  # noqa: N812  (short alias, as in scipy docs)

RNG = np.random.default_rng(20240611)
QUATS = [Q.normalize(RNG.normal(size=4)) for _ in range(200)]


def _euler_dcm_eq_2_4(phi: float, theta: float, psi: float) -> np.ndarray:
    """bCe of eq. 2.4 built as the thesis does: Cx(phi) Cy(theta) Cz(psi) (eq. 2.1-2.3)."""
    c, s = math.cos, math.sin
    Cx = np.array([[1, 0, 0], [0, c(phi), s(phi)], [0, -s(phi), c(phi)]])
    Cy = np.array([[c(theta), 0, -s(theta)], [0, 1, 0], [s(theta), 0, c(theta)]])
    Cz = np.array([[c(psi), s(psi), 0], [-s(psi), c(psi), 0], [0, 0, 1]])
    return Cx @ Cy @ Cz


@pytest.mark.parametrize("q", QUATS[:50])
def test_dcm_matches_scipy(q: np.ndarray) -> None:
    # Independent answer: scipy's scalar-first quaternion -> matrix is eCb (DESIGN.md).
    expected = Rotation.from_quat(q, scalar_first=True).as_matrix()
    np.testing.assert_allclose(Q.dcm_from_quat(q), expected, atol=1e-12)


def test_multiply_matches_scipy_composition() -> None:
    for p, q in zip(QUATS[:100], QUATS[100:], strict=True):
        expected = (
            Rotation.from_quat(p, scalar_first=True) * Rotation.from_quat(q, scalar_first=True)
        ).as_quat(scalar_first=True)
        got = Q.multiply(p, q)
        np.testing.assert_allclose(Q.canonical(got), Q.canonical(expected), atol=1e-12)
        # the product's DCM is the product of the DCMs (Hamilton convention)
        np.testing.assert_allclose(
            Q.dcm_from_quat(got), Q.dcm_from_quat(p) @ Q.dcm_from_quat(q), atol=1e-12
        )


def test_conjugate_is_inverse_and_rotate() -> None:
    for q in QUATS[:50]:
        np.testing.assert_allclose(Q.multiply(q, Q.conjugate(q)), Q.IDENTITY, atol=1e-12)
        v = RNG.normal(size=3)
        r = Rotation.from_quat(q, scalar_first=True)
        np.testing.assert_allclose(Q.rotate(q, v), r.apply(v), atol=1e-12)
        np.testing.assert_allclose(Q.rotate_inverse(q, v), r.inv().apply(v), atol=1e-12)
        # rotate == vector part of q ⊗ [0, v] ⊗ q*
        qv = Q.multiply(Q.multiply(q, np.r_[0.0, v]), Q.conjugate(q))
        np.testing.assert_allclose(Q.rotate(q, v), qv[1:], atol=1e-12)


def test_quat_from_dcm_roundtrip_including_half_turns() -> None:
    extra = [np.array([0.0, 1.0, 0.0, 0.0]), np.array([0.0, 0.0, 0.0, 1.0]),
             Q.normalize(np.array([1e-9, 1.0, 1.0, 0.0]))]
    for q in [*QUATS, *extra]:
        back = Q.quat_from_dcm(Q.dcm_from_quat(q))
        np.testing.assert_allclose(back, Q.canonical(q), atol=1e-9)
        assert back[0] >= 0.0


@pytest.mark.parametrize("q", QUATS[:50])
def test_quaternion_dcm_equals_321_euler_dcm_erratum_2_20(q: np.ndarray) -> None:
    # DESIGN.md erratum: eq. 2.20 is labelled bCe, but in our convention it is eCb.
    # For the same attitude, the Euler DCM of eq. 2.4 (bCe = Cx Cy Cz) must equal dcm.T.
    phi, theta, psi = Q.euler_from_quat(q)
    bCe = _euler_dcm_eq_2_4(phi, theta, psi)
    np.testing.assert_allclose(Q.dcm_from_quat(q).T, bCe, atol=1e-12)
    np.testing.assert_allclose(Q.dcm_from_euler(phi, theta, psi), bCe.T, atol=1e-12)
    # and scipy agrees on the 3-2-1 angles (intrinsic ZYX = yaw, pitch, roll)
    zyx = Rotation.from_quat(q, scalar_first=True).as_euler("ZYX")
    np.testing.assert_allclose([psi, theta, phi], zyx, atol=1e-9)


def test_euler_roundtrip_and_sign_of_pitch() -> None:
    for _ in range(100):
        phi, psi = RNG.uniform(-math.pi, math.pi, size=2)
        theta = RNG.uniform(-1.5, 1.5)
        q = Q.quat_from_euler(phi, theta, psi)
        np.testing.assert_allclose(Q.euler_from_quat(q), (phi, theta, psi), atol=1e-9)
    # nose up: positive pitch rotates body x (forward) toward earth -z (up)
    fwd = Q.rotate(Q.quat_from_euler(0.0, 0.3, 0.0), np.array([1.0, 0.0, 0.0]))
    assert fwd[2] == pytest.approx(-math.sin(0.3))


@pytest.mark.parametrize("q", QUATS[:50])
def test_gravity_in_body_axes(q: np.ndarray) -> None:
    # bCe @ [0,0,g] = g [2(q1q3-q0q2), 2(q2q3+q0q1), q0^2-q1^2-q2^2+q3^2] (eq. 4.10 corrected)
    g = 9.82
    q0, q1, q2, q3 = q
    expected = g * np.array(
        [2 * (q1 * q3 - q0 * q2), 2 * (q2 * q3 + q0 * q1), q0**2 - q1**2 - q2**2 + q3**2]
    )
    np.testing.assert_allclose(Q.dcm_from_quat(q).T @ np.array([0, 0, g]), expected, atol=1e-12)
    np.testing.assert_allclose(Q.gravity_body(q, g), expected, atol=1e-12)
    via_scipy = Rotation.from_quat(q, scalar_first=True).inv().apply([0, 0, g])
    np.testing.assert_allclose(expected, via_scipy, atol=1e-12)


def test_omega_matrix_is_right_product_with_rate() -> None:
    for q in QUATS[:50]:
        w = RNG.normal(size=3)
        np.testing.assert_allclose(
            Q.omega_matrix(w) @ q, Q.multiply(q, np.r_[0.0, w]), atol=1e-12
        )


def test_omega_matrix_integrates_like_scipy_body_rate() -> None:
    # Integrating q_dot = 0.5 Ω(ω) q for a constant body rate equals right-multiplying
    # by the rotation about ω·t (scipy's from_rotvec), i.e. ω is expressed in body axes.
    from scipy.linalg import expm

    q = QUATS[0]
    w = np.array([0.3, -0.7, 1.1])
    t = 0.9
    got = expm(0.5 * Q.omega_matrix(w) * t) @ q
    r = Rotation.from_quat(q, scalar_first=True) * Rotation.from_rotvec(w * t)
    np.testing.assert_allclose(Q.canonical(got), Q.canonical(r.as_quat(scalar_first=True)),
                               atol=1e-12)
    np.testing.assert_allclose(Q.multiply(q, Q.quat_from_rotvec(w * t)), got, atol=1e-12)


def test_rotvec_exp_log_match_scipy() -> None:
    for q in QUATS[:50]:
        rv = Rotation.from_quat(q, scalar_first=True).as_rotvec()
        np.testing.assert_allclose(Q.rotvec_from_quat(q), rv, atol=1e-9)
        np.testing.assert_allclose(Q.canonical(Q.quat_from_rotvec(rv)), Q.canonical(q), atol=1e-12)
    tiny = np.array([1e-9, -2e-9, 3e-9])
    np.testing.assert_allclose(Q.rotvec_from_quat(Q.quat_from_rotvec(tiny)), tiny, rtol=1e-6)


def test_skew_normalize_canonical() -> None:
    a, b = RNG.normal(size=3), RNG.normal(size=3)
    np.testing.assert_allclose(Q.skew(a) @ b, np.cross(a, b), atol=1e-15)
    assert np.linalg.norm(Q.normalize(np.array([2.0, 0, 0, 0]))) == pytest.approx(1.0)
    with pytest.raises(ValueError):
        Q.normalize(np.zeros(4))
    np.testing.assert_array_equal(Q.canonical(np.array([-0.5, 0.5, -0.5, 0.5])),
                                  [0.5, -0.5, 0.5, -0.5])
    np.testing.assert_array_equal(Q.canonical(np.array([0.0, -1.0, 0, 0])), [0.0, 1.0, 0, 0])
