"""The controller role: a small protocol, a null controller as its template, shared helpers.

A controller is pure computation: the loop hands it the time, the latest
:class:`~groundstation.types.StateEstimate` and the trajectory's
:class:`~groundstation.types.Reference`; it returns a
:class:`~groundstation.types.ControlOutput` (body-rate set points [rad/s] and
``F_z = F_lift + m g`` [N], 0 in hover, negative to climb). It owns no clock and
no thread; gains are computed at construction and :meth:`Controller.step` is
lean (no validation, as little allocation as the output records allow).

The flight core calls :meth:`Controller.step` once per COMMAND actually sent (the
controllers are designed at that period), hands it the reference ``lead_s``
seconds ahead as a preview when it asks for one, and then tells it with
:meth:`Controller.sent` what went out after the channel handover.

Heading invariance: the quadrotor's dynamics do not depend on its heading, so
every controller works in the *heading frame* (:class:`HeadingFrame`): earth
axes turned by the vehicle's own heading about the vertical. Horizontal errors,
velocities and the tilt are expressed there and the heading error is wrapped to
(-pi, pi], so a gain designed at heading 0 (the thesis's linearisation at
``q = [1, 0, 0, 0]``) is right at every heading and while the heading turns.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Protocol, runtime_checkable

import numpy as np

from groundstation.types import ControlOutput, FloatArray, Reference, StateEstimate

REDUCED_STATES = ("x", "y", "z", "q1", "q2", "q3", "v1", "v2", "v3")
"""Order of the reduced hover state (``groundstation.model.hover_model_reduced``)."""


@runtime_checkable
class Controller(Protocol):
    """What the flight loop calls once per COMMAND period.

    lead_s : how far ahead of the tick [s] the controller wants the reference as a
        preview (its feed-forward looks ahead by the rate-loop lag and the link
        delay); 0 for a controller without preview.
    """

    lead_s: float

    def step(self, t: float, estimate: StateEstimate, reference: Reference,
             preview: Reference | None = None) -> ControlOutput:
        """Control output for the state ``estimate`` at time ``t`` [s] given ``reference``
        (the reference now) and ``preview`` (the reference ``lead_s`` later, or None)."""
        ...

    def sent(self, output: ControlOutput, automatic: bool) -> None:
        """What the vehicle was sent after the last :meth:`step` (after the channel
        handover and the stick conversion, in physical units); ``automatic``: every
        channel was under the controller's own control (no pilot, no handover blend)."""
        ...

    def reset(self) -> None:
        """Forget all internal state (integrators, filters, previous samples)."""
        ...


class NullController:
    """Hover thrust and zero body rates, whatever the state: the template controller.

    It does not fly (nothing stabilises the attitude); it is the default for
    tests of the loop's plumbing and shows the minimum a controller provides.
    """

    lead_s = 0.0

    def __init__(self) -> None:
        self._omega = np.zeros(3)

    def step(self, t: float, estimate: StateEstimate, reference: Reference,
             preview: Reference | None = None) -> ControlOutput:
        """Zero rates and ``F_z = 0`` (lift equals weight, eq. 4.14)."""
        return ControlOutput(omega=self._omega.copy(), f_z=0.0)

    def sent(self, output: ControlOutput, automatic: bool) -> None:
        """Nothing to learn from."""

    def reset(self) -> None:
        """Nothing to forget."""


def wrap_angle(angle: float) -> float:
    """``angle`` [rad] wrapped to (-pi, pi]."""
    a = math.remainder(angle, math.tau)  # in [-pi, pi]
    return math.pi if a == -math.pi else a


def heading_of(q: FloatArray) -> float:
    """Heading [rad] of the scalar-first attitude ``q`` (3-2-1 Euler psi, ``R(q) = eCb``)."""
    q0, q1, q2, q3 = float(q[0]), float(q[1]), float(q[2]), float(q[3])
    return math.atan2(2.0 * (q0 * q3 + q1 * q2), 1.0 - 2.0 * (q2 * q2 + q3 * q3))


