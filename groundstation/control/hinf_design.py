"""H-infinity state-feedback synthesis (thesis Ch. 10): the standard problem and its LMI.

Standard problem (eq. 10.1-10.10), state ``x = [x_s, x_r, x_n]``:

* ``x_s`` the plant: the reduced hover model (9 states) or, with
  ``include_rate_loop``, the model with the first-order rate-loop lag (12);
* ``x_r`` the reference weight ``W_r = k_r / (s + a_r)`` per output
  [x, y, z, q3] (eq. 10.10): the reference the vehicle must follow is the
  output of a low-pass filter driven by ``w_r``;
* ``x_n`` the sensor-noise weight ``W_n = k_n (s + b_n) / (s + a_n)``
  (high-pass, eq. 10.7; the thesis's state-space form eq. 10.9 has a typo:
  the input matrix is ``k_n (b_n - a_n)``).

Performance ``z = [C_r x_r - C_s' x_s ; eps u]`` (eq. 10.5), so ``D12 = [0; eps I]``
has full column rank. With state feedback ``u = F x`` the LMI of eq. 10.12-10.16
(``D11 = 0``, so ``R_1 = I``), with the bound ``gamma`` made explicit::

    [[A Y + Y Aᵀ + B2 W + Wᵀ B2ᵀ,  B1,      Y C1ᵀ + Wᵀ D12ᵀ],
     [B1ᵀ,                         -gamma I, 0             ],
     [C1 Y + D12 W,                0,       -gamma I       ]]  < 0,   Y > 0

gives ``||T_zw||_inf < gamma`` and ``F = W Y⁻¹`` (eq. 10.17). The measurement
channel (``C2``, ``D21``, the noise weight) does not enter a state-feedback
LMI; ``W_n`` is kept for fidelity to the standard problem (its states are
uncontrollable and stable, their gain unused).

Why continuous time: the thesis synthesises in continuous time and its
finding (the gain that stabilises the model but not the vehicle) is about the
missing rate-loop dynamics, not about sampling. The loop runs at 100 Hz,
more than 30 times the closed-loop bandwidth, so the continuous design is
checked afterwards on the exact discretisation at the loop period with the
command delay (:func:`discrete_spectral_radius`), which is what decides
stability in the loop.
"""

from __future__ import annotations

import importlib
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.linalg

from groundstation.control.lqr import H_OUTPUTS
from groundstation.errors import ControlError
from groundstation.model import QuadrotorParams, hover_model_rate_lag, hover_model_reduced
from groundstation.types import FloatArray


@dataclass(frozen=True, slots=True)
class HinfWeights:
    """Weights of the standard problem (thesis Ch. 10.1).

    eps : input weight in ``D12`` (eq. 10.5); reference_pole a_r [rad/s] and
    reference_gain k_r of ``W_r`` (default k_r = a_r: unit DC gain);
    noise_gain k_n, noise_zero b_n, noise_pole a_n [rad/s] of ``W_n``;
    output_scale : (4,) weights on the [x, y, z, q3] errors in ``z``;
    integral_scale : (4,) weights in ``z`` on the integrated [x, y, z, q3] errors
        (beyond the thesis: integrator states ``x_i' = C_r x_r - C_s x_s`` are
        appended, so the gain has integral action and holds zero steady-state
        error under a thrust-map error or a wrong mass), or None: no integrators.
    """

    eps: float = 0.1
    reference_pole: float = 1.0
    reference_gain: float | None = None
    noise_gain: float = 0.01
    noise_zero: float = 1.0
    noise_pole: float = 100.0
    output_scale: tuple[float, float, float, float] = (1.0, 1.0, 1.0, 1.0)
    integral_scale: tuple[float, float, float, float] | None = None


