"""What a reference may ask of the vehicle in flight: the feasibility check's limits, per tick.

The feasibility check (:mod:`groundstation.control.feasibility`) refuses before flight a
trajectory that asks more than the vehicle can give. In flight the same quantities are
checked on every reference the controller is about to track, because the reference
comes from code, files and requests that can be wrong between the points any check
looked at (a dense waypoint file flown as rest-to-rest corners asked 69 m/s^2 between
10 ms knots). A reference beyond the envelope is a fault, not an input: the flight core
feeds the controller no acceleration or jerk from it and the supervisor lands.

The quantities are the point-mass inversion of the check, per unit mass (NED, e3 down)::

    f = a - g e3 - (I_i / m) v3 e3          required specific thrust [m/s^2]
    lift = m |f|,  tilt = angle(-f, -e3),  tilt rate = |f'_perp| / |f|,  f' ~ j

The margins leave room for rounding at the limits and for what the check may measure
differently (a trajectory that does not describe itself in pieces is checked on samples,
its tilt rate as the change of direction over 0.1 s); they are far below the faults they
exist for (the fly-away's reference asked 82 deg of tilt and 84,500 m/s^3).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from groundstation.control.feasibility import FlightLimits
from groundstation.types import Reference

TILT_MARGIN = 1.5
"""Tilt allowed in flight / the trajectory tilt limit."""
LIFT_MARGIN = 1.25
"""Largest lift allowed in flight / the rotors' most (and the least allowed x 1/2)."""
RATE_MARGIN = 3.0
"""Tilt rate allowed in flight / the body-rate limit: a sampled check's 0.1 s average of a
min-jerk corner's tilt rate lies below the instant's peak."""


@dataclass(frozen=True, slots=True)
class ReferenceEnvelope:
    """The per-tick bounds of a reference (build with :meth:`from_limits`).

    g [m/s^2], inflow_per_mass I_i / m [1/s]; max_tilt_rad; lift_min_n, lift_max_n [N]
    and mass_kg; max_tilt_rate_rad_s: all with their margins applied.
    """

    g: float
    inflow_per_mass: float
    mass_kg: float
    max_tilt_rad: float
    lift_min_n: float
    lift_max_n: float
    max_tilt_rate_rad_s: float

    @classmethod
    def from_limits(cls, limits: FlightLimits) -> ReferenceEnvelope:
        """The envelope of what the feasibility check allows under ``limits``."""
        return cls(g=limits.gravity, inflow_per_mass=limits.induced_inflow / limits.mass_kg,
                   mass_kg=limits.mass_kg,
                   max_tilt_rad=min(TILT_MARGIN * limits.max_tilt_rad, math.radians(80.0)),
                   lift_min_n=0.5 * limits.lift_min_n, lift_max_n=LIFT_MARGIN * limits.lift_max_n,
                   max_tilt_rate_rad_s=RATE_MARGIN * limits.max_rate_rad_s)

    def fault(self, ref: Reference) -> str:
        """Why ``ref`` is beyond the envelope ("" if it is not)."""
        ax, ay, az = ref.acceleration.tolist()
        jx, jy, jz = ref.jerk.tolist()
        vz = float(ref.velocity[2])
        fx, fy, fz = ax, ay, az - self.g - self.inflow_per_mass * vz
        norm = math.sqrt(fx * fx + fy * fy + fz * fz)
        if not math.isfinite(norm) or not math.isfinite(jx + jy + jz):
            return "the reference is not finite"
        lift = self.mass_kg * norm
        accel = math.sqrt(ax * ax + ay * ay + az * az)
        if lift > self.lift_max_n or lift < self.lift_min_n:
            return (f"it asks {lift:.1f} N of lift ({accel:.1f} m/s^2), the rotors give "
                    f"{self.lift_min_n / 0.5:.1f} to {self.lift_max_n / LIFT_MARGIN:.1f} N")
        tilt = math.acos(min(max(-fz / norm, -1.0), 1.0))
        if tilt > self.max_tilt_rad:
            return (f"it asks {math.degrees(tilt):.0f} deg of tilt ({accel:.1f} m/s^2), "
                    f"more than {math.degrees(self.max_tilt_rad):.0f} deg")
        # the part of f' (~ j, with the inflow's small share left out) across f
        dot = (jx * fx + jy * fy + jz * fz) / (norm * norm)
        px, py, pz = jx - dot * fx, jy - dot * fy, jz - dot * fz
        rate = math.sqrt(px * px + py * py + pz * pz) / norm
        if rate > self.max_tilt_rate_rad_s:
            jerk = math.sqrt(jx * jx + jy * jy + jz * jz)
            return (f"it asks a tilt rate of {rate:.1f} rad/s ({jerk:.0f} m/s^3 of jerk), more "
                    f"than {self.max_tilt_rate_rad_s:.1f} rad/s")
        return ""
