"""LQR with a reference model (thesis Ch. 9), plus integral action and anti-windup.

The control law is eq. 9.21 extended by integrators of the tracking error::

    u = K_s x_s + K_i x_i + K_r x_r,        u = [omega_x, omega_y, omega_z, F_z]

* ``x_s`` the reduced hover state ``[P, q1, q2, q3, v]`` (q0 dropped: it is
  uncontrollable, eq. 4.18, so the pair would not be stabilisable); with the
  ``rate-loop`` design model (the default) also the measured body rates and the
  inputs sent during the command delay (:mod:`.augmented`);
* ``x_r`` the reference-model state: ``r = [x, y, z, q3]_ref`` for the constant
  position model, ``[r(k); r(k-1)]`` for the constant velocity model (eq. 9.24),
  whose previous sample carries the reference velocity forward. Like the thesis
  (Ch. 9.2.1) the previous sample is not the raw one: it is ``r(k) - dt v`` with
  ``v`` either the trajectory's own velocity (exact, the default) or a
  first-order filter of the sample differences;
* ``x_i`` integrated error ``x_i(k+1) = x_i(k) + dt (r - y)`` for the outputs
  with a positive integral weight (beyond the thesis: zero steady-state error
  under a thrust error, battery droop or a biased estimate). The integrators
  hold while the output saturates and are clamped to ``integral_limit``.

Heading: the states and the reference are taken relative to the reference and
turned into the vehicle's heading frame (:func:`.base.fill_heading_state`); the
gains are invariant under a common shift of state and reference, so at heading
0 this is exactly the thesis's law, and at any other heading it is the same law
turned with the vehicle (the thesis's linearisation at ``q = [1, 0, 0, 0]`` fed
earth-axis quantities, which is wrong away from heading 0).

The gains are designed once, in ``__init__``, on the exact ZOH discretisation
of the linear hover model at the command period (:mod:`.lqr_design`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Literal

import numpy as np

from groundstation.control.augmented import N_VEHICLE, OUTPUT_ROWS, DesignModel, InputHistory
from groundstation.control.base import (
    HeadingFrame,
    OutputIntegrator,
    TiltCompensation,
    fill_heading_state,
    wrap_angle,
)
from groundstation.control.disturbance import DisturbanceObserver
from groundstation.control.lqr_design import (
    ReferenceKind,
    TrackingGains,
    design_tracking_lqr,
    saturate,
    weight_matrix,
)
from groundstation.control.sticks import CommandLimits, StickParams
from groundstation.errors import ControlError
from groundstation.model import QuadrotorParams, hover_model_reduced
from groundstation.types import ControlOutput, FloatArray, Reference, StateEstimate

DEFAULT_Q_ERROR = (8.0, 8.0, 20.0, 2.0)
"""Q_e on the [x, y, z, q3] errors (eq. 9.18) [1/m^2, 1/m^2, 1/m^2, -]."""
DEFAULT_R_INPUT = (4.0, 4.0, 4.0, 2.0)
"""R on [omega_x, omega_y, omega_z, F_z] [1/(rad/s)^2, ..., 1/N^2]."""
DEFAULT_DISTURBANCE_TAU = 1.0
"""Time constant [s] of the constant-disturbance observer (:mod:`.disturbance`)."""

H_OUTPUTS = OUTPUT_ROWS
"""Rows of the reduced state that are the controlled outputs x, y, z, q3 (eq. 9.15)."""



class LqrController:
    """Discrete LQR tracking controller (see the module docstring).

    params : vehicle model parameters (mass, g, inflow, rate gains, thrust map, and for
        the rate-loop design model the rate-loop time constant and the input delay)
    dt : command period [s] the gains are designed for (one step per call)
    reference_model : "velocity" (constant velocity, Ch. 9.2.1, the thesis's
        best) or "position" (constant position)
    q_error : (4,) or (4, 4) Q_e on [x, y, z, q3] errors
    r_input : (4,) or (4, 4) R on [omega_x, omega_y, omega_z, F_z]
    q_integral : (4,) diagonal weights on the integrated errors (0 = no
        integrator), or None (default): no integral action
    integral_limit : clamp on each integrated error [m s]
    disturbance_tau : time constant [s] of the constant-disturbance observer
        that removes the steady-state error (default 1 s), or None for the
        thesis's controller without it. It learns only from steps whose
        command was sent with every channel under automatic control
        (:meth:`sent`): with the pilot on a channel, or during a handover blend,
        the model's input is not the one the vehicle got.
    velocity_source : "reference" (use ``Reference.velocity``) or "samples"
        (filter the differences of the reference samples, as the thesis)
    velocity_filter : weight of the previous velocity in that filter, 0..1
    max_reference_speed : a sample difference faster than this [m/s] is a
        set-point step, not motion, and is not fed forward
    design_model : "rate-loop" (default): the hover model with the rate-loop lag and
        the input delay of ``params`` (:mod:`.augmented`), the measured body rates and
        the inputs sent during the delay fed back; "thesis": the ideal-rate-loop model
    tilt_compensation : divide the vertical force by the tilt cosine, so a
        tilted vehicle keeps its height (the linear model drops this term;
        False flies the thesis's purely linear law)
    limits : output saturation; default from ``params`` (stick ranges)
    """

    lead_s = 0.0

    def __init__(
        self,
        *,
        params: QuadrotorParams | None = None,
        dt: float = 0.02,
        reference_model: ReferenceKind = "velocity",
        q_error: Sequence[float] = DEFAULT_Q_ERROR,
        r_input: Sequence[float] = DEFAULT_R_INPUT,
        q_integral: Sequence[float] | None = None,
        integral_limit: float = 0.5,
        disturbance_tau: float | None = DEFAULT_DISTURBANCE_TAU,
        velocity_source: Literal["reference", "samples"] = "reference",
        velocity_filter: float = 0.5,
        max_reference_speed: float = 5.0,
        design_model: Literal["rate-loop", "thesis"] = "rate-loop",
        tilt_compensation: bool = True,
        limits: CommandLimits | None = None,
    ) -> None:
        self.params = params if params is not None else QuadrotorParams()
        if not (dt > 0.0 and math.isfinite(dt)):
            raise ControlError(f"dt must be a positive period [s], found {dt!r}")
        if not 0.0 <= velocity_filter < 1.0:
            raise ControlError(f"velocity_filter must be in [0, 1), found {velocity_filter!r}")
        if velocity_source not in ("reference", "samples"):
            raise ControlError(f"velocity_source must be 'reference' or 'samples', "
                               f"found {velocity_source!r}")
        if design_model not in ("rate-loop", "thesis"):
            raise ControlError(f"design_model must be 'rate-loop' or 'thesis', "
                               f"found {design_model!r}")
        self.dt = dt
        self.reference_model: ReferenceKind = reference_model
        self._use_ref_velocity = velocity_source == "reference"
        self._alpha = velocity_filter
        self._max_step = max_reference_speed * dt
        Phi, Gamma, past = self._model(design_model)
        self.gains, integrated = self._design(Phi, Gamma, q_error, r_input, q_integral)
        self._n_s = Phi.shape[0]
        self._past = past
        self._history = InputHistory(past)
        self._observer = (None if disturbance_tau is None
                          else DisturbanceObserver(Phi, Gamma, dt, disturbance_tau))
        self._learn = True
        self._half_inv_g = 0.5 / self.params.g
        self._tilt = TiltCompensation(self.params.mass * self.params.g, tilt_compensation)
        lim = limits or CommandLimits.from_stick_params(StickParams.from_quadrotor(self.params))
        self._lo = [*lim.omega_min.tolist(), lim.f_z_min]  # saturation, as Python floats:
        self._hi = [*lim.omega_max.tolist(), lim.f_z_max]  # cheaper than numpy on 4 values
        g = self.gains
        self._K = np.hstack([g.K_s, g.K_i, g.K_r])
        n_i, n_r = g.K_i.shape[1], g.K_r.shape[1]
        self._z = np.zeros(self._n_s + n_i + n_r)  # [x_s; x_i; x_r]
        self._xs = self._z[: self._n_s]
        self._xi = self._z[self._n_s : self._n_s + n_i]
        self._xr = self._z[self._n_s + n_i :]
        self._integral = OutputIntegrator(integrated, dt, integral_limit)
        self._frame = HeadingFrame()
        self._u = np.zeros(4)
        self._d = np.zeros(4)  # filtered reference step per sample, earth axes
        self._r_last = np.zeros(4)  # previous [x, y, z, yaw] reference sample
        self._have_last = False

    def _model(self, design_model: str) -> tuple[FloatArray, FloatArray, int]:
        """``(Phi, Gamma, past inputs)`` of the design model at the command period."""
        if design_model == "thesis":
            Phi, Gamma = hover_model_reduced(self.params).discretize(self.dt)
            return Phi, Gamma, 0
        model = DesignModel.build(self.params, self.dt)
        return model.Phi, model.Gamma, model.past

    def _design(
        self, Phi: FloatArray, Gamma: FloatArray, q_error: Sequence[float],
        r_input: Sequence[float], q_integral: Sequence[float] | None,
    ) -> tuple[TrackingGains, list[int]]:
        n_s = Phi.shape[0]
        H_s = np.zeros((4, n_s))
        H_s[np.arange(4), H_OUTPUTS] = 1.0
        integrated: list[int] = []
        Q_i = None
        if q_integral is not None:
            qi = np.asarray(q_integral, dtype=float)
            if qi.shape != (4,) or np.any(qi < 0.0) or not np.all(np.isfinite(qi)):
                raise ControlError(f"q_integral must be 4 non-negative weights, found {qi!r}")
            integrated = [k for k in range(4) if qi[k] > 0.0]
            Q_i = np.diag(qi[integrated]) if integrated else None
        gains = design_tracking_lqr(
            Phi, Gamma, H_s, weight_matrix(q_error, 4, "q_error"),
            weight_matrix(r_input, 4, "r_input"),
            reference=self.reference_model, dt=self.dt, Q_i=Q_i, integrate=integrated,
        )
        return gains, integrated

    def reset(self) -> None:
        """Zero the integrators and the input history; forget the previous reference."""
        self._integral.reset()
        self._d[:] = 0.0
        self._have_last = False
        self._history.reset()
        if self._observer is not None:
            self._observer.reset()

    @property
    def disturbance(self) -> np.ndarray:
        """Current disturbance estimate (3,) [m/s^2, heading-frame axes] (zeros without
        observer)."""
        return self._observer.estimate if self._observer is not None else np.zeros(3)

    def step(self, t: float, estimate: StateEstimate, reference: Reference,
             preview: Reference | None = None) -> ControlOutput:
        """One control step: body-rate set points [rad/s] and F_z [N], saturated."""
        xs = self._xs
        frame = self._frame
        fill_heading_state(frame, estimate, reference, xs)
        if self._n_s > 9:
            xs[9:N_VEHICLE] = estimate.omega
            xs[N_VEHICLE:] = self._history.advance()
        obs = self._observer
        if obs is not None:
            d = obs.update(xs, learn=self._learn)
            xs[3] += d[1] * self._half_inv_g  # hold the tilt that cancels d (eq. 4.22-4.23)
            xs[4] -= d[0] * self._half_inv_g
            # and the thrust that cancels it: the inputs sent during the delay include that
            # compensation, which is not the LQR's to correct
            xs[N_VEHICLE + 3::4] += self.params.mass * d[2]
        self._update_reference_state(reference)
        self._integral.update(frame, xs, self._xi)
        u = np.dot(self._K, self._z, out=self._u)
        if obs is not None:
            u[3] -= self.params.mass * obs.estimate[2]
        if saturate(u, self._lo, self._hi) is not None:
            self._integral.update(frame, xs, self._xi, undo=True)
        self._history.propose(u)
        if obs is not None:
            obs.commit(u)  # the linear model's input: the compensation below is not in it
        self._learn = True  # until sent() says otherwise
        return ControlOutput(omega=u[0:3].copy(),
                             f_z=self._tilt.command(float(u[3]), estimate.quaternion))

    def sent(self, output: ControlOutput, automatic: bool) -> None:
        """Record what went out (as the linear model's input) for the input-history
        states and the observer; the observer learns from the next step only if this
        command was ``automatic`` on every channel."""
        f_lin = self._tilt.linear(output.f_z)
        w = output.omega
        u = np.array([w[0], w[1], w[2], f_lin])
        if self._observer is not None:
            self._observer.commit(u)
        self._history.record(u)
        self._learn = automatic

    def _update_reference_state(self, reference: Reference) -> None:
        """Fill x_r relative to the reference in the heading frame: 0 (constant position)
        or ``[0; -d]`` (constant velocity, d the reference's step over one period)."""
        xr = self._xr
        xr[0:4] = 0.0
        if self.reference_model == "position":
            return
        d = self._d
        r = self._r_last
        px, py, pz = reference.position.tolist()
        if self._use_ref_velocity:
            vx, vy, vz = reference.velocity.tolist()
            dt = self.dt
            d[:] = (dt * vx, dt * vy, dt * vz, dt * reference.yaw_rate)
        elif self._have_last:
            raw = np.array([px - r[0], py - r[1], pz - r[2], wrap_angle(reference.yaw - r[3])])
            if np.any(np.abs(raw[:3]) > self._max_step):
                raw[:] = 0.0  # a set-point step is not a velocity
            d *= self._alpha
            d += (1.0 - self._alpha) * raw
        r[:] = (px, py, pz, reference.yaw)
        self._have_last = True
        d0, d1, d2, d3 = d.tolist()
        hx, hy = self._frame.to_heading(d0, d1)
        xr[4:8] = (-hx, -hy, -d2, -math.sin(0.5 * d3))
