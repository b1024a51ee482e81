"""Nonlinear quadrotor model of thesis eq. 3.19-3.22 (Ch. 3).

State ``x`` (10,) = ``[P (3), q (4), v (3)]``:

* ``P`` position of the body in NED [m] (hover 1 m above the floor is ``z = -1``)
* ``q`` attitude, scalar-first unit quaternion, ``R(q) = eCb`` (body FRD -> NED)
* ``v`` velocity of the body relative to earth, in body FRD axes [m/s]

Input ``u`` (4,) = ``[omega_x, omega_y, omega_z, F_z]`` (this order, chosen to
match :class:`groundstation.types.ControlOutput`):

* ``omega`` body-rate set points, FRD [rad/s]; the on-board rate loop is taken
  as ideal (eq. 3.22: ``omega = K * u_stick``), so the body rates equal them;
* ``F_z = F_lift + m g`` [N], the net vertical body-z force (the thesis's
  linearising input, Ch. 4): 0 in hover, negative to climb (body z points down).

Dynamics (eq. 3.19-3.21, with ``F_lift = F_z - m g`` along body z)::

    P_dot = eCb v
    q_dot = 0.5 q ⊗ [0, omega]
    v_dot = (F_lift + I_i v_3)/m e_3 + bCe [0, 0, g] - omega × v

:func:`inputs_from_sticks` converts RC stick units to ``u`` through the rate gains
and the thrust polynomial; :meth:`QuadrotorModel.specific_force` is what an
ideal body-mounted accelerometer reads.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from groundstation.model.quaternion import dcm_from_quat
from groundstation.model.thrust import THRUST_POLY_EQ37, ThrustMap
from groundstation.types import FloatArray, Sticks

__all__ = ["HOVER_STATE", "QuadrotorModel", "QuadrotorParams", "inputs_from_sticks"]

HOVER_STATE: FloatArray = np.array([0.0, 0.0, -1.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0])
"""Hover 1 m above the origin, level, facing north, at rest: ``[P, q, v]``."""


@dataclass(frozen=True, slots=True)
class QuadrotorParams:
    """Physical parameters of the X-3D model.

    mass : vehicle mass [kg]. Not printed in the thesis; 0.60 kg makes the eq. 3.7
        polynomial hover near mid-stick (F_lift(2000) = -5.92 N ~ -m g; the exact
        hover stick is about 1990).
    g : gravitational acceleration [m/s^2] (9.82 in Denmark, Ch. 3.4).
    k_rate : (K_phi, K_theta, K_psi), body rate per stick unit [rad/s per unit].
        Not printed; the maximum roll step (2047) gave 2.25 rad/s (Ch. 3.3.1), so
        1.1e-3 for all three axes. Positive: a positive stick commands a positive
        FRD body rate (DESIGN.md).
    inflow : induced-inflow constant I_i [N s/m] (eq. 3.9, Table C.2): force
        ``I_i * v_3`` along body z.
    thrust_poly : (a3, a2, a1, a0) of F_lift(u_thrust) [N] (eq. 3.7; negative = up).
    rate_tau : time constant [s] of the on-board rate loop when modelled as a
        first-order lag (the lagged linear model and the controller designs on it):
        Fig. 3.8's 10-90 % rise of 0.14 s is 2.2 tau for a first-order lag.
    input_delay : time [s] from the state a command is computed from to the moment the
        vehicle applies it: the command link's transport delay (20 ms) plus the time
        the DATA frame (41 bytes) and the COMMAND frame (23 bytes) take on a 57600-baud
        wire (11.1 ms). The controllers model it (:mod:`groundstation.control.augmented`).
    """

    mass: float = 0.60
    g: float = 9.82
    k_rate: tuple[float, float, float] = (1.1e-3, 1.1e-3, 1.1e-3)
    inflow: float = -0.423
    thrust_poly: tuple[float, float, float, float] = THRUST_POLY_EQ37
    rate_tau: float = 0.064
    input_delay: float = 0.0311

    def __post_init__(self) -> None:
        """Validate once: positive mass, g, tau; finite gains; three rate gains."""
        if not (self.mass > 0.0 and self.g > 0.0 and self.rate_tau > 0.0):
            raise ValueError(f"mass, g and rate_tau must be > 0, got {self!r}")
        if not (self.input_delay >= 0.0 and math.isfinite(self.input_delay)):
            raise ValueError(f"input_delay must be a finite time >= 0, got {self.input_delay!r}")
        if len(self.k_rate) != 3 or not all(math.isfinite(k) for k in self.k_rate):
            raise ValueError(f"k_rate must be three finite gains, got {self.k_rate!r}")
        if len(self.thrust_poly) != 4:
            raise ValueError(f"thrust_poly must be (a3, a2, a1, a0), got {self.thrust_poly!r}")


def inputs_from_sticks(sticks: Sticks, params: QuadrotorParams) -> FloatArray:
    """Model input ``[omega_x, omega_y, omega_z, F_z]`` from RC sticks (eq. 3.7, 3.22).

    omega = K * (roll, pitch, yaw) [rad/s]; F_z = F_lift(thrust) + m g [N].
    """
    kx, ky, kz = params.k_rate
    f_lift = ThrustMap(params.thrust_poly).force(float(sticks.thrust))
    return np.array(
        [kx * sticks.roll, ky * sticks.pitch, kz * sticks.yaw, f_lift + params.mass * params.g]
    )


class QuadrotorModel:
    """Continuous-time nonlinear model ``x_dot = f(x, u)`` (eq. 3.19-3.22).

    See the module docstring for the state and input layout.
    """

    def __init__(self, params: QuadrotorParams | None = None) -> None:
        self.params = params if params is not None else QuadrotorParams()

    def derivative(self, x: FloatArray, u: FloatArray) -> FloatArray:
        """``x_dot`` (10,) for state ``x`` (10,) and input ``u`` (4,)."""
        p = self.params
        q = x[3:7]
        v = x[7:10]
        omega = u[0:3]
        R = dcm_from_quat(q)
        xdot = np.empty(10)
        xdot[0:3] = R @ v
        w1, w2, w3 = omega
        q0, q1, q2, q3 = q
        xdot[3] = 0.5 * (-w1 * q1 - w2 * q2 - w3 * q3)
        xdot[4] = 0.5 * (w1 * q0 + w3 * q2 - w2 * q3)
        xdot[5] = 0.5 * (w2 * q0 - w3 * q1 + w1 * q3)
        xdot[6] = 0.5 * (w3 * q0 + w2 * q1 - w1 * q2)
        acc = p.g * R[2, :]  # bCe @ [0, 0, g] = g * (third row of eCb)
        acc[2] += (u[3] - p.mass * p.g + p.inflow * v[2]) / p.mass
        # acc - omega x v, written out: np.cross on 3-vectors took most of a simulation's time
        v1, v2, v3 = v
        xdot[7] = acc[0] - (w2 * v3 - w3 * v2)
        xdot[8] = acc[1] - (w3 * v1 - w1 * v3)
        xdot[9] = acc[2] - (w1 * v2 - w2 * v1)
        return xdot

    def specific_force(self, x: FloatArray, u: FloatArray) -> FloatArray:
        """Specific force in body axes [m/s^2], (3,): non-gravitational force / m.

        What an ideal accelerometer at the centre of mass reads: rotor lift plus
        induced-inflow drag, ``[0, 0, (F_lift + I_i v_3)/m]``; about (0, 0, -g) in hover.
        """
        p = self.params
        return np.array([0.0, 0.0, (u[3] - p.mass * p.g + p.inflow * x[9]) / p.mass])

    def step(self, x: FloatArray, u: FloatArray, dt: float) -> FloatArray:
        """One RK4 step of length ``dt`` [s] with ``u`` held; the quaternion is renormalised."""
        k1 = self.derivative(x, u)
        k2 = self.derivative(x + 0.5 * dt * k1, u)
        k3 = self.derivative(x + 0.5 * dt * k2, u)
        k4 = self.derivative(x + dt * k3, u)
        out: FloatArray = x + (dt / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
        out[3:7] /= np.linalg.norm(out[3:7])
        return out

    def hover_input(self) -> FloatArray:
        """The equilibrium input at level hover: zero rates and ``F_z = 0``."""
        return np.zeros(4)