@dataclass(frozen=True, slots=True)
class HinfDesign:
    """How ``gs synth hinf`` designs a gain (:func:`groundstation.control.hinf.
    synthesise_hinf`): the ``weights``, on the model with the rate-loop lag or the
    thesis's (``include_rate_loop``), robust over +-``robust_range`` of the rate gains,
    rate-loop lag and thrust, the closed-loop poles inside ``pole_radius`` [rad/s] and
    left of ``-min_decay`` [1/s] (None: unconstrained)."""

    weights: HinfWeights
    include_rate_loop: bool
    robust_range: float
    pole_radius: float | None
    min_decay: float | None


@dataclass(frozen=True, slots=True)
class StandardProblem:
    """``A, B1, B2, C1, D11, D12, C2, D21`` of eq. 10.1 and the state partition sizes:
    ``x = [x_s (n_s), x_r (n_r), x_n (n_n), x_i (n_i)]``."""

    A: FloatArray
    B1: FloatArray
    B2: FloatArray
    C1: FloatArray
    D11: FloatArray
    D12: FloatArray
    C2: FloatArray
    D21: FloatArray
    n_s: int
    n_r: int
    n_n: int
    n_i: int = 0


def plant_model(params: QuadrotorParams, include_rate_loop: bool,
                rate_tau: float | None = None) -> tuple[FloatArray, FloatArray]:
    """Continuous ``(A_s, B_s)``: reduced hover model, or with the rate-loop lag."""
    model = (hover_model_rate_lag(params, rate_tau) if include_rate_loop
             else hover_model_reduced(params))
    return model.A, model.B


def standard_problem(A_s: FloatArray, B_s: FloatArray, weights: HinfWeights) -> StandardProblem:
    """Assemble eq. 10.1-10.10 around the plant ``(A_s, B_s)`` (outputs x, y, z, q3)."""
    n_s, m = B_s.shape
    p = 4
    w = weights
    a_r = w.reference_pole
    k_r = a_r if w.reference_gain is None else w.reference_gain
    C_s = np.zeros((p, n_s))
    C_s[np.arange(p), H_OUTPUTS] = 1.0
    n = n_s + 2 * p
    A = scipy.linalg.block_diag(A_s, -a_r * np.eye(p), -w.noise_pole * np.eye(p))
    B1 = np.zeros((n, 2 * p))
    B1[n_s:n_s + p, :p] = k_r * np.eye(p)
    B1[n_s + p:, p:] = w.noise_gain * (w.noise_zero - w.noise_pole) * np.eye(p)
    B2 = np.vstack([B_s, np.zeros((2 * p, m))])
    scale = np.diag(w.output_scale)
    C1 = np.zeros((p + m, n))
    C1[:p, :n_s] = -scale @ C_s
    C1[:p, n_s:n_s + p] = scale
    D12 = np.vstack([np.zeros((p, m)), w.eps * np.eye(m)])
    C2 = np.hstack([np.eye(n_s), np.zeros((n_s, p)), np.zeros((n_s, p))])
    C2[np.ix_(H_OUTPUTS, range(n_s + p, n))] = np.eye(p)  # noise on the measured outputs
    D21 = np.zeros((n_s, 2 * p))
    D21[np.ix_(H_OUTPUTS, range(p, 2 * p))] = w.noise_gain * np.eye(p)
    sp = StandardProblem(A, B1, B2, C1, np.zeros((p + m, 2 * p)), D12, C2, D21, n_s, p, p)
    return sp if w.integral_scale is None else _with_integrators(sp, w.integral_scale)


def _with_integrators(sp: StandardProblem,
                      scale: tuple[float, float, float, float]) -> StandardProblem:
    """``sp`` with integrators of the four output errors appended to the state and
    weighted by ``scale`` in the performance output."""
    p = 4
    n = sp.A.shape[0]
    C_s = np.zeros((p, n))
    C_s[np.arange(p), H_OUTPUTS] = 1.0
    C_r = np.zeros((p, n))
    C_r[:, sp.n_s:sp.n_s + p] = np.eye(p)
    A = np.zeros((n + p, n + p))
    A[:n, :n] = sp.A
    A[n:, :n] = C_r - C_s
    pad = np.zeros((p, sp.B1.shape[1]))
    C1 = np.block([[sp.C1, np.zeros((sp.C1.shape[0], p))],
                   [np.zeros((p, n)), np.diag(np.asarray(scale, dtype=float))]])
    return StandardProblem(
        A, np.vstack([sp.B1, pad]), np.vstack([sp.B2, np.zeros((p, sp.B2.shape[1]))]), C1,
        np.vstack([sp.D11, np.zeros((p, sp.D11.shape[1]))]),
        np.vstack([sp.D12, np.zeros((p, sp.D12.shape[1]))]),
        np.hstack([sp.C2, np.zeros((sp.C2.shape[0], p))]), sp.D21, sp.n_s, sp.n_r, sp.n_n, p,
    )


