"""Linear hover models of the quadrotor (thesis Ch. 4), as state-space matrices.

All models linearise :class:`~groundstation.model.quadrotor.QuadrotorModel` about
level hover (``q = [1, 0, 0, 0]``, ``v = 0``, ``omega = 0``, ``F_z = 0``); the
position is free (it does not enter the dynamics). Inputs are physical:
``[omega_x, omega_y, omega_z]`` body-rate set points [rad/s] and ``F_z = F_lift + m g`` [N];
multiply ``B`` by :func:`stick_input_gain` for stick units.

Thesis erratum (DESIGN.md): eq. 4.14 flips the sign of the first row. From the
physics (eq. 4.13, 4.22), nose up (``q2 > 0``) accelerates toward -x and right side
down (``q1 > 0``) toward +y: ``v1_dot = -2 g q2``, ``v2_dot = +2 g q1``.

Three variants:

* :func:`hover_model` - state ``[x, y, z, q0, q1, q2, q3, v1, v2, v3]`` (10), the
  exact Jacobian of the nonlinear model. ``q0`` is uncontrollable (``q0_dot = 0``)
  and the column ``d v3_dot / d q0 = 2 g`` (which eq. 4.11 drops by setting
  ``q0^2 = 1``) never acts along the unit sphere, where ``dq0 = 0`` to first order.
* :func:`hover_model_reduced` - state ``[x, y, z, q1, q2, q3, v1, v2, v3]`` (9),
  without ``q0``: stabilisable, for LQR design.
* :func:`hover_model_rate_lag` - the reduced state plus the body rates
  ``[omega_x, omega_y, omega_z]`` (12), with the on-board rate loop as a
  first-order lag ``omega_dot = (omega_cmd - omega) / tau``; inputs
  ``[omega_cmd (3), F_z]``. For H-infinity design.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import expm

from groundstation.model.quadrotor import QuadrotorParams
from groundstation.types import FloatArray

__all__ = [
    "LinearModel",
    "hover_model",
    "hover_model_rate_lag",
    "hover_model_reduced",
    "stick_input_gain",
]

_INPUTS = ("omega_x", "omega_y", "omega_z", "F_z")


@dataclass(frozen=True, slots=True)
class LinearModel:
    """Continuous-time ``x_dot = A x + B u`` with named states and inputs.

    A : (n, n), B : (n, m); ``states`` and ``inputs`` name the rows/columns
    (units: m, m/s, rad/s, N, quaternion components dimensionless).
    """

    A: FloatArray
    B: FloatArray
    states: tuple[str, ...]
    inputs: tuple[str, ...]

    def discretize(self, dt: float) -> tuple[FloatArray, FloatArray]:
        """Zero-order-hold discretisation ``(Ad, Bd)`` for sample time ``dt`` [s]
        (exact, via the matrix exponential of the augmented ``[[A, B], [0, 0]]``)."""
        n, m = self.B.shape
        M = np.zeros((n + m, n + m))
        M[:n, :n] = self.A
        M[:n, n:] = self.B
        E = expm(M * dt)
        return E[:n, :n], E[:n, n:]

    def index(self, name: str) -> int:
        """Row index of the named state (``ValueError`` if absent)."""
        return self.states.index(name)


def stick_input_gain(params: QuadrotorParams) -> FloatArray:
    """``diag(K_phi, K_theta, K_psi, 1)`` (4, 4): ``u = G @ [u_phi, u_theta, u_psi, F_z]``
    maps stick units (rates) and newtons (``F_z``) to the model input (eq. 3.22)."""
    return np.diag([*params.k_rate, 1.0])


def hover_model(params: QuadrotorParams | None = None) -> LinearModel:
    """Exact Jacobian at hover, state ``[P, q0..q3, v]`` (10), inputs ``[omega, F_z]``."""
    p = params if params is not None else QuadrotorParams()
    A = np.zeros((10, 10))
    B = np.zeros((10, 4))
    A[0:3, 7:10] = np.eye(3)  # P_dot = v (eq. 4.15-4.17)
    B[4:7, 0:3] = 0.5 * np.eye(3)  # q_dot = 0.5 omega (eq. 4.19-4.21)
    A[7, 5] = -2.0 * p.g  # nose up -> toward -x (eq. 4.22; 4.14's sign is a typo)
    A[8, 4] = 2.0 * p.g  # right side down -> toward +y (eq. 4.23)
    A[9, 3] = 2.0 * p.g  # d(g q0^2)/dq0; inert on the unit sphere (see module doc)
    A[9, 9] = p.inflow / p.mass  # induced inflow (eq. 4.24)
    B[9, 3] = 1.0 / p.mass
    states = ("x", "y", "z", "q0", "q1", "q2", "q3", "v1", "v2", "v3")
    return LinearModel(A, B, states, _INPUTS)


def hover_model_reduced(params: QuadrotorParams | None = None) -> LinearModel:
    """Hover model without ``q0``: state ``[P, q1, q2, q3, v]`` (9), inputs ``[omega, F_z]``."""
    full = hover_model(params)
    keep = [0, 1, 2, 4, 5, 6, 7, 8, 9]
    A = full.A[np.ix_(keep, keep)]
    B = full.B[keep, :]
    return LinearModel(A, B, tuple(full.states[i] for i in keep), _INPUTS)


def hover_model_rate_lag(
    params: QuadrotorParams | None = None, tau: float | None = None
) -> LinearModel:
    """Reduced hover model with a first-order rate loop, state ``[P, q1..q3, v, omega]`` (12).

    tau : rate-loop time constant [s]; default ``params.rate_tau``.
    Inputs ``[omega_cmd_x, omega_cmd_y, omega_cmd_z, F_z]``.
    """
    p = params if params is not None else QuadrotorParams()
    t = p.rate_tau if tau is None else tau
    if not t > 0.0:
        raise ValueError(f"tau must be > 0, got {t!r}")
    red = hover_model_reduced(p)
    A = np.zeros((12, 12))
    B = np.zeros((12, 4))
    A[:9, :9] = red.A
    A[3:6, 9:12] = 0.5 * np.eye(3)  # q_dot = 0.5 omega (omega now a state)
    A[9:12, 9:12] = -np.eye(3) / t
    B[9:12, 0:3] = np.eye(3) / t
    B[8, 3] = red.B[8, 3]
    states = (*red.states, "omega_x", "omega_y", "omega_z")
    return LinearModel(A, B, states, ("omega_cmd_x", "omega_cmd_y", "omega_cmd_z", "F_z"))
