"""Discrete LQR design with an appended reference model (thesis Ch. 9).

Sign convention as in the thesis (eq. 9.7, 9.12): the control law is
``u = K x`` with ``K = -(R + Γᵀ P Γ)⁻¹ Γᵀ P Φ``, so K carries the minus sign
(python-control's ``dlqr`` returns ``-K``).

The tracking problem (eq. 9.16-9.21) appends the reference model
``x_r(k+1) = Φ_r x_r(k)``, ``r = H_r x_r`` to the plant and weights the error
``e = H_r x_r - H_s x_s``. The reference states are uncontrollable with
eigenvalues on the unit circle, so a generic DARE solver refuses the
augmented pair (its Hamiltonian pencil has unit-circle eigenvalues). The
augmented Riccati equation is therefore solved blockwise, which is exact and
is the same fixed point Algorithm 3 iterates towards:

* ``P_aa`` from the DARE of the (stabilisable) plant part with ``Q_aa``;
* the cross term from the Stein equation
  ``P_ar = Q_ar + Φ_clᵀ (P_aa E + P_ar Φ_r)`` with ``Φ_cl = Φ_a + Γ_a K_a``,
  uniquely solvable because ``|λ(Φ_cl)| < 1`` and ``|λ(Φ_r)| = 1``;
* ``K_r = -(R + Γᵀ P_aa Γ)⁻¹ Γᵀ (P_aa E + P_ar Φ_r)``.

``P_rr`` is never needed (it does not enter the gains, and it is unbounded
when following the reference costs input forever, e.g. a climb against the
induced inflow). "Plant part" ``a`` means the vehicle states, optionally with
integrators of the error appended (beyond the thesis: zero steady-state error
under constant disturbances); ``E`` is how the reference drives them.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np
import numpy.typing as npt
import scipy.linalg

from groundstation.errors import ControlError
from groundstation.types import FloatArray

ReferenceKind = Literal["position", "velocity"]

_Key = tuple[tuple[tuple[int, ...], bytes], ...]
"""Arrays as a hashable key: each one's shape and float64 bytes."""

_MEMO_SIZE = 64
"""Designs remembered per process. A design is a pure function of its matrices, and every
controller built from one configuration asks for the same ones (``gs eval`` builds one per
flight, five flights of a scenario on the same design model): the matrix exponentials and
the Riccati solution cost tens of milliseconds each time. Callers get copies."""


def _key(*arrays: FloatArray) -> _Key:
    return tuple((a.shape, np.ascontiguousarray(a, dtype=float).tobytes()) for a in arrays)


def _arrays(key: _Key) -> list[FloatArray]:
    return [np.frombuffer(data, dtype=float).reshape(shape) for shape, data in key]


def _f64(x: object) -> FloatArray:
    """``x`` as a float64 array (numpy's stubs widen linalg results to floating[Any])."""
    return np.asarray(x, dtype=np.float64)