class HeadingFrame:
    """Earth axes turned about the vertical by the vehicle's heading (see the module doc).

    :meth:`update` takes an estimate and fills, in this frame, the quantities the
    linear hover model is written in: ``tilt`` ``(q1, q2)`` of ``q_h = q_z(psi)* ⊗ q``
    (the attitude without its heading: ``q_h1 ~ phi / 2``, ``q_h2 ~ theta / 2``) and
    the velocity ``velocity`` (3,) [m/s] (earth axes turned by ``-psi``).
    :meth:`to_heading` turns any earth-axis vector the same way. ``yaw`` [rad],
    ``cos``, ``sin``: the heading and its cosine and sine.
    """

    __slots__ = ("cos", "sin", "tilt", "velocity", "yaw")

    def __init__(self) -> None:
        self.yaw = 0.0
        self.cos = 1.0
        self.sin = 0.0
        self.tilt = (0.0, 0.0)
        self.velocity = np.zeros(3)

    def update(self, estimate: StateEstimate) -> None:
        """Heading, tilt and heading-frame velocity of ``estimate``."""
        q0, q1, q2, q3 = estimate.quaternion.tolist()
        if q0 < 0.0:
            q0, q1, q2, q3 = -q0, -q1, -q2, -q3
        psi = math.atan2(2.0 * (q0 * q3 + q1 * q2), 1.0 - 2.0 * (q2 * q2 + q3 * q3))
        ch, sh = math.cos(0.5 * psi), math.sin(0.5 * psi)
        self.yaw = psi
        self.cos, self.sin = math.cos(psi), math.sin(psi)
        # vector part of q_h = q_z(-psi) ⊗ q, signed so that q_h0 >= 0 (psi and psi - 2 pi
        # give opposite q_z: the same rotation, the opposite sign)
        sign = 1.0 if ch * q0 + sh * q3 >= 0.0 else -1.0
        self.tilt = (sign * (ch * q1 + sh * q2), sign * (ch * q2 - sh * q1))
        vx, vy, vz = estimate.velocity_body.tolist()
        # eCb v (eq. 2.20 read as body -> earth), then turned by -psi about the vertical
        n = ((q0 * q0 + q1 * q1 - q2 * q2 - q3 * q3) * vx + 2 * (q1 * q2 - q0 * q3) * vy
             + 2 * (q1 * q3 + q0 * q2) * vz)
        e = (2 * (q1 * q2 + q0 * q3) * vx + (q0 * q0 - q1 * q1 + q2 * q2 - q3 * q3) * vy
             + 2 * (q2 * q3 - q0 * q1) * vz)
        d = (2 * (q1 * q3 - q0 * q2) * vx + 2 * (q2 * q3 + q0 * q1) * vy
             + (q0 * q0 - q1 * q1 - q2 * q2 + q3 * q3) * vz)
        c, s = self.cos, self.sin
        self.velocity[:] = (c * n + s * e, -s * n + c * e, d)

    def to_heading(self, x: float, y: float) -> tuple[float, float]:
        """The horizontal earth-axis vector ``(x, y)`` (north, east) in the heading frame."""
        return self.cos * x + self.sin * y, -self.sin * x + self.cos * y

    def to_earth(self, x: float, y: float) -> tuple[float, float]:
        """The heading-frame vector ``(x, y)`` (forward, right) in earth axes."""
        return self.cos * x - self.sin * y, self.sin * x + self.cos * y

    def yaw_error(self, yaw_ref: float) -> float:
        """``sin(wrap(psi - yaw_ref) / 2)``: the heading error as the q3 of the hover
        model (eq. 9.15 controls q3), continuous through +-180 degrees."""
        return math.sin(0.5 * wrap_angle(self.yaw - yaw_ref))


