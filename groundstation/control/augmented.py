"""The design model of the vehicle that flies: rate loop and command delay included.

The thesis designs its LQR on the hover model with an ideal rate loop and
concludes (Ch. 10.3, 12) that the on-board rate loop cannot be ignored. The
model here is the reduced hover model with the rate loop as a first-order lag
(:func:`groundstation.model.hover_model_rate_lag`, time constant from Fig. 3.8)
and the transport delay of the commands, discretised exactly at the period the
COMMANDs are actually sent at (:func:`.lqr_design.discretise_delayed`). Its
state is

    [x, y, z, q1, q2, q3, v1, v2, v3, omega_x, omega_y, omega_z,
     u(k-1), ..., u(k-l)]                                    (12 + 4 l)

with ``u = [omega_cmd (3) rad/s, F_z N]``. The rates are measured (the gyro); the
earlier inputs are known exactly, because the controller is told what was sent
(:class:`InputHistory`), so the whole state is available to a state-feedback law.

The delay is the configured command delay plus the time the DATA frame that
carried the newest IMU sample and the COMMAND frame spend on the wire (both
known from the baud rate): the age of the state estimate plus the command's
travel time.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from groundstation.control.lqr_design import discretise_delayed
from groundstation.errors import ControlError
from groundstation.model import QuadrotorParams, hover_model_rate_lag
from groundstation.types import FloatArray

N_INPUTS = 4
"""Inputs ``[omega_cmd_x, omega_cmd_y, omega_cmd_z, F_z]``."""
N_VEHICLE = 12
"""Vehicle states of the rate-loop model: position, q1..q3, velocity, body rates."""
OUTPUT_ROWS = (0, 1, 2, 5)
"""Rows of the controlled outputs x, y, z, q3 (eq. 9.15)."""


@dataclass(frozen=True, slots=True)
class DesignModel:
    """The discrete design model (see the module docstring).

    Phi (n, n), Gamma (n, 4): ``z(k+1) = Phi z(k) + Gamma u(k)``; period [s];
    rate_tau [s]; delay [s] the total input delay modelled; past : number ``l`` of
    earlier inputs in the state (``ceil(delay / period)``).
    """

    Phi: FloatArray
    Gamma: FloatArray
    period: float
    rate_tau: float
    delay: float
    past: int

    @property
    def size(self) -> int:
        """Number of states ``12 + 4 l``."""
        return int(self.Phi.shape[0])

    @classmethod
    def build(cls, params: QuadrotorParams, period: float, *, rate_tau: float | None = None,
              delay: float | None = None) -> DesignModel:
        """The model for ``params`` at the command ``period`` [s]; ``rate_tau`` and
        ``delay`` [s] default to ``params.rate_tau`` and ``params.input_delay``."""
        tau = params.rate_tau if rate_tau is None else rate_tau
        d = params.input_delay if delay is None else delay
        if not (period > 0.0 and tau > 0.0 and d >= 0.0):
            raise ControlError(f"need period > 0, rate_tau > 0 and delay >= 0, found "
                               f"{period!r}, {tau!r}, {d!r}")
        model = hover_model_rate_lag(params, tau)
        Phi, Gamma, past = discretise_delayed(model.A, model.B, period, d)
        return cls(Phi, Gamma, period, tau, d, past)

    def output_matrix(self) -> FloatArray:
        """``H`` (4, n) picking the controlled outputs x, y, z, q3."""
        H = np.zeros((4, self.size))
        H[np.arange(4), OUTPUT_ROWS] = 1.0
        return H


class InputHistory:
    """The last ``past`` inputs the vehicle was sent, newest first, ``(past, 4)``.

    The controller :meth:`propose` s its own output at each step; if the loop then
    reports what really went out (:meth:`record`: after the channel handover, with
    the pilot's sticks on manual channels and saturation applied), that replaces
    it. The entry is pushed into the history at the next step (:meth:`advance`).
    """

    def __init__(self, past: int) -> None:
        self.values = np.zeros((past, N_INPUTS))
        self._flat = self.values.reshape(-1)  # a view, made once
        self._pending = np.zeros(N_INPUTS)
        self._have_pending = False

    def reset(self) -> None:
        """Forget: zeros (the vehicle on the floor, nothing commanded)."""
        self.values[:] = 0.0
        self._have_pending = False

    def propose(self, u: FloatArray) -> None:
        """The controller's own output (4,) of this step."""
        self._pending[:] = u
        self._have_pending = True

    def record(self, u: FloatArray) -> None:
        """What was actually sent (4,) for this step."""
        self._pending[:] = u
        self._have_pending = True

    def advance(self) -> FloatArray:
        """Push the last step's input into the history; returns the flattened history
        ``[u(k-1), ..., u(k-l)]`` (4 l,) (a view)."""
        v = self.values
        if self._have_pending and len(v):
            v[1:] = v[:-1].copy()
            v[0] = self._pending
        self._have_pending = False
        return self._flat
