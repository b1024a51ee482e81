"""The serial link's parameters: plain records the links are built from.

The configuration's ``serial`` section becomes a :class:`LinkParams` in one place,
:mod:`groundstation.flight.assembly`; nothing here reads the configuration.
"""

from __future__ import annotations

from dataclasses import dataclass

from groundstation.types import Dialect


@dataclass(frozen=True, slots=True)
class LlParams:
    """The AscTec LL dialect's link schedule and motor gesture (docs/protocol.md).

    status_every, rc_every : IMU polls per LL_STATUS and per RC_DATA poll [-]
    answer_timeout_s : a poll not answered completely by then is counted unanswered [s]
    ack_timeout_s : a command not acknowledged by then is counted missing [s]
    fallback_s : the vehicle's fallback after the last command [s]
    rc_channels : RC_DATA ``channels_out`` index of pitch, roll, thrust and yaw
    motor_start_yaw : the motor gesture's yaw to start the motors (the opposite stops)
        [stick units]
    motor_gesture_s : how long the gesture is held [s]
    """

    status_every: int
    rc_every: int
    answer_timeout_s: float
    ack_timeout_s: float
    fallback_s: float
    rc_channels: tuple[int, int, int, int]
    motor_start_yaw: int
    motor_gesture_s: float


@dataclass(frozen=True, slots=True)
class LinkParams:
    """The serial link to the vehicle.

    protocol : the dialect; port : device path or pyserial URL; baud : line rate [baud]
    crc_profile : the X-3D dialect's CRC16 profile (spec section 2)
    sensor_mask : the DATA blocks the X-3D is asked to stream (CONFIG mask, spec 3.3)
    data_period_ms : IMU period the vehicle streams (X-3D) or is polled at (LL) [ms]
    command_rate_hz : the COMMAND rate the keep-alive guarantees while armed [Hz]
    stale_command_s : how long the keep-alive re-sends the loop's last command [s]
    ll : the LL dialect's schedule (read with protocol ``asctec-ll`` only)
    """

    protocol: Dialect
    port: str
    baud: int
    crc_profile: str
    sensor_mask: int
    data_period_ms: int
    command_rate_hz: float
    stale_command_s: float
    ll: LlParams

    @property
    def data_period_s(self) -> float:
        """The IMU period [s]."""
        return self.data_period_ms / 1000.0