def check_shape(name: str, matrix: FloatArray, shape: tuple[int, int]) -> FloatArray:
    """Return ``matrix`` as a finite float array of ``shape`` or raise ControlError naming it."""
    arr = np.asarray(matrix, dtype=float)
    if arr.shape != shape:
        raise ControlError(f"{name} must have shape {shape}, found {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ControlError(f"{name} has non-finite entries")
    return arr


def weight_matrix(values: Sequence[float], n: int, name: str) -> FloatArray:
    """An n x n weight given as its n diagonal entries or in full; ControlError otherwise."""
    arr = np.asarray(values, dtype=float)
    if arr.shape == (n,):
        return np.diag(arr)
    if arr.shape == (n, n):
        return arr
    raise ControlError(f"{name} must be {n} diagonal entries or {n}x{n}, found shape {arr.shape}")


def saturate(u: FloatArray, lo: Sequence[float], hi: Sequence[float]) -> list[float] | None:
    """Clip ``u`` (4,) in place to ``[lo, hi]``; returns the clipped values as Python floats
    if any was out of range, else None (scalar Python: numpy's call overhead on 4 values
    costs more than the arithmetic)."""
    raw = u.tolist()
    clipped = [min(max(x, a), b) for x, a, b in zip(raw, lo, hi, strict=True)]
    if clipped == raw:
        return None
    u[:] = clipped
    return clipped


def check_weight(name: str, matrix: FloatArray, n: int, *, definite: bool) -> FloatArray:
    """A symmetric positive (semi-)definite n x n weight, or ControlError."""
    arr = check_shape(name, matrix, (n, n))
    if not np.allclose(arr, arr.T, rtol=1e-10, atol=1e-12):
        raise ControlError(f"{name} must be symmetric")
    lowest = float(np.min(np.linalg.eigvalsh(arr))) if n else 0.0
    if (definite and lowest <= 0.0) or lowest < -1e-12 * max(1.0, float(np.max(np.abs(arr)))):
        kind = "positive definite" if definite else "positive semi-definite"
        raise ControlError(f"{name} must be {kind} (smallest eigenvalue {lowest:.3g})")
    return arr


def discretise(A: FloatArray, B: FloatArray, dt: float) -> tuple[FloatArray, FloatArray]:
    """Exact zero-order-hold discretisation: ``Φ = e^{A dt}``, ``Γ = ∫_0^dt e^{A s} ds B``.

    Computed as one matrix exponential of ``[[A, B], [0, 0]] dt`` (Van Loan),
    the same as ``scipy.signal.cont2discrete(..., method="zoh")``.
    """
    Phi, Gamma = _discretise(_key(_f64(A), _f64(B)), float(dt))
    return Phi.copy(), Gamma.copy()


@functools.lru_cache(maxsize=_MEMO_SIZE)
def _discretise(key: _Key, dt: float) -> tuple[FloatArray, FloatArray]:
    A, B = _arrays(key)
    n, m = B.shape
    block = np.zeros((n + m, n + m))
    block[:n, :n] = A
    block[:n, n:] = B
    e = scipy.linalg.expm(block * dt)
    return e[:n, :n], e[:n, n:]


def discretise_delayed(A: FloatArray, B: FloatArray, period: float,
                       delay: float) -> tuple[FloatArray, FloatArray, int]:
    """ZOH discretisation with an input transport delay: ``(Φ_d, Γ_d, l)``.

    The input is held over each ``period`` [s] and reaches the plant ``delay`` [s]
    after it is sent. With ``delay = (l - 1) period + m``, ``0 < m <= period``, the
    input acting over one period is ``u(k-l)`` for its first ``m`` seconds and
    ``u(k-l+1)`` for the rest (Åström and Wittenmark, *Computer-Controlled
    Systems*, Ch. 2.3)::

        x(k+1) = Φ x(k) + Γ_1 u(k-l+1) + Γ_0 u(k-l)
        Γ_1 = ∫_0^{period-m} e^{As} ds B,    Γ_0 = e^{A (period-m)} ∫_0^m e^{As} ds B

    The returned model's state is ``[x; u(k-1); ...; u(k-l)]`` (n + l m_in); its
    input is ``u(k)``, the command sent now. ``delay = 0`` gives the plain ZOH
    model (``l = 0``).
    """
    n, m_in = B.shape
    if not (period > 0.0 and delay >= 0.0 and math.isfinite(delay)):
        raise ControlError(f"need period > 0 and a finite delay >= 0, found {period!r}, "
                           f"{delay!r}")
    Phi, Gamma = discretise(A, B, period)
    if delay == 0.0:
        return Phi, Gamma, 0
    past = max(1, math.ceil(delay / period - 1e-12))
    m = delay - (past - 1) * period
    Gamma_m = discretise(A, B, m)[1]
    Phi_rest, Gamma_1 = discretise(A, B, period - m)
    Gamma_0 = Phi_rest @ Gamma_m
    size = n + past * m_in
    Phi_d = np.zeros((size, size))
    Gamma_d = np.zeros((size, m_in))
    Phi_d[:n, :n] = Phi
    Phi_d[:n, n + (past - 1) * m_in:] = Gamma_0  # u(k-l), the oldest
    if past == 1:
        Gamma_d[:n] = Gamma_1  # u(k-l+1) is the command sent now
    else:
        Phi_d[:n, n + (past - 2) * m_in: n + (past - 1) * m_in] = Gamma_1
    Gamma_d[n:n + m_in] = np.eye(m_in)  # u(k-1) <- u(k)
    for j in range(1, past):  # u(k-j-1) <- u(k-j)
        Phi_d[n + j * m_in: n + (j + 1) * m_in, n + (j - 1) * m_in: n + j * m_in] = np.eye(m_in)
    return Phi_d, Gamma_d, past


def dlqr(Phi: FloatArray, Gamma: FloatArray, Q: FloatArray,
         R: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Infinite-horizon discrete LQR: ``(K, P)`` with ``u = K x`` (thesis sign, eq. 9.12).

    ``P`` solves the DARE (scipy ``solve_discrete_are``). Raises ControlError
    if the pair is not stabilisable / the weights not detectable.
    """
    K, P = _dlqr(_key(_f64(Phi), _f64(Gamma), _f64(Q), _f64(R)))
    return K.copy(), P.copy()


@functools.lru_cache(maxsize=_MEMO_SIZE)
def _dlqr(key: _Key) -> tuple[FloatArray, FloatArray]:
    Phi, Gamma, Q, R = _arrays(key)
    try:
        P = scipy.linalg.solve_discrete_are(Phi, Gamma, Q, R)
    except (np.linalg.LinAlgError, ValueError) as exc:
        raise ControlError(f"discrete Riccati equation has no stabilising solution: {exc}") from exc
    K = -np.linalg.solve(R + Gamma.T @ P @ Gamma, Gamma.T @ P @ Phi)
    return K, P


def riccati_iteration(
    Phi: FloatArray, Gamma: FloatArray, Q: FloatArray, R: FloatArray,
    *, tol: float = 1e-5, max_iter: int = 100_000,
) -> tuple[FloatArray, int]:
    """Thesis Algorithm 3: iterate P from Q until ``‖K - K'‖ < tol``; returns ``(K, iterations)``.

    Works on the full augmented system including the uncontrollable reference
    states (only K has to converge). Kept as an independent check of
    :func:`design_tracking_lqr`; raises ControlError if it does not converge.
    """
    P = Q.copy()
    K = np.zeros((Gamma.shape[1], Phi.shape[0]))
    for k in range(1, max_iter + 1):
        K_new = _f64(-np.linalg.solve(R + Gamma.T @ P @ Gamma, Gamma.T @ P @ Phi))
        Acl = Phi + Gamma @ K_new
        P = Q + K_new.T @ R @ K_new + Acl.T @ P @ Acl
        if np.linalg.norm(K_new - K) < tol:
            return K_new, k
        K = K_new
    raise ControlError(f"Algorithm 3 did not converge in {max_iter} iterations")


def reference_model(kind: ReferenceKind, n_out: int) -> tuple[FloatArray, FloatArray]:
    """``(Φ_r, H_r)`` of the reference model for ``n_out`` outputs.

    position: constant position, ``x_r = r``, ``Φ_r = I``, ``H_r = I``.
    velocity: constant velocity (eq. 9.22-9.26), ``x_r = [r(k); r(k-1)]``,
    ``Φ_r = [[2I, -I], [I, 0]]``, ``H_r = [I, 0]``.
    """
    eye = np.eye(n_out)
    if kind == "position":
        return eye.copy(), eye.copy()
    if kind == "velocity":
        zero = np.zeros((n_out, n_out))
        return np.block([[2 * eye, -eye], [eye, zero]]), np.hstack([eye, zero])
    raise ControlError(f"unknown reference model {kind!r}; use 'position' or 'velocity'")


@dataclass(frozen=True, slots=True)
class TrackingGains:
    """Gains of ``u = K_s x_s + K_i x_i + K_r x_r`` (thesis eq. 9.21 plus integral action).

    K_s : (m, n_s) state feedback; K_i : (m, k) feedback of the k integrated
    errors ``x_i(k+1) = x_i(k) + dt (r - H_s x_s)`` (zeros(m, 0) without integral
    action); K_r : (m, n_r) reference feed-forward; Phi_r, H_r : the reference
    model; closed_loop_poles : eigenvalues of the plant part under feedback.
    """

    K_s: FloatArray
    K_i: FloatArray
    K_r: FloatArray
    Phi_r: FloatArray
    H_r: FloatArray
    closed_loop_poles: npt.NDArray[np.complex128]


def tracking_system(
    Phi_s: FloatArray, Gamma_s: FloatArray, H_s: FloatArray, Phi_r: FloatArray, H_r: FloatArray,
    Q_e: FloatArray, dt: float, Q_i: FloatArray | None = None,
    integrate: Sequence[int] | None = None,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
    """Augmented ``(Φ_a, Γ_a, E, Q_aa, Q_ar)`` of eq. 9.16-9.20 with optional integrators.

    Plant part ``x_a = [x_s; x_i]``: ``x_a(k+1) = Φ_a x_a + Γ_a u + E x_r``, where
    ``x_i`` integrates the errors of the outputs listed in ``integrate``
    (default: all when ``Q_i`` is given). Weights: ``Q = Hᵀ Q_e H`` with
    ``H = [-H_s, H_r]`` (eq. 9.20), plus ``Q_i`` on ``x_i``.
    """
    n_s, n_r = Phi_s.shape[0], Phi_r.shape[0]
    idx = _integrated(H_s.shape[0], Q_i, integrate)
    n_i = len(idx)
    Phi_a = np.eye(n_s + n_i)
    Phi_a[:n_s, :n_s] = Phi_s
    Phi_a[n_s:, :n_s] = -dt * H_s[idx]
    Gamma_a = np.vstack([Gamma_s, np.zeros((n_i, Gamma_s.shape[1]))])
    E = np.zeros((n_s + n_i, n_r))
    E[n_s:] = dt * H_r[idx]
    Q_aa = np.zeros((n_s + n_i, n_s + n_i))
    Q_aa[:n_s, :n_s] = H_s.T @ Q_e @ H_s
    if Q_i is not None:
        Q_aa[n_s:, n_s:] = Q_i
    Q_ar = np.zeros((n_s + n_i, n_r))
    Q_ar[:n_s] = -H_s.T @ Q_e @ H_r
    return Phi_a, Gamma_a, E, Q_aa, Q_ar


def _integrated(p: int, Q_i: FloatArray | None, integrate: Sequence[int] | None) -> list[int]:
    """Indices of the integrated outputs, checked against Q_i's size."""
    if Q_i is None:
        return []
    idx = list(range(p)) if integrate is None else [int(k) for k in integrate]
    if any(not 0 <= k < p for k in idx) or len(set(idx)) != len(idx):
        raise ControlError(f"integrate must list distinct output indices < {p}, found {idx}")
    check_weight("Q_i", Q_i, len(idx), definite=False)
    return idx


def design_tracking_lqr(
    Phi_s: FloatArray, Gamma_s: FloatArray, H_s: FloatArray, Q_e: FloatArray, R: FloatArray,
    *, reference: ReferenceKind, dt: float, Q_i: FloatArray | None = None,
    integrate: Sequence[int] | None = None,
) -> TrackingGains:
    """LQR with a reference model (eq. 9.16-9.21), optionally with integral action.

    Phi_s (n, n), Gamma_s (n, m): discrete plant; H_s (p, n): controlled outputs;
    Q_e (p, p) error weight, R (m, m) input weight; Q_i (k, k) weight on the
    integrated errors of the ``k`` outputs listed in ``integrate`` (default all
    p), or None for no integral action; dt [s] the sample time.
    Only weighted outputs should be integrated: an unweighted integrator is a
    closed-loop pole left on the unit circle.
    """
    n, m = Gamma_s.shape
    p = H_s.shape[0]
    check_shape("Phi_s", Phi_s, (n, n))
    check_shape("H_s", H_s, (p, n))
    check_weight("Q_e", Q_e, p, definite=False)
    check_weight("R", R, m, definite=True)
    Phi_r, H_r = reference_model(reference, p)
    Phi_a, Gamma_a, E, Q_aa, Q_ar = tracking_system(
        Phi_s, Gamma_s, H_s, Phi_r, H_r, Q_e, dt, Q_i, integrate
    )
    K_a, P_aa = dlqr(Phi_a, Gamma_a, Q_aa, R)
    Phi_cl = Phi_a + Gamma_a @ K_a
    P_ar = _solve_stein(Phi_cl.T, Phi_r, Q_ar + Phi_cl.T @ P_aa @ E)
    K_r = _f64(-np.linalg.solve(R + Gamma_a.T @ P_aa @ Gamma_a,
                                Gamma_a.T @ (P_aa @ E + P_ar @ Phi_r)))
    return TrackingGains(
        K_s=K_a[:, :n], K_i=K_a[:, n:], K_r=K_r, Phi_r=Phi_r, H_r=H_r,
        closed_loop_poles=np.asarray(np.linalg.eigvals(Phi_cl), dtype=complex),
    )


def _solve_stein(A: FloatArray, B: FloatArray, C: FloatArray) -> FloatArray:
    """X with ``X - A X B = C`` (A: (n, n), B: (r, r), C, X: (n, r)), by Kronecker solve."""
    n, r = C.shape
    lhs = np.eye(n * r) - np.kron(B.T, A)
    vec = np.linalg.solve(lhs, C.reshape(-1, order="F"))
    return _f64(vec.reshape((n, r), order="F"))


def full_tracking_system(
    Phi_s: FloatArray, Gamma_s: FloatArray, H_s: FloatArray, Q_e: FloatArray,
    *, reference: ReferenceKind, dt: float, Q_i: FloatArray | None = None,
    integrate: Sequence[int] | None = None,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """The whole augmented ``(Φ, Γ, Q)`` of eq. 9.16 and 9.20 (state ``[x_s; x_i; x_r]``).

    For :func:`riccati_iteration` (Algorithm 3), which works on it directly.
    """
    Phi_r, H_r = reference_model(reference, H_s.shape[0])
    Phi_a, Gamma_a, E, Q_aa, Q_ar = tracking_system(
        Phi_s, Gamma_s, H_s, Phi_r, H_r, Q_e, dt, Q_i, integrate
    )
    Phi = np.block([[Phi_a, E], [np.zeros((Phi_r.shape[0], Phi_a.shape[1])), Phi_r]])
    Gamma = np.vstack([Gamma_a, np.zeros((Phi_r.shape[0], Gamma_a.shape[1]))])
    Q = np.block([[Q_aa, Q_ar], [Q_ar.T, H_r.T @ Q_e @ H_r]])
    return Phi, Gamma, Q