class TiltCompensation:
    """The vertical-force command corrected for tilt, and its inverse for the input history.

    The linear models' vertical force ``f`` acts along the body z axis; hovering tilted
    by an angle with cosine ``c``, only ``c f`` holds the weight ``m g``. With the
    compensation on, the controller's linear output ``f_lin`` becomes
    ``f_z = (f_lin - m g (1 - c)) / c``: the weight's share is scaled up, the rest
    passes unchanged. ``c`` (the body z axis's vertical component,
    ``q0^2 - q1^2 - q2^2 + q3^2``, quaternion scalar first) is floored at 0.5 (60 degrees).

    weight : m g [N]; enabled : False passes ``f_lin`` through unchanged
    """

    def __init__(self, weight: float, enabled: bool) -> None:
        self.weight = weight
        self.enabled = enabled
        self.cos_tilt = 1.0
        """The cosine used by the last :meth:`command` (used again by :meth:`linear`)."""

    def command(self, f_lin: float, quaternion: FloatArray) -> float:
        """The vertical force to command [N] for the linear output ``f_lin`` [N] at the
        attitude ``quaternion`` (4,) [q0, q1, q2, q3]."""
        q0, q1, q2, q3 = quaternion.tolist()
        c = max(q0 * q0 - q1 * q1 - q2 * q2 + q3 * q3, 0.5)
        self.cos_tilt = c
        return (f_lin - self.weight * (1.0 - c)) / c if self.enabled else f_lin

    def linear(self, f_z: float) -> float:
        """The linear output [N] a sent vertical force ``f_z`` [N] stands for (the inverse
        of the last :meth:`command`)."""
        c = self.cos_tilt
        return c * f_z + self.weight * (1.0 - c) if self.enabled else f_z


class OutputIntegrator:
    """Integrated output errors ``r - y`` of ``[x, y, z, heading]`` for an LQR with integral
    action, kept with x and y in *earth* axes and handed to the gain in the heading frame.

    An integrator holds the force that cancels a constant disturbance; a disturbance
    fixed in the lab (a draught, a biased position) stays fixed while the vehicle
    turns, so the integral must not turn with the heading frame.

    outputs : which of the four outputs have an integrator (indices 0..3)
    dt : period [s]; limit : clamp on each integral [m s, s]
    """

    def __init__(self, outputs: Sequence[int], dt: float, limit: float) -> None:
        self._outputs = tuple(int(k) for k in outputs)
        self._dt = dt
        self._limit = limit
        self.earth = np.zeros(4)

    def reset(self) -> None:
        """Zero every integral."""
        self.earth[:] = 0.0

    def update(self, frame: HeadingFrame, state: FloatArray, out: FloatArray,
               undo: bool = False) -> None:
        """Integrate the errors of the heading-frame ``state`` (``[x, y, z]`` relative to
        the reference in rows 0..2, heading error in row 5, as
        :func:`fill_heading_state` writes it) and write the integrals of the chosen
        outputs into ``out`` in the heading frame. ``undo`` takes the step back
        (conditional integration: hold while the output saturates)."""
        if not self._outputs:
            return
        step = self._dt if undo else -self._dt
        lim = self._limit
        x, y, z, _q1, _q2, q3 = state[0:6].tolist()
        ex, ey = frame.to_earth(x, y)
        i0, i1, i2, i3 = self.earth.tolist()
        i0 = min(max(i0 + step * ex, -lim), lim)
        i1 = min(max(i1 + step * ey, -lim), lim)
        i2 = min(max(i2 + step * z, -lim), lim)
        i3 = min(max(i3 + step * q3, -lim), lim)
        self.earth[:] = (i0, i1, i2, i3)
        hx, hy = frame.to_heading(i0, i1)
        in_frame = (hx, hy, i2, i3)
        out[:] = [in_frame[idx] for idx in self._outputs]


def fill_heading_state(frame: HeadingFrame, estimate: StateEstimate, reference: Reference,
                       out: FloatArray) -> FloatArray:
    """The reduced hover state ``[P, q1, q2, q3, v]`` (9,) of ``estimate`` *relative to*
    ``reference``, in the heading frame ``frame`` (updated from ``estimate`` first).

    ``P`` is the position minus the reference position, turned into the heading
    frame; ``q1, q2`` the tilt; ``q3`` the wrapped heading error
    (:meth:`HeadingFrame.yaw_error`); ``v`` the heading-frame velocity. The
    reference's own outputs ``[x, y, z, q3]`` are then 0. Every LQR gain here is
    invariant under a common shift of the state and the reference positions (the
    positions are pure integrators of the velocity), so this equals the thesis's
    absolute-coordinate law at heading 0 and turns it with the vehicle at any other.
    ``out`` must be a float array of length >= 9; returns it.
    """
    frame.update(estimate)
    px, py, pz = estimate.position.tolist()
    rx, ry, rz = reference.position.tolist()
    hx, hy = frame.to_heading(px - rx, py - ry)
    t1, t2 = frame.tilt
    out[0:6] = (hx, hy, pz - rz, t1, t2, frame.yaw_error(reference.yaw))
    out[6:9] = frame.velocity
    return out
