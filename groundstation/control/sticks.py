"""From a controller's physical output to RC stick units, saturated, with flags.

``omega`` [rad/s] becomes ``u = omega / K`` per axis (eq. 3.22) and ``F_z`` [N]
becomes the thrust stick through the inverse of the eq. 3.7 polynomial
(:class:`groundstation.model.ThrustMap`) applied to ``F_lift = F_z - m g``. The
results are rounded and saturated to the command ranges of the protocol
(roll/pitch/yaw -2048..2047, thrust 0..4096); the saturation flags tell the
controller's anti-windup which channels were clipped.

:class:`CommandLimits` gives the same ranges in physical units, so a controller
can saturate its own output (and stop integrating) before the conversion.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from groundstation.model import QuadrotorParams, ThrustMap
from groundstation.types import ControlOutput, FloatArray, Sticks

RATE_MIN, RATE_MAX = -2048, 2047
"""Roll/pitch/yaw stick range [RC units] (spec section 4)."""
THRUST_MIN, THRUST_MAX = 0, 4096
"""Thrust stick range [RC units] (spec section 4)."""


@dataclass(frozen=True, slots=True)
class SaturationFlags:
    """Which channels were clipped by :func:`to_sticks` (``invalid``: non-finite input)."""

    roll: bool = False
    pitch: bool = False
    yaw: bool = False
    thrust: bool = False
    invalid: bool = False

    @property
    def any(self) -> bool:
        """True if any channel was clipped or the input was not finite."""
        return self.roll or self.pitch or self.yaw or self.thrust or self.invalid


_NO_SATURATION = SaturationFlags()


@dataclass(frozen=True, slots=True)
class StickParams:
    """What the conversion needs: rate gains, thrust map, weight.

    k_rate : (K_phi, K_theta, K_psi) [rad/s per RC unit], non-zero (eq. 3.22);
    thrust_map : eq. 3.7 and its inverse; mass [kg]; g [m/s^2].
    """

    k_rate: tuple[float, float, float]
    thrust_map: ThrustMap
    mass: float
    g: float

    @classmethod
    def from_quadrotor(cls, params: QuadrotorParams) -> StickParams:
        """From the model parameters (``groundstation.model.QuadrotorParams``)."""
        if any(k == 0.0 or not math.isfinite(k) for k in params.k_rate):
            raise ValueError(f"k_rate must be finite and non-zero, got {params.k_rate!r}")
        return cls(tuple(params.k_rate), ThrustMap(params.thrust_poly),  # type: ignore[arg-type]
                   params.mass, params.g)

    @property
    def hover_thrust(self) -> int:
        """Thrust stick that balances the weight [RC units]."""
        return round(self.thrust_map.hover_stick(self.mass, self.g))


@dataclass(frozen=True, slots=True)
class CommandLimits:
    """The stick ranges in physical units.

    omega_min, omega_max : (3,) reachable body-rate set points [rad/s]
    (``K * -2048`` and ``K * 2047``, ordered); f_z_min, f_z_max : reachable
    ``F_z = F_lift + m g`` [N] over the monotonic thrust range (f_z_min is the
    most lift, negative).
    """

    omega_min: FloatArray
    omega_max: FloatArray
    f_z_min: float
    f_z_max: float

    @classmethod
    def from_stick_params(cls, params: StickParams) -> CommandLimits:
        """Limits implied by the rate gains and the thrust map's monotonic range."""
        k = np.asarray(params.k_rate, dtype=float)
        ends = np.vstack([k * RATE_MIN, k * RATE_MAX])
        f_most, f_least = params.thrust_map.force_range
        weight = params.mass * params.g
        return cls(ends.min(axis=0), ends.max(axis=0), f_most + weight, f_least + weight)


def _rate_stick(omega: float, k: float) -> tuple[int, bool]:
    u = omega / k
    if u > RATE_MAX:
        return RATE_MAX, True
    if u < RATE_MIN:
        return RATE_MIN, True
    return round(u), False


def to_sticks(output: ControlOutput, params: StickParams) -> tuple[Sticks, SaturationFlags]:
    """Convert ``output`` to stick units, saturated to the protocol ranges.

    Returns the sticks and which channels were clipped. A non-finite output
    (a controller bug) never reaches the wire: it becomes zero rates and the
    hover thrust, flagged ``invalid``.
    """
    w = output.omega
    f_z = output.f_z
    if not (math.isfinite(w[0]) and math.isfinite(w[1]) and math.isfinite(w[2])
            and math.isfinite(f_z)):
        return Sticks(0, 0, 0, params.hover_thrust), SaturationFlags(invalid=True)
    kx, ky, kz = params.k_rate
    roll, s_roll = _rate_stick(float(w[0]), kx)
    pitch, s_pitch = _rate_stick(float(w[1]), ky)
    yaw, s_yaw = _rate_stick(float(w[2]), kz)
    tm = params.thrust_map
    f_lift = f_z - params.mass * params.g
    s_thrust = not (tm.f_at_max <= f_lift <= tm.f_at_zero)
    thrust = min(max(round(tm.stick(f_lift)), THRUST_MIN), THRUST_MAX)
    sticks = Sticks(roll=roll, pitch=pitch, yaw=yaw, thrust=thrust)
    if s_roll or s_pitch or s_yaw or s_thrust:
        return sticks, SaturationFlags(s_roll, s_pitch, s_yaw, s_thrust)
    return sticks, _NO_SATURATION
