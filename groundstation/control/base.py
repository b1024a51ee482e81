"""The controller role: a small protocol, a null controller as its template, shared helpers.

A controller is pure computation: the loop hands it the time, the latest
:class:`~groundstation.types.StateEstimate` and the trajectory's
:class:`~groundstation.types.Reference`; it returns a
:class:`~groundstation.types.ControlOutput` (body-rate set points [rad/s] and
``F_z = F_lift + m g`` [N], 0 in hover, negative to climb). It owns no clock and
no thread; gains are computed at construction and :meth:`Controller.step` is
lean (no validation, as little allocation as the output records allow).
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np

from groundstation.types import ControlOutput, FloatArray, Reference, StateEstimate

REDUCED_STATES = ("x", "y", "z", "q1", "q2", "q3", "v1", "v2", "v3")
"""Order of the reduced hover state (``groundstation.model.hover_model_reduced``)."""


@runtime_checkable
class Controller(Protocol):
    """What the flight loop calls once per control period."""

    def step(self, t: float, estimate: StateEstimate, reference: Reference) -> ControlOutput:
        """Control output for the state ``estimate`` at time ``t`` [s] given ``reference``."""
        ...

    def reset(self) -> None:
        """Forget all internal state (integrators, filters, previous samples)."""
        ...


class NullController:
    """Hover thrust and zero body rates, whatever the state: the template controller.

    It does not fly (nothing stabilises the attitude); it is the default for
    tests of the loop's plumbing and shows the minimum a controller provides.
    """

    def __init__(self) -> None:
        self._omega = np.zeros(3)

    def step(self, t: float, estimate: StateEstimate, reference: Reference) -> ControlOutput:
        """Zero rates and ``F_z = 0`` (lift equals weight, eq. 4.14)."""
        return ControlOutput(omega=self._omega.copy(), f_z=0.0)

    def reset(self) -> None:
        """Nothing to forget."""


def fill_reduced_state(estimate: StateEstimate, out: FloatArray) -> FloatArray:
    """Write the reduced hover state ``[P, q1, q2, q3, v]`` (9,) of ``estimate`` into ``out``.

    The quaternion sign is chosen with ``q0 >= 0`` so that the small-angle
    components ``q1..q3`` describe the attitude near hover (``q`` and ``-q`` are
    the same attitude). The velocity is rotated to earth axes, ``v = eCb bv``:
    the linear model's ``P_dot = v`` (eq. 4.8) then holds exactly, not only at
    hover (a tilted vehicle flying level would otherwise appear to climb or
    sink by ``sin(tilt) |v|``); at hover it equals ``bv``, the thesis's state.
    ``out`` must be a float array of length >= 9; returns it.
    """
    q0, q1, q2, q3 = estimate.quaternion
    sign = 1.0 if q0 >= 0.0 else -1.0
    out[0:3] = estimate.position
    out[3] = sign * q1
    out[4] = sign * q2
    out[5] = sign * q3
    vx, vy, vz = estimate.velocity_body
    # eCb @ v (eq. 2.20 read as body -> earth, see groundstation.model.quaternion)
    out[6] = ((q0 * q0 + q1 * q1 - q2 * q2 - q3 * q3) * vx + 2 * (q1 * q2 - q0 * q3) * vy
              + 2 * (q1 * q3 + q0 * q2) * vz)
    out[7] = (2 * (q1 * q2 + q0 * q3) * vx + (q0 * q0 - q1 * q1 + q2 * q2 - q3 * q3) * vy
              + 2 * (q2 * q3 - q0 * q1) * vz)
    out[8] = (2 * (q1 * q3 - q0 * q2) * vx + 2 * (q2 * q3 + q0 * q1) * vy
              + (q0 * q0 - q1 * q1 - q2 * q2 + q3 * q3) * vz)
    return out


def reference_outputs(reference: Reference, out: FloatArray) -> FloatArray:
    """Write the controlled outputs ``[x, y, z, q3]`` (4,) of ``reference`` into ``out``.

    ``q3 = sin(yaw / 2)`` is the z component of a pure heading quaternion
    (eq. 9.15 controls ``q3``).
    """
    out[0:3] = reference.position
    out[3] = np.sin(0.5 * reference.yaw)
    return out
