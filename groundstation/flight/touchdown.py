"""Feeling for the floor when a landing has only the IMU.

A landing with Vicon ends when the estimate sits at the floor. Without Vicon the estimate
is dead reckoning: the landing reference goes on below the floor (``touchdown_depth``,
then the creep), the controller keeps the estimate on it, and the accelerometer cannot
tell a vehicle resting on the floor from one descending at constant speed: both read
1 g. So the controller holds about the hover thrust on the floor and the supervisor's
floor contact (commanded lift well below the weight while the accelerometer still reads
1 g) never comes; where the true lift is a little more than the model's, the vehicle lifts
off again and climbs while its estimate descends through the floor (the virtual lab:
touched down, then 0.3-0.7 m up when the unconfirmed landing handed it back).

:class:`TouchdownProbe` asks the floor. Once the estimate is at the floor on dead
reckoning, it caps the commanded lift, lowering the cap from what was commanded at
:data:`LIFT_RAMP_PER_S` of the weight per second down to :data:`LIFT_FLOOR`. On the floor
nothing moves, the accelerometer keeps reading 1 g, and the lift passes below the
supervisor's contact fraction: contact, then DISARM. In the air the vehicle sinks and the
specific force falls with the lift; once it reads less than ``1 - air_tolerance`` g (the
probe at 0.8 of the weight: about 0.65 m/s down and 0.15 m lower after 0.7 s) the probe
stops for the rest of the landing and the controller has the thrust again; the landing
then ends as it did before (handed back when it stays unconfirmed).
"""

from __future__ import annotations

import math

LIFT_RAMP_PER_S = 0.3
"""How fast the cap on the commanded lift falls [fraction of the weight per second]: from
the hover to the supervisor's contact fraction (0.6) in 1.3 s."""

LIFT_FLOOR = 0.5
"""The lowest cap [fraction of the weight]: below the supervisor's contact fraction (0.6),
so contact on the floor is felt."""

FORCE_FILTER_S = 0.05
"""Time constant of the low-pass on the specific force the probe judges [s]: five IMU
samples, so one noisy sample does not end it."""


class TouchdownProbe:
    """The cap on the commanded lift while a landing on the IMU alone feels for the floor.

    air_tolerance : the specific force below ``1 - air_tolerance`` g [g] that says the
        vehicle is in the air (the supervisor's ``contact_accel_tolerance``)
    """

    def __init__(self, air_tolerance: float) -> None:
        self._tolerance = air_tolerance
        self._start: tuple[float, float] | None = None  # (t [s], lift fraction) at start
        self._force_g = 1.0
        self._t_force: float | None = None
        self._airborne = False

    @property
    def airborne(self) -> bool:
        """The probe found the vehicle in the air during this landing."""
        return self._airborne

    def update(self, t: float, blind_landing: bool, at_floor: bool, specific_force_g: float,
               lift_fraction: float) -> float | None:
        """The cap on the lift at ``t`` [s] as a fraction of the weight, or None (no cap).

        blind_landing : the vehicle is landing on the IMU alone (no Vicon fix)
        at_floor : its estimate is at the floor
        specific_force_g : the accelerometer's specific force [g], bias removed
        lift_fraction : the lift commanded last [fraction of the weight]
        """
        dt = 0.0 if self._t_force is None else max(t - self._t_force, 0.0)
        self._t_force = t
        self._force_g += (specific_force_g - self._force_g) * (1.0 - math.exp(-dt / FORCE_FILTER_S))
        if not blind_landing:
            self._airborne = False
        if not (blind_landing and at_floor) or self._airborne:
            self._start = None
            return None
        if self._start is None:
            self._start = (t, min(lift_fraction, 1.0))
        if self._force_g < 1.0 - self._tolerance:
            self._airborne = True
            self._start = None
            return None
        t0, lift0 = self._start
        return max(LIFT_FLOOR, lift0 - LIFT_RAMP_PER_S * (t - t0))