def uncertainty_vertices(params: QuadrotorParams, rate_tau: float, weights: HinfWeights,
                         rate_gain_range: float, tau_range: float,
                         thrust_gain_range: float = 0.0) -> list[StandardProblem]:
    """The standard problem at the vertices of the uncertainty box: every rate gain
    scaled by ``1 -+ rate_gain_range``, the rate-loop time constant by
    ``1 -+ tau_range`` and the force per newton of ``F_z`` (mass and thrust-map
    errors) by ``1 -+ thrust_gain_range``. A gain that satisfies the LMI at every
    vertex with one Lyapunov matrix is stable for every plant in between (quadratic
    stability). The hover model's axes are decoupled, so solved axis by axis
    (:func:`solve_lmi`) the vertices cover each axis's own gain on its own."""
    out = []
    for k in (1.0 - rate_gain_range, 1.0 + rate_gain_range):
        for tau in (rate_tau * (1.0 - tau_range), rate_tau * (1.0 + tau_range)):
            for k_f in sorted({1.0 - thrust_gain_range, 1.0 + thrust_gain_range}):
                A_s, B_s = plant_model(params, True, tau)
                B_s = B_s.copy()
                B_s[9:12, 0:3] *= k
                B_s[:, 3] *= k_f
                out.append(standard_problem(A_s, B_s, weights))
    return out


def decoupled_blocks(sp: StandardProblem) -> list[tuple[list[int], list[int], list[int],
                                                         list[int]]]:
    """The independent sub-problems of ``sp``: ``(states, control inputs, exogenous
    inputs, performance outputs)`` index lists, one per connected component of the
    graph whose edges are the non-zero entries of A, B1, B2, C1 and D12.

    For the hover model these are the four axes (x with pitch, y with roll, z with
    thrust, heading with yaw rate) with their weight and integrator states, and the
    noise-weight states, which no input reaches. The closed loop of the whole
    problem is then block diagonal: its H-infinity norm is the largest of the blocks'.
    """
    n, m = sp.B2.shape
    nw, nz = sp.B1.shape[1], sp.C1.shape[0]
    parent = list(range(n + m + nw + nz))  # union-find over states, u, w, z

    def find(a: int) -> int:
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    def link(rows: FloatArray, row0: int, col0: int) -> None:
        for r, c in zip(*np.nonzero(rows), strict=True):
            parent[find(row0 + int(r))] = find(col0 + int(c))

    u0, w0, z0 = n, n + m, n + m + nw
    link(sp.A, 0, 0)
    link(sp.B2, 0, u0)
    link(sp.B1, 0, w0)
    link(sp.C1, z0, 0)
    link(sp.D12, z0, u0)
    groups: dict[int, list[int]] = {}
    for node in range(len(parent)):
        groups.setdefault(find(node), []).append(node)
    out = []
    for nodes in groups.values():
        states = [k for k in nodes if k < u0]
        if not states:
            continue
        out.append((states, [k - u0 for k in nodes if u0 <= k < w0],
                    [k - w0 for k in nodes if w0 <= k < z0], [k - z0 for k in nodes if k >= z0]))
    return out


