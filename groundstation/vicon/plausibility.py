"""Absolute plausibility of one Vicon object item: could the vehicle be there, so?

Every pose of the tracked object passes this before anything else (issue 14), at
start-up and after a gap too, and before any arithmetic that could overflow:

1. **Raw values** (Vicon's mm and radians, already known to be finite): every
   translation component within the radius of the plausible volume, so the
   conversion to metres and NED cannot produce anything huge; every Euler angle
   within one turn (no XYZ decomposition needs more; Tracker reports (-pi, pi]).
2. **Converted pose**: the NED position inside the plausible volume, the
   quaternion finite and of unit norm (a rotation that is not a rotation means
   the values were not an attitude).

The plausible volume is the flight volume (``safety.volume_x/y/z``) grown by
``vicon.plausibility_margin_m`` (:meth:`groundstation.config.ViconConfig.plausible_volume`).
Only comparisons and Python float arithmetic on bounded values: no numpy warning.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Final

from groundstation.errors import ConfigError
from groundstation.types import FloatArray

Box = tuple[tuple[float, float], tuple[float, float], tuple[float, float]]
"""An axis-aligned box ``((x_min, x_max), (y_min, y_max), (z_min, z_max))``, NED [m]."""

DEFAULT_VOLUME: Final[Box] = ((-2.0, 2.0), (-2.0, 2.0), (-2.5, 0.55))
"""The configuration's defaults: ``safety.volume_x/y/z`` (Table B.1: +/-1.5 m, 0..2 m
height, z to +0.05 m) grown by ``vicon.plausibility_margin_m`` (0.5 m)."""

MAX_ANGLE: Final = 2.0 * math.pi
"""Largest |Euler angle| accepted [rad]: one turn (Tracker reports (-pi, pi])."""

UNIT_TOLERANCE: Final = 1e-6
"""Largest | |q|^2 - 1 | of a converted quaternion (a rotation gives ~1e-16)."""

POSITION: Final = "position"
ROTATION: Final = "rotation"


@dataclass(frozen=True, slots=True)
class Plausibility:
    """The absolute checks for one plausible volume (build with :meth:`create`).

    volume : the plausible volume, NED [m]
    radius_mm : the largest distance of any point of the volume from the origin [mm];
        a translation component beyond it cannot be inside, whatever the rotation
    """

    volume: Box
    radius_mm: float

    @classmethod
    def create(cls, volume: Box = DEFAULT_VOLUME) -> Plausibility:
        """Validate ``volume`` (finite, each min < max; ConfigError otherwise)."""
        bounds = [(float(lo), float(hi)) for lo, hi in volume]
        if len(bounds) != 3 or not all(
            math.isfinite(lo) and math.isfinite(hi) and lo < hi for lo, hi in bounds
        ):
            raise ConfigError("invalid plausible volume",
                              [("plausible_volume", volume, "three finite (min, max), min < max")])
        far = [max(abs(lo), abs(hi)) for lo, hi in bounds]
        box: Box = (bounds[0], bounds[1], bounds[2])
        return cls(box, 1000.0 * math.sqrt(sum(f * f for f in far)))

    def raw(self, translation: tuple[float, float, float],
            rotation: tuple[float, float, float]) -> str | None:
        """Check finite raw values (translation [mm], Euler XYZ [rad]) before conversion.

        Returns None if they may be a pose in the volume, else :data:`POSITION` or
        :data:`ROTATION` (what is wrong).
        """
        r = self.radius_mm
        x, y, z = translation
        if abs(x) > r or abs(y) > r or abs(z) > r:
            return POSITION
        a, b, c = rotation
        if abs(a) > MAX_ANGLE or abs(b) > MAX_ANGLE or abs(c) > MAX_ANGLE:
            return ROTATION
        return None

    def converted(self, position: FloatArray, quaternion: FloatArray) -> str | None:
        """Check a converted pose: ``position`` (3,) NED [m] inside the volume,
        ``quaternion`` (4,) finite with unit norm. None if plausible, else the reason."""
        (x0, x1), (y0, y1), (z0, z1) = self.volume
        x, y, z = position.tolist()
        if not (x0 <= x <= x1 and y0 <= y <= y1 and z0 <= z <= z1):
            return POSITION
        q0, q1, q2, q3 = quaternion.tolist()
        n2 = q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3
        if not abs(n2 - 1.0) <= UNIT_TOLERANCE:  # also NaN
            return ROTATION
        return None
