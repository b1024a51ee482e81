"""Absolute plausibility of one Vicon object item: could Tracker have seen it there?

Every pose of the tracked object passes this before anything else, at
start-up and after a gap too, and before any arithmetic that could overflow:

1. **Raw values** (Vicon's mm and radians, already known to be finite): every
   translation component within the radius of the sighting range, so the
   conversion to metres and NED cannot produce anything huge; every Euler angle
   within one turn (no XYZ decomposition needs more; Tracker reports (-pi, pi]).
2. **Converted pose**: the quaternion finite and of unit norm (a rotation that is
   not a rotation means the values were not an attitude), and the NED position
   inside the sighting range.

Two boxes, NED [m]:

* the **plausible volume**, the flight volume (``safety.volume_x/y/z``) grown by
  ``vicon.plausibility_margin_m``
  (:meth:`groundstation.config.ViconConfig.plausible_volume`): where a pose may be
  passed on to the estimator;
* the **sighting range**, the plausible volume grown by :data:`SIGHTING_MARGIN_M` on
  every side: where Tracker can see the vehicle at all. A pose beyond it is absurd
  and refused. A pose inside the range but outside the plausible volume is
  :data:`OUTSIDE`: the vehicle may really have left the volume, so the pose filter
  sorts it into its pose streams like any other (a vehicle crossing the boundary
  continues its stream) and reports it as a sighting, never as a pose to fuse.

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

def grown(box: Box, margin: float) -> Box:
    """``box`` grown by ``margin`` [m] on every side (the flight volume grown by
    ``vicon.plausibility_margin_m`` is where a pose can be)."""
    (x0, x1), (y0, y1), (z0, z1) = box
    return ((x0 - margin, x1 + margin), (y0 - margin, y1 + margin), (z0 - margin, z1 + margin))


SIGHTING_MARGIN_M: Final = 10.0
"""How far beyond the plausible volume a pose is still a sighting, not absurd [m].
Tracker's cameras look into one room; a lab room reaches a few metres, not ten, past
any flight volume drawn in it, and a vehicle leaving the volume at the gate's 5 m/s is
seen for at most two seconds before it leaves the cameras' view. Anything further is
no vehicle Tracker can have seen (a garbage value or a hostile sender)."""

MAX_ANGLE: Final = 2.0 * math.pi
"""Largest |Euler angle| accepted [rad]: one turn (Tracker reports (-pi, pi])."""

UNIT_TOLERANCE: Final = 1e-6
"""Largest | |q|^2 - 1 | of a converted quaternion (a rotation gives ~1e-16)."""

POSITION: Final = "position"
"""The position is beyond the sighting range (absurd)."""
ROTATION: Final = "rotation"
"""The angles are no attitude."""
OUTSIDE: Final = "outside"
"""A sighting: inside the sighting range, outside the plausible volume."""


@dataclass(frozen=True, slots=True)
class Plausibility:
    """The absolute checks for one plausible volume (build with :meth:`create`).

    volume : the plausible volume, NED [m]
    sighting : the sighting range, ``volume`` grown by :data:`SIGHTING_MARGIN_M`, NED [m]
    radius_mm : the largest distance of any point of the sighting range from the origin
        [mm]; a translation component beyond it cannot be inside, whatever the rotation
    """

    volume: Box
    sighting: Box
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
        m = SIGHTING_MARGIN_M
        grown = [(lo - m, hi + m) for lo, hi in bounds]
        far = [max(abs(lo), abs(hi)) for lo, hi in grown]
        box: Box = (bounds[0], bounds[1], bounds[2])
        sighting: Box = (grown[0], grown[1], grown[2])
        return cls(box, sighting, 1000.0 * math.sqrt(sum(f * f for f in far)))

    def raw(self, translation: tuple[float, float, float],
            rotation: tuple[float, float, float]) -> str | None:
        """Check finite raw values (translation [mm], Euler XYZ [rad]) before conversion.

        Returns None if they may be a pose in the sighting range, else :data:`POSITION`
        or :data:`ROTATION` (what is wrong).
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
        """Check a converted pose: ``quaternion`` (4,) finite with unit norm, ``position``
        (3,) NED [m] inside the sighting range and the plausible volume.

        Returns None if plausible, :data:`OUTSIDE` for a sighting outside the plausible
        volume, else what is wrong (:data:`ROTATION`, :data:`POSITION`).
        """
        q0, q1, q2, q3 = quaternion.tolist()
        n2 = q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3
        if not abs(n2 - 1.0) <= UNIT_TOLERANCE:  # also NaN
            return ROTATION
        x, y, z = position.tolist()
        if not _inside(self.sighting, x, y, z):
            return POSITION
        if not _inside(self.volume, x, y, z):
            return OUTSIDE
        return None


def _inside(box: Box, x: float, y: float, z: float) -> bool:
    """Whether NED (x, y, z) [m] lies in ``box`` (boundaries included)."""
    (x0, x1), (y0, y1), (z0, z1) = box
    return x0 <= x <= x1 and y0 <= y <= y1 and z0 <= z <= z1