def _block(sp: StandardProblem, states: list[int], inputs: list[int], exo: list[int],
           perf: list[int]) -> StandardProblem:
    """The sub-problem of ``sp`` on the given index lists (for :func:`solve_lmi`)."""
    ix = np.ix_
    return StandardProblem(
        sp.A[ix(states, states)], sp.B1[ix(states, exo)], sp.B2[ix(states, inputs)],
        sp.C1[ix(perf, states)], sp.D11[ix(perf, exo)], sp.D12[ix(perf, inputs)],
        np.zeros((0, len(states))), np.zeros((0, len(exo))), len(states), 0, 0)


def solve_lmi(sp: StandardProblem | Sequence[StandardProblem], *, gamma: float | None = 1.0,
              objective: str = "feasibility", margin: float = 1e-7, solver: str = "CLARABEL",
              pole_radius: float | None = None, min_decay: float | None = None,
              decouple: bool = True) -> FloatArray:
    """Solve the LMI (eq. 10.12-10.17) with cvxpy; returns ``F = W Y⁻¹`` (m, n).

    sp : the standard problem, or several (the vertices of an uncertainty box,
    :func:`uncertainty_vertices`): the LMI is then imposed at each with the same
    ``Y`` and ``W``, which makes the one gain stable, with the bound, on all of them.
    gamma : the bound; ``None`` minimises it (the optimum is degenerate: Y
    becomes singular and the gain unbounded, use it to find ``gamma_min`` only).
    objective : "feasibility" (any feasible point, as an LMI feasibility solver
    returns), or "min-gain": minimise ``|W|_F`` with ``Y >= I``, which bounds
    ``|F| <= |W|`` (the thesis aimed at "as low a feedback matrix as possible").
    pole_radius : if given [rad/s], also keep the closed-loop poles inside the disc
    of that radius centred on ``-pole_radius`` (Chilali and Gahinet's LMI region,
    same ``Y``): the continuous design then asks for no loop faster than the
    sampled, delayed command link can carry. min_decay : if given [1/s], also keep
    every closed-loop pole left of ``-min_decay`` (``A Y + Y Aᵀ + 2 min_decay Y < 0``):
    no loop slower than that (it must stay below the reference weight's pole, which
    no gain can move). decouple : solve each independent sub-problem
    (:func:`decoupled_blocks`: the axes) on its own, which is exact for a block-diagonal
    problem, far faster, and gives each axis its own uncertainty; False solves the one
    joint LMI, as the thesis did (its feasible point differs).
    Needs the optional ``hinf`` extra (cvxpy); ControlError without it or when
    the LMI is infeasible.
    """
    try:  # optional extra, imported lazily; typed Any so mypy agrees with and without it
        cp: Any = importlib.import_module("cvxpy")
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise ControlError("H-infinity synthesis needs cvxpy: pip install '.[hinf]'") from exc
    if objective not in ("feasibility", "min-gain"):
        raise ControlError(f"objective must be 'feasibility' or 'min-gain', found {objective!r}")
    problems = [sp] if isinstance(sp, StandardProblem) else list(sp)
    n, m = problems[0].B2.shape
    F = np.zeros((m, n))
    every = (list(range(n)), list(range(m)), list(range(problems[0].B1.shape[1])),
             list(range(problems[0].C1.shape[0])))
    for states, inputs, exo, perf in decoupled_blocks(problems[0]) if decouple else [every]:
        if not inputs:  # nothing reaches these states (the noise weight): no gain
            continue
        blocks = [_block(v, states, inputs, exo, perf) for v in problems]
        F[np.ix_(inputs, states)] = _solve_block(blocks, cp, gamma, objective, margin, solver,
                                                 pole_radius, min_decay)
    return F


