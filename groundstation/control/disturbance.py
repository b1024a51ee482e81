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
        self._M = np.ascontiguousarray(np.hstack([Phi[V_ROWS, :n], Gamma[V_ROWS]]))
        self._gain = 1.0 / tau  # dt/tau per step on (innovation / dt)
        self._dt = dt
        self._limit = limit
        self.estimate = np.zeros(3)
        self._z_prev = np.zeros(n + Gamma.shape[1])  # [x(k-1); u(k-1)]: one product
        self._x_prev = self._z_prev[:n]
        self._u_prev = self._z_prev[n:]
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
            if u_applied_prev is not None:
                self._u_prev[:] = u_applied_prev
            p0, p1, p2 = np.dot(self._M, self._z_prev, out=self._pred).tolist()
            v0, v1, v2 = x[V_ROWS].tolist()
            d0, d1, d2 = self.estimate.tolist()
            k, dt, lim = self._gain, self._dt, self._limit
            self.estimate[:] = (min(max(d0 + k * (v0 - p0 - dt * d0), -lim), lim),
                                min(max(d1 + k * (v1 - p1 - dt * d1), -lim), lim),
                                min(max(d2 + k * (v2 - p2 - dt * d2), -lim), lim))
        self._x_prev[:] = x
        self._have_prev = True
        return self.estimate

    def commit(self, u_applied: FloatArray) -> None:
        """Remember the command that will act until the next :meth:`update`."""
        self._u_prev[:] = u_applied
