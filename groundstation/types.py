"""Plain data records that cross module boundaries (see DESIGN.md data flow).

All arrays are float64 numpy arrays. Times are monotonic seconds.
Quaternions are scalar-first ``[q0, q1, q2, q3]`` describing the body attitude
(``R(q) = eCb``, body FRD -> earth NED); see :mod:`groundstation`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Final, Literal, get_args

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]

Channel = Literal["pitch", "roll", "yaw", "thrust"]
"""A stick channel of the vehicle; the COMMAND ctrl-mask bit is its index in
:data:`CHANNELS` (spec section 3.2)."""

CHANNELS: Final[tuple[Channel, ...]] = get_args(Channel)
"""Channels in ctrl-mask bit order (bit0 pitch, bit1 roll, bit2 yaw, bit3 thrust)."""

Dialect = Literal["x3d", "asctec-ll"]
"""The vehicle's serial dialect (``serial.protocol``): the X-3D's, or the AscTec AutoPilot
LL's (docs/protocol.md); configured, never guessed from the bytes."""

SensorBlockName = Literal["status", "gyro", "acc", "pressure", "rc"]
"""A block of the vehicle's DATA frame; the CONFIG mask bit is its index in
:data:`SENSOR_BLOCK_NAMES` (spec section 3.3)."""

SENSOR_BLOCK_NAMES: Final[tuple[SensorBlockName, ...]] = get_args(SensorBlockName)
"""DATA block names in mask bit order (bit0 status ... bit4 rc)."""


@dataclass(frozen=True, slots=True)
class ImuSample:
    """One scaled IMU sample from the X-3D DATA stream.

    t : monotonic receive time [s]
    gyro : (3,) body rates, FRD [rad/s]
    acc : (3,) specific force, FRD [m/s^2] (about (0, 0, -9.82) at rest)
    counter : the DATA sample counter (uint16, wraps), used to spot repeats
    """

    t: float
    gyro: FloatArray
    acc: FloatArray
    counter: int = 0


@dataclass(frozen=True, slots=True)
class Pose:
    """One Vicon pose in the project's frames.

    t : monotonic time of the measurement (receive time minus latency) [s]
    position : (3,) NED [m]
    quaternion : (4,) scalar-first attitude, unit norm
    frame : Vicon frame number (for diagnostics)
    """

    t: float
    position: FloatArray
    quaternion: FloatArray
    frame: int = 0


@dataclass(frozen=True, slots=True)
class Sticks:
    """Stick values in RC units, in the thesis's meaning (not wire order).

    roll, pitch, yaw : -2048..2047, positive = positive FRD body rate
    thrust : 0..4096, larger = more lift
    """

    roll: int = 0
    pitch: int = 0
    yaw: int = 0
    thrust: int = 0


@dataclass(frozen=True, slots=True)
class Reference:
    """Trajectory reference at one time.

    t : time since the trajectory started [s]
    position : (3,) NED [m]
    velocity : (3,) NED [m/s]
    acceleration : (3,) NED [m/s^2] (zeros where not defined)
    yaw : heading [rad], 3-2-1 Euler psi (the thesis controls q3 = sin(yaw / 2) near level)
    jerk : (3,) NED [m/s^3], the derivative of ``acceleration`` (zeros where not defined)
    yaw_rate : d yaw / dt [rad/s]
    """

    t: float
    position: FloatArray
    velocity: FloatArray
    acceleration: FloatArray = field(default_factory=lambda: np.zeros(3))
    yaw: float = 0.0
    jerk: FloatArray = field(default_factory=lambda: np.zeros(3))
    yaw_rate: float = 0.0


@dataclass(frozen=True, slots=True)
class StateEstimate:
    """The estimator's output, as the controller and the recorder see it.

    t : time of the estimate [s]
    position : (3,) NED [m]
    quaternion : (4,) scalar-first attitude (R(q) = eCb), unit norm
    velocity_body : (3,) velocity of the body relative to earth, in FRD axes [m/s]
    omega : (3,) bias-corrected body rates, FRD [rad/s] (last IMU sample)
    gyro_bias : (3,) estimated gyro bias, FRD [rad/s]
    acc_bias : (3,) estimated accelerometer bias, FRD [m/s^2]
    covariance_diag : (16,) diagonal of the state covariance, same order as the
        EKF state [P, q, v, gyro_bias, acc_bias]
    specific_force : (3,) bias-corrected accelerometer reading, FRD [m/s^2] (last IMU
        sample; about (0, 0, -g) in hover); NaN where no accelerometer was read
    """

    t: float
    position: FloatArray
    quaternion: FloatArray
    velocity_body: FloatArray
    omega: FloatArray
    gyro_bias: FloatArray
    acc_bias: FloatArray
    covariance_diag: FloatArray
    specific_force: FloatArray = field(default_factory=lambda: np.full(3, np.nan))


@dataclass(frozen=True, slots=True)
class ControlOutput:
    """What a controller asks of the vehicle, before conversion to stick units.

    omega : (3,) body-rate set points, FRD [rad/s] (the on-board rate loop tracks them)
    f_z : net vertical force in body z, F_z = F_lift + m g [N] (eq. 4.14;
        0 in hover, negative to climb since body z points down)
    """

    omega: FloatArray
    f_z: float