def _solve_block(problems: list[StandardProblem], cp: Any, gamma: float | None,
                 objective: str, margin: float, solver: str,
                 pole_radius: float | None, min_decay: float | None) -> FloatArray:
    """The LMI of :func:`solve_lmi` for one block, at every vertex in ``problems``."""
    first = problems[0]
    n, m = first.B2.shape
    nw, nz = first.B1.shape[1], first.C1.shape[0]
    Y = cp.Variable((n, n), symmetric=True)
    W = cp.Variable((m, n))
    g = cp.Variable() if gamma is None else gamma
    y_min = 1.0 if objective == "min-gain" and gamma is not None else margin
    cons = [Y >> y_min * np.eye(n)]
    for v in problems:
        AY = v.A @ Y + v.B2 @ W
        F13 = Y @ v.C1.T + W.T @ v.D12.T
        lmi = cp.bmat([
            [AY + AY.T, v.B1, F13],
            [v.B1.T, -g * np.eye(nw), v.D11.T],
            [F13.T, v.D11, -g * np.eye(nz)],
        ])
        cons.append(0.5 * (lmi + lmi.T) << -margin * np.eye(n + nw + nz))
        if pole_radius is not None:
            r = pole_radius
            disc = cp.bmat([[-r * Y, r * Y + AY], [(r * Y + AY).T, -r * Y]])
            cons.append(0.5 * (disc + disc.T) << -margin * np.eye(2 * n))
        if min_decay is not None:
            decay = AY + AY.T + 2.0 * min_decay * Y
            cons.append(0.5 * (decay + decay.T) << -margin * np.eye(n))
    if gamma is None:
        goal = cp.Minimize(g)
    elif objective == "min-gain":
        goal = cp.Minimize(cp.norm(W, "fro"))
    else:
        goal = cp.Minimize(0)
    problem = cp.Problem(goal, cons)
    try:
        problem.solve(solver=solver)
    except cp.error.SolverError:
        if solver == "SCS":
            raise ControlError("H-infinity LMI: the solver failed") from None
        problem.solve(solver="SCS")  # first-order fallback when the interior point stalls
    if problem.status not in ("optimal", "optimal_inaccurate") or Y.value is None:
        raise ControlError(f"H-infinity LMI (gamma={gamma}) not solved: {problem.status}")
    F = np.linalg.solve(Y.value.T, W.value.T).T  # F = W Y^-1: solve, do not invert
    return np.asarray(F, dtype=float)


def continuous_closed_loop(A_s: FloatArray, B_s: FloatArray, F_s: FloatArray) -> FloatArray:
    """Eigenvalues of ``A_s + B_s F_s`` (plant part; reference zero)."""
    return np.asarray(np.linalg.eigvals(A_s + B_s @ F_s), dtype=complex)


def discrete_spectral_radius(A_s: FloatArray, B_s: FloatArray, F_s: FloatArray, dt: float,
                             delay_s: float = 0.0) -> float:
    """Spectral radius of the sampled loop ``u(k) = F_s x(k)`` on the ZOH plant.

    A_s (n, n), B_s (n, m): the plant the gain is tried on (may have more
    states than F_s has columns: extra states, such as the rate-loop lag, are
    not fed back). ``delay_s`` [s] of transport delay is rounded to whole
    samples and modelled as a shift register of inputs. < 1 means stable.
    """
    n, m = B_s.shape
    d = round(delay_s / dt)
    M = np.zeros((n + m, n + m))
    M[:n, :n], M[:n, n:] = A_s, B_s
    E = scipy.linalg.expm(M * dt)
    Phi, Gamma = E[:n, :n], E[:n, n:]
    K = np.zeros((m, n))
    K[:, : F_s.shape[1]] = F_s
    size = n + d * m
    T = np.zeros((size, size))
    T[:n, :n] = Phi
    if d == 0:
        T[:n, :n] += Gamma @ K
    else:
        T[:n, n + (d - 1) * m:] = Gamma  # the oldest input acts now
        T[n:n + m, :n] = K  # the newest input enters the register
        for j in range(1, d):
            T[n + j * m:n + (j + 1) * m, n + (j - 1) * m:n + j * m] = np.eye(m)
    return float(np.max(np.abs(np.linalg.eigvals(T))))


def hinf_bandwidth_hz(poles: FloatArray) -> float:
    """Slowest closed-loop pole as a frequency [Hz] (|Re| / 2 pi), a bandwidth indicator."""
    return float(np.min(np.abs(np.real(poles))) / (2.0 * math.pi))
