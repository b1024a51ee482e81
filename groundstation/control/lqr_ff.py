"""LQR with the feed-forward reference model (beyond the thesis): ``lqr-ff``.

The thesis's two reference models feed the LQR the reference position
(constant position) or position and velocity (constant velocity, eq. 9.24).
Neither can make the vehicle tilt *before* a tracking error builds up: an
acceleration of the reference needs a tilt, the tilt needs a body rate, and the
body rate reaches the vehicle only after the command delay and the rate loop's
lag. This controller follows the whole state the trajectory implies and feeds
the inputs forward, ahead of time (the trajectory is known in advance):

* **Reference state** at the tick, from the trajectory's flat outputs (position,
  velocity, acceleration, jerk, heading and its rate) through the linear hover
  model (eq. 4.22-4.24, heading frame): tilt ``q1 = a_right / 2g``,
  ``q2 = -a_forward / 2g``; body rates ``omega_x = j_right / g``,
  ``omega_y = -j_forward / g``, ``omega_z = yaw_dot``; velocity and position as given.
* **Feed-forward input** from the reference ``lead_s`` later (the *preview*):
  the body rates that produce the reference's tilt rates, and ``F_z = m a_z -
  I_i v_z`` (eq. 4.24). ``lead_s`` = the modelled input delay + the rate loop's
  time constant + half a command period, so that after the delay, the
  first-order lag (``omega_cmd(t) ~ omega(t + tau)`` to first order) and the
  zero-order hold the vehicle's rates are the reference's rates *now*. The
  thrust path has no rate loop: its feed-forward is taken ``tau`` earlier
  (``a - tau * jerk`` of the preview).
* **Feedback** on the error from the reference state with the gains of the LQR
  designed on the vehicle that flies (:mod:`.augmented`: rate-loop lag and
  command delay, at the command period), including the earlier inputs the
  vehicle was sent (their error from the earlier feed-forward), and integral
  action on the x, y, z and heading errors, which holds zero steady-state error
  under a thrust-map error, a wrong mass or a drooping battery.

Everything is in the heading frame (:class:`.base.HeadingFrame`), so the gain
designed at heading 0 is right at any heading; the heading error is wrapped.
At nominal parameters and on a trajectory the vehicle can fly (smooth to the
jerk), the error stays zero and the feed-forward alone flies the trajectory.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from groundstation.control.augmented import N_VEHICLE, DesignModel, InputHistory
from groundstation.control.base import (
    HeadingFrame,
    OutputIntegrator,
    TiltCompensation,
    fill_heading_state,
    wrap_angle,
)
from groundstation.control.external_force import ExternalForceObserver
from groundstation.control.lqr_design import design_tracking_lqr, saturate, weight_matrix
from groundstation.control.sticks import CommandLimits, StickParams
from groundstation.errors import ControlError
from groundstation.model import QuadrotorParams
from groundstation.types import ControlOutput, FloatArray, Reference, StateEstimate

DEFAULT_Q_ERROR = (100.0, 100.0, 300.0, 20.0)
"""Q_e on the [x, y, z, q3] errors [1/m^2, 1/m^2, 1/m^2, -]: about 0.8 Hz horizontal
closed-loop bandwidth on the rate-loop model (tuned, see ``gs eval --perturb``); z 300
for the payload (``groundstation.config.LqrFfConfig``)."""
DEFAULT_R_INPUT = (1.0, 1.0, 1.0, 0.5)
"""R on [omega_x, omega_y, omega_z, F_z] [1/(rad/s)^2, 1/(rad/s)^2, 1/(rad/s)^2, 1/N^2]."""
DEFAULT_Q_INTEGRAL = (20.0, 20.0, 60.0, 2.0)
"""Weights on the integrated [x, y, z, q3] errors [1/(m s)^2, ..., 1/s^2]."""



class FeedforwardLqr:
    """The ``lqr-ff`` controller (see the module docstring).

    params : the vehicle model (mass, g, inflow, rate gains, thrust map, rate-loop
        time constant ``rate_tau`` and ``input_delay``)
    period : the command period [s] the gains are designed for (one step per COMMAND)
    q_error : (4,) or (4, 4) Q_e on the [x, y, z, q3] errors
    r_input : (4,) or (4, 4) R on [omega_x, omega_y, omega_z, F_z]
    q_integral : (4,) weights on the integrated errors (0 turns an integrator off)
    integral_limit : clamp on each integrated error [m s] (heading: [s])
    tilt_compensation : divide the vertical force by the tilt cosine
    limits : output saturation; default from ``params`` (stick ranges)
    """

    def __init__(
        self,
        *,
        params: QuadrotorParams | None = None,
        period: float = 0.02,
        q_error: Sequence[float] = DEFAULT_Q_ERROR,
        r_input: Sequence[float] = DEFAULT_R_INPUT,
        q_integral: Sequence[float] = DEFAULT_Q_INTEGRAL,
        integral_limit: float = 2.0,
        tilt_compensation: bool = True,
        limits: CommandLimits | None = None,
        external_force: ExternalForceObserver | None = None,
    ) -> None:
        p = params if params is not None else QuadrotorParams()
        self.params = p
        if not (period > 0.0 and math.isfinite(period)):
            raise ControlError(f"period must be a positive time [s], found {period!r}")
        if not integral_limit > 0.0:
            raise ControlError(f"integral_limit must be > 0, found {integral_limit!r}")
        qi = np.asarray(q_integral, dtype=float)
        if qi.shape != (4,) or np.any(qi < 0.0) or not np.all(np.isfinite(qi)):
            raise ControlError(f"q_integral must be 4 non-negative weights, found {q_integral!r}")
        self.period = period
        self.model = DesignModel.build(p, period)
        integrated = [k for k in range(4) if qi[k] > 0.0]
        gains = design_tracking_lqr(
            self.model.Phi, self.model.Gamma, self.model.output_matrix(),
            weight_matrix(q_error, 4, "q_error"), weight_matrix(r_input, 4, "r_input"),
            reference="position", dt=period,
            Q_i=np.diag(qi[integrated]) if integrated else None, integrate=integrated,
        )
        self.gains = gains
        self.closed_loop_poles = gains.closed_loop_poles
        n = self.model.size
        self._K = np.hstack([gains.K_s, gains.K_i])
        self._e = np.zeros(n + len(integrated))  # [x - x_ref; past - past_ff; x_i]
        self._xi = self._e[n:]
        self._integral = OutputIntegrator(integrated, period, integral_limit)
        self._history = InputHistory(self.model.past)
        self._ff_history = InputHistory(self.model.past)
        self.lead_s = self.model.delay + self.model.rate_tau + 0.5 * period
        self._frame = HeadingFrame()
        self._u = np.zeros(4)
        self._u_ff = np.zeros(4)
        self._tilt = TiltCompensation(p.mass * p.g, tilt_compensation)
        self._inv_2g = 0.5 / p.g
        lim = limits or CommandLimits.from_stick_params(StickParams.from_quadrotor(p))
        self._lo = [*lim.omega_min.tolist(), lim.f_z_min]  # saturation, as Python floats:
        self._hi = [*lim.omega_max.tolist(), lim.f_z_max]  # cheaper than numpy on 4 values
        self.external_force = external_force
        """The accelerometer's external-force estimate this controller cancels
        (:mod:`.external_force`), or None."""
        self._d = (0.0, 0.0, 0.0)  # its estimate, NED [m/s^2]
        self._dd = (0.0, 0.0, 0.0)  # and its rate, NED [m/s^3]
        self._lead_z = 0.0 if external_force is None else external_force.vertical_lead_s

    def reset(self) -> None:
        """Zero the integrators, the input histories and the external-force estimate."""
        self._integral.reset()
        self._history.reset()
        self._ff_history.reset()
        self._d = self._dd = (0.0, 0.0, 0.0)
        if self.external_force is not None:
            self.external_force.reset()

    @property
    def integral(self) -> FloatArray:
        """Integrated [x, y, z, heading] errors, x and y in earth axes (4,) [m s, s]."""
        return self._integral.earth.copy()

    def step(self, t: float, estimate: StateEstimate, reference: Reference,
             preview: Reference | None = None) -> ControlOutput:
        """One control step: body-rate set points [rad/s] and F_z [N], saturated."""
        e = self._e
        frame = self._frame
        fill_heading_state(frame, estimate, reference, e)  # also updates the frame
        g2 = self._inv_2g
        # reference tilt, velocity and body rates in the heading frame; the tilt is the one
        # that gives the reference's acceleration less the external one (module doc)
        a0, a1, _a2 = reference.acceleration.tolist()
        j0, j1, _j2 = reference.jerk.tolist()
        if self.external_force is not None:
            d0, d1, d2 = self.external_force.update(estimate)
            r0, r1, r2 = self.external_force.rate
            self._d = (d0, d1, d2)
            self._dd = (r0, r1, r2)
            a0 -= d0
            a1 -= d1
            j0 -= r0
            j1 -= r1
        v0, v1, v2 = reference.velocity.tolist()
        ax, ay = frame.to_heading(a0, a1)
        jx, jy = frame.to_heading(j0, j1)
        vx, vy = frame.to_heading(v0, v1)
        _x, _y, _z, q1, q2, _q3, w0, w1, w2 = e[0:9].tolist()
        # body rates that turn the thrust vector as the jerk asks (the heading frame's own
        # turn at r cancels: omega_x = 2 q1_dot - 2 q2 r = j_right / g, likewise omega_y)
        om0, om1, om2 = estimate.omega.tolist()
        e[3:12] = (q1 - ay * g2, q2 + ax * g2, _q3, w0 - vx, w1 - vy, w2 - v2,
                   om0 - 2.0 * g2 * jy, om1 + 2.0 * g2 * jx, om2 - reference.yaw_rate)
        n_past = 4 * self.model.past
        e[N_VEHICLE:N_VEHICLE + n_past] = self._history.advance()
        e[N_VEHICLE:N_VEHICLE + n_past] -= self._ff_history.advance()
        self._integral.update(frame, e, self._xi)
        u_ff = self._feedforward(reference if preview is None else preview, reference)
        u = np.dot(self._K, e, out=self._u)
        u += u_ff
        if saturate(u, self._lo, self._hi) is not None:
            self._integral.update(frame, e, self._xi, undo=True)
        self._history.propose(u)
        self._ff_history.propose(u_ff)
        return ControlOutput(omega=u[0:3].copy(),
                             f_z=self._tilt.command(float(u[3]), estimate.quaternion))

    def sent(self, output: ControlOutput, automatic: bool) -> None:
        """Record what really went out, as the model's input (the vertical force before
        the tilt compensation), for the earlier-input states of the next steps."""
        f_lin = self._tilt.linear(output.f_z)
        w = output.omega
        self._history.record(np.array([w[0], w[1], w[2], f_lin]))
        if self.external_force is not None:
            self.external_force.sent(output.f_z, automatic)

    # ----------------------------------------------------------------- internals
    def _feedforward(self, ahead: Reference, now: Reference) -> FloatArray:
        """``u_ff`` (4,) from the preview ``ahead``, turned into the heading frame the
        vehicle will have then (its heading plus the reference's turn until then)."""
        frame = self._frame
        psi = frame.yaw + wrap_angle(ahead.yaw - now.yaw)
        c, s = math.cos(psi), math.sin(psi)
        j0, j1, j2 = ahead.jerk.tolist()
        r0, r1, r2 = self._dd
        j0 -= r0  # the jerk less the external acceleration's rate (its value ahead: the
        j1 -= r1  # rate now is the best guess)
        jx = c * j0 + s * j1
        jy = -s * j0 + c * j1
        inv_g = 2.0 * self._inv_2g
        p = self.params
        u = self._u_ff
        # the thrust acts after the input delay and the motors' lag, and the estimate lags a
        # step: the vertical external acceleration is taken ahead (see .external_force)
        d_z = self._d[2] + self._lead_z * r2
        u[:] = (inv_g * jy, -inv_g * jx, ahead.yaw_rate,
                p.mass * (float(ahead.acceleration[2]) - self.model.rate_tau * (j2 - r2) - d_z)
                - p.inflow * float(ahead.velocity[2]))
        return u
