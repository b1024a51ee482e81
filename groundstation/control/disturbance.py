"""Constant-disturbance observer: zero steady-state error without integrators on the error.

Beyond the thesis. A 10 % thrust error, a drooping battery or a wrong mass all
appear as a constant extra acceleration along body z; a biased attitude
estimate or an off-centre mass appear as a constant horizontal acceleration.
The observer estimates ``d`` (3,) [m/s^2, body axes] in

    v(k+1) = Φ_v x(k) + Γ_v u(k) + dt d

from the one-step prediction error of the velocity (rows v of the discrete hover
model): ``d += (dt / tau) * (v_meas - v_pred) / dt``, a first-order estimate
with time constant ``tau``. The controller cancels it: ``F_z -= m d_3`` and the
tilt it must hold, ``q2 = d_1 / 2g`` and ``q1 = -d_2 / 2g`` (eq. 4.22-4.23),
is subtracted from the attitude it feeds back. Unlike integral action on the
position error, a set-point change does not drive the estimate (the model
predicts the manoeuvre), so the step responses keep the LQR's shape.
"""

from __future__ import annotations

import numpy as np

from groundstation.types import FloatArray

V_ROWS = slice(6, 9)
"""Rows of the body velocity in the reduced hover state."""


class DisturbanceObserver:
    """Estimate of a constant acceleration disturbance (see the module docstring).

    Phi (n, n), Gamma (n, 4): the discrete hover model (reduced state first);
    dt [s]; tau [s] estimation time constant (>= a few dt); limit [m/s^2]
    clamp on each component of the estimate.
    """

    def __init__(self, Phi: FloatArray, Gamma: FloatArray, dt: float, tau: float,
                 limit: float = 3.0) -> None:
        if not tau >= dt > 0.0:
            raise ValueError(f"need tau >= dt > 0, found tau={tau!r}, dt={dt!r}")
        n = Phi.shape[0]
        self._Phi_v = np.ascontiguousarray(Phi[V_ROWS, :n])
        self._Gamma_v = np.ascontiguousarray(Gamma[V_ROWS])
        self._gain = 1.0 / tau  # dt/tau per step on (innovation / dt)
        self._dt = dt
        self._limit = limit
        self.estimate = np.zeros(3)
        self._x_prev = np.zeros(n)
        self._u_prev = np.zeros(Gamma.shape[1])
        self._pred = np.zeros(3)
        self._have_prev = False

    def reset(self) -> None:
        """Forget the estimate and the previous sample."""
        self.estimate[:] = 0.0
        self._have_prev = False

    def update(self, x: FloatArray, u_applied_prev: FloatArray | None = None, *,
               learn: bool = True) -> FloatArray:
        """Correct the estimate with the new state ``x`` (n,); returns the estimate (3,).

        ``u_applied_prev`` is the command applied since the previous call
        (default: the one given to :meth:`commit`). ``learn=False`` keeps the
        estimate (the input since the previous call is not known: the pilot had a
        channel, or a handover was blending) and only remembers ``x``.
        """
        if self._have_prev and learn:
            u = self._u_prev if u_applied_prev is None else u_applied_prev
            pred = self._pred
            np.dot(self._Phi_v, self._x_prev, out=pred)
            pred += self._Gamma_v @ u
            pred += self._dt * self.estimate
            d = self.estimate
            d += self._gain * (x[V_ROWS] - pred)
            np.clip(d, -self._limit, self._limit, out=d)
        self._x_prev[:] = x
        self._have_prev = True
        return self.estimate

    def commit(self, u_applied: FloatArray) -> None:
        """Remember the command that will act until the next :meth:`update`."""
        self._u_prev[:] = u_applied
