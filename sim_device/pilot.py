"""The RC pilot of the virtual lab: a stick source the tests and the lab can script.

By default the pilot holds neutral rate sticks (``sim.pilot_rate_sticks``) and a fixed
thrust stick (``sim.pilot_thrust``; 0 keeps the motors off on the floor). When the
vehicle falls back to the pilot in the air, the pilot holds the thrust it had (its rate
sticks as held), like a safety pilot whose stick sits near hover.
A script ``t -> Sticks`` replaces the fixed sticks, e.g. a manual take-off.
The pilot also owns the serial-enable switch (commands apply only while it is
on) and the RC link flag reported in STATUS.
"""

from __future__ import annotations

from collections.abc import Callable

from groundstation.types import Sticks
from sim_device.params import PilotParams

StickScript = Callable[[float], Sticks]
"""Sticks as a function of simulated time [s]."""


class Pilot:
    """The scripted pilot: fixed sticks or a script, the serial switch, the RC link.

    sticks : held sticks (thesis meaning: positive roll/pitch/yaw = positive FRD rate)
    script : when set, overrides ``sticks`` with ``script(t)``
    serial_enable : RC serial-enable switch; rc_link : RC link valid
    hold_thrust : take over the applied thrust when given the thrust channel in the air
    """

    __slots__ = ("hold_thrust", "rc_link", "script", "serial_enable", "sticks")

    def __init__(self, params: PilotParams | None = None) -> None:
        params = params if params is not None else PilotParams()
        roll, pitch, yaw = params.rate_sticks
        self.sticks = Sticks(roll=roll, pitch=pitch, yaw=yaw, thrust=params.thrust)
        self.script: StickScript | None = None
        self.serial_enable = params.serial_enable
        self.rc_link = params.rc_link
        self.hold_thrust = params.hold_thrust

    def take_over_thrust(self, thrust: int) -> None:
        """The thrust channel came back in flight: hold ``thrust``, rate sticks as held."""
        if self.hold_thrust and self.script is None:
            s = self.sticks
            self.sticks = Sticks(roll=s.roll, pitch=s.pitch, yaw=s.yaw, thrust=thrust)

    def sticks_at(self, t: float) -> Sticks:
        """The pilot's sticks at simulated time ``t`` [s]."""
        script = self.script
        return self.sticks if script is None else script(t)
