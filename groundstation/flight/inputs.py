"""From DATA messages and Vicon poses to what the flight core consumes.

Shared by the real-time daemon and the in-process runner so both read the
vehicle identically: scale the IMU counts, read who flies the vehicle from the
STATUS and RC blocks, and measure the DATA rate and age.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from groundstation.asctec.messages import DataMsg
from groundstation.model.sensors import ImuScaling
from groundstation.types import ImuSample, Sticks
from groundstation.vicon.health import RateMonitor, ViconEvidence


@dataclass(frozen=True, slots=True)
class VehicleStatus:
    """What the X-3D reports about who flies it and its battery (STATUS and RC blocks).

    pilot : the pilot's sticks (RC block)
    pilot_enabled : RC serial-enable switch on
    applying : STATUS bit0, the X-3D is applying ground-station commands
    battery_v : battery voltage [V] (NaN until a STATUS block arrives)
    flags : the STATUS flags byte (bit0 serial control active, bit1 motors on, bit2 RC
        link valid; 0 without STATUS)
    applied_mask : the ctrl mask the X-3D applies (STATUS; 0 without STATUS)
    """

    pilot: Sticks
    pilot_enabled: bool
    applying: bool
    battery_v: float = math.nan
    flags: int = 0
    applied_mask: int = 0


@dataclass(frozen=True, slots=True)
class InputHealth:
    """Link and Vicon health as the loop measures them.

    data_age_s, data_rate_hz : time since the last DATA frame [s], its rate [Hz]
    vicon_age_s, vicon_rate_hz : time since the last accepted pose [s], its rate [Hz]
    vicon_last : NED [m] of the newest pose the pose filter passed (None before one)
    vicon_outside : NED [m] of a confirmed Vicon sighting beyond the plausible volume that
        is newer than any pose passed (None if there is none)
    vicon_rivals : confirmed pose streams of the object besides the one followed, now
    vicon_diagnosis : what the pose filter saw, in one line (called only when needed)
    peer_distance_m, peer_name : the nearest peer of a fleet, from this vehicle's estimate
        [m], and its name (inf and "" alone, or with no peer heard: groundstation/fleet)
    """

    data_age_s: float
    data_rate_hz: float
    vicon_age_s: float
    vicon_rate_hz: float
    vicon_last: tuple[float, float, float] | None = None
    vicon_outside: tuple[float, float, float] | None = None
    vicon_rivals: int = 0
    vicon_diagnosis: Callable[[], str] | None = None
    peer_distance_m: float = math.inf
    peer_name: str = ""


def with_vicon(health: InputHealth, evidence: ViconEvidence,
               diagnosis: Callable[[], str]) -> InputHealth:
    """``health`` with what the pose stream says beyond its poses (:class:`ViconEvidence`)
    and the pose filter's one-line ``diagnosis`` for a preflight failure."""
    return replace(health, vicon_last=evidence.last_position, vicon_outside=evidence.outside,
                   vicon_rivals=evidence.rivals, vicon_diagnosis=diagnosis)


class DataFrontEnd:
    """Turns each received DATA message into an IMU sample (scaled as ``imu`` says: the
    flight's :attr:`~groundstation.flight.params.FlightParams.imu`) and the vehicle's status.

    A frame without GYRO and ACC yields no IMU sample; without STATUS the X-3D is
    assumed to apply our commands and without RC the switch is assumed on (the
    configuration validator insists on gyro and acc; status and rc are advised).
    """

    def __init__(self, imu: ImuScaling, rate_window_s: float = 1.0) -> None:
        self._scaling = imu
        self._rate = RateMonitor(window_s=rate_window_s, min_rate_hz=0.0, max_rate_hz=math.inf)
        self._t_last = -math.inf
        self._gyro = np.zeros(3)
        self._acc = np.zeros(3)
        self.status = VehicleStatus(pilot=Sticks(), pilot_enabled=True, applying=False)

    def receive(self, t: float, msg: DataMsg) -> ImuSample | None:
        """Record a DATA message received at ``t`` [s]; return its scaled IMU sample."""
        self._rate.record(t)
        self._t_last = t
        status, rc = msg.status, msg.rc
        if status is not None or rc is not None:
            old = self.status
            self.status = VehicleStatus(
                pilot=rc.sticks() if rc is not None else old.pilot,
                pilot_enabled=rc.serial_enabled if rc is not None else True,
                applying=status.serial_active if status is not None else True,
                battery_v=1e-3 * status.battery_mv if status is not None else old.battery_v,
                flags=status.flags if status is not None else old.flags,
                applied_mask=status.ctrl_mask if status is not None else old.applied_mask,
            )
        if msg.gyro is None or msg.acc is None:
            return None
        g, a = msg.gyro, msg.acc
        self._gyro[:] = (g.x, g.y, g.z)
        self._acc[:] = (a.x, a.y, a.z)
        return self._scaling.scale(t, self._gyro, self._acc, msg.counter)

    def data_age(self, now: float) -> float:
        """Seconds since the last DATA frame (inf before the first)."""
        return now - self._t_last

    def health(self, now: float, vicon_age_s: float, vicon_rate_hz: float) -> InputHealth:
        """Link and Vicon health at ``now``."""
        return InputHealth(data_age_s=now - self._t_last, data_rate_hz=self._rate.rate(now),
                           vicon_age_s=vicon_age_s, vicon_rate_hz=vicon_rate_hz)
