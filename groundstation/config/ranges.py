"""The physical range of every number in the configuration, each with its source.

Every number with a physical range is checked against it, not only for its type: a
configuration with gyro_scale -187564 or a Vicon variance of 1.2e29 is a typo, and it
is refused before a flight, naming the field, the value, the range and where the range
comes from (a thesis table, physics, the hardware). :func:`within` and
:func:`magnitude_within` make a range a validator; the named types below are the ranges
the sections share; paths and addresses are checked for what they name.
"""

from __future__ import annotations

import math
import stat
from pathlib import Path
from typing import Annotated

from pydantic import AfterValidator, Field

from groundstation.endpoints import host_address, zenoh_endpoint, zmq_endpoint
from groundstation.model.quadrotor import QuadrotorParams
from groundstation.model.sensors import (
    ACC_VARIANCE_TABLE_6_3,
    GYRO_VARIANCE_TABLE_6_3,
    K_ACC_TABLE_6_2,
    K_GYRO_TABLE_6_2,
    VICON_POSITION_VARIANCE_TABLE_6_1,
    VICON_QUATERNION_VARIANCE_TABLE_6_1,
)


def _interval(lo: float | None, hi: float | None, lo_open: bool, hi_open: bool) -> str:
    left = "(" if lo_open or lo is None else "["
    right = ")" if hi_open or hi is None else "]"
    low = "-inf" if lo is None else f"{lo:g}"
    high = "inf" if hi is None else f"{hi:g}"
    return f"{left}{low}, {high}{right}"


def within(lo: float | None, hi: float | None, why: str, *, lo_open: bool = False,
           hi_open: bool = False) -> AfterValidator:
    """The physical range of one number, as a validator for ``Annotated[float, ...]``
    (or ``int``): ``lo <= value <= hi``, strict where ``lo_open``/``hi_open``, no bound
    on a side given as None. Outside it the error gives the range and ``why`` (the
    range's source: a thesis table, physics, the hardware); the field path and the value
    come with every error (:func:`validate_config`)."""
    interval = _interval(lo, hi, lo_open, hi_open)

    def check(value: float) -> float:
        low = lo is not None and (value <= lo if lo_open else value < lo)
        high = hi is not None and (value >= hi if hi_open else value > hi)
        if low or high:
            raise ValueError(f"outside {interval}: {why}")
        return value

    return AfterValidator(check)


def magnitude_within(lo: float, hi: float, why: str) -> AfterValidator:
    """Like :func:`within` for a number whose sign is free (a sensor scale or a rate gain
    is negative for an axis mounted reversed): ``lo <= |value| <= hi``."""

    def check(value: float) -> float:
        if not lo <= abs(value) <= hi:
            raise ValueError(f"magnitude outside [{lo:g}, {hi:g}] (either sign): {why}")
        return value

    return AfterValidator(check)


LAB_EXTENT_M = 100.0
"""Largest coordinate, length or volume bound in the configuration [m]: a motion-capture
hall, not a field (Table B.1's tracked volume is +-1.5 m; the largest indoor flight arenas
are tens of metres). A centre or a volume beyond it is a typo, not a lab."""

LabCoordinate = Annotated[float, within(-LAB_EXTENT_M, LAB_EXTENT_M,
                                        "a coordinate in the lab [m] (LAB_EXTENT_M)")]
LabLength = Annotated[float, within(0.0, LAB_EXTENT_M, "a length in the lab [m] "
                                    "(LAB_EXTENT_M)", lo_open=True)]
TurnDeg = Annotated[float, within(-360.0, 360.0, "an angle or heading within one turn "
                                  "either way [deg]")]
TiltDeg = Annotated[float, within(0.0, 90.0, "a tilt limit [deg]: at 90 deg the rotors "
                                  "lift nothing and beyond it they push down",
                                  lo_open=True, hi_open=True)]

COMMAND_RATE_MAX_HZ = 100.0
"""The fastest command rate accepted (serial.command_rate_hz; spec section 4's 50-100 Hz)."""

NYQUIST_RAD_S = math.pi * COMMAND_RATE_MAX_HZ
"""The highest frequency a loop stepped at the fastest command rate can realise [rad/s]:
no pole, bandwidth or loop gain [1/s] of a controller here can be faster (314 rad/s)."""

DAY_S = 86_400.0
"""A day [s]: no flight, not even a simulated one, has an event or a period longer."""


def _kind(path: Path) -> str:
    """What a path is on this machine, for an error: 'a regular file', 'a character
    device', ..."""
    try:
        mode = path.stat().st_mode
    except FileNotFoundError:
        return "a broken symbolic link" if path.is_symlink() else "nothing"
    except OSError as exc:
        return f"unreadable ({exc.strerror})"
    for test, name in ((stat.S_ISDIR, "a directory"), (stat.S_ISREG, "a regular file"),
                       (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"),
                       (stat.S_ISFIFO, "a named pipe"), (stat.S_ISSOCK, "a socket")):
        if test(mode):
            return name
    return "a special file"


def _nearest_existing(path: Path) -> Path | None:
    """``path`` or its nearest ancestor that exists (relative paths stay relative: the
    working directory is the flight's, and need not be looked up)."""
    for candidate in (path, *path.parents):
        if candidate.exists() or candidate.is_symlink():
            return candidate
    return None


def _directory_key(value: Path | None) -> Path | None:
    """A directory the ground station reads or writes: an existing directory, or one
    that can be made (its nearest existing ancestor is a directory, as the flight
    recorder makes it with its parents). Never a device or a regular file."""
    if value is None:
        return value
    found = _nearest_existing(value)
    if found == value and not value.is_dir():
        raise ValueError(f"names {_kind(value)}, not a directory")
    if found is not None and found != value and not found.is_dir():
        raise ValueError(f"cannot be made: {str(found)!r} is {_kind(found)}, not a directory")
    return value


def _file_key(value: Path | None) -> Path | None:
    """A file the ground station reads or writes: a regular file where it exists (never a
    device, a pipe or a directory). Whether it exists is checked where it is needed
    (:func:`check_files` for the files a flight reads)."""
    if value is None:
        return value
    found = _nearest_existing(value)
    if found == value and not value.is_file():
        raise ValueError(f"names {_kind(value)}, not a regular file")
    if found is not None and found != value and not found.is_dir():
        raise ValueError(f"cannot exist: {str(found)!r} is {_kind(found)}, not a directory")
    return value


DirectoryPath = Annotated[Path, AfterValidator(_directory_key)]
FilePath = Annotated[Path, AfterValidator(_file_key)]

HostAddress = Annotated[str, AfterValidator(host_address)]
"""The address of a UDP socket (IPv4: the Vicon client and sender are AF_INET)."""

ZmqEndpoint = Annotated[str, AfterValidator(zmq_endpoint)]
ZenohEndpoint = Annotated[str, AfterValidator(zenoh_endpoint)]
"""A fleet member's Zenoh locator, ``PROTOCOL/HOST:PORT`` (``fleet.zenoh``, fleet.yaml)."""



RcChannel = Annotated[int, within(0, 7, "an index into RC_DATA's channels_out[8] (spec)")]


VICON_RATE_MAX_HZ = 2000.0
"""The fastest a Vicon system streams [Hz] (its cameras' top frame rate)."""


GRAVITY_RANGE_M_S2 = (9.76, 9.84)
"""Gravity at the Earth's surface [m/s^2]: 9.76 on the highest equatorial summits to 9.83
at the poles; the thesis's 9.82 (eq. 3.8) is Denmark's."""

THRUST_MAX_N = 500.0
"""Largest lift a thrust map may give over the stick range 0..4095 [N]: the heaviest vehicle
accepted (vehicle.mass_kg <= 20 kg) at a thrust-to-weight ratio of 2.5. The X-3D's eq. 3.7
gives 10 N at full stick."""

_K_RATE = max(abs(k) for k in QuadrotorParams().k_rate)

RateGain = Annotated[float, magnitude_within(
    _K_RATE / 100, _K_RATE * 100,
    "rad/s per stick unit, two decades either side of Ch. 3.3.1's (2.25 rad/s at stick "
    "2047): full stick from 0.02 to 225 rad/s")]
GyroScale = Annotated[float, magnitude_within(
    min(K_GYRO_TABLE_6_2) / 1000, max(K_GYRO_TABLE_6_2) * 50,
    "rad/s per count, 1/1000 to 50 x Table 6.2's: from 16-bit counts (the LL dialect's "
    "int16) over a MEMS gyro's narrowest range (+-50 deg/s: 2.7e-5) to 10-bit counts "
    "(Ch. 6.2's 0..1023) over its widest (+-4000 deg/s: 0.14)")]
AccScale = Annotated[float, magnitude_within(
    min(K_ACC_TABLE_6_2) / 1000, max(K_ACC_TABLE_6_2) * 50,
    "m/s^2 per count, 1/1000 to 50 x Table 6.2's: from 16-bit counts over a MEMS "
    "accelerometer's narrowest range (+-2 g: 6e-4) to 10-bit counts over its widest "
    "(+-16 g: 0.31)")]
AdcZero = Annotated[float, within(-32768.0, 65535.0, "counts: the zero lies in the ADC's "
                                  "range, 12-bit 0..4095 (X-3D) or int16 (LL dialect)")]


def variance_band(table: tuple[float, ...]) -> tuple[float, float]:
    """Where a sensor's noise variance may lie: from 1/1000 of the smallest of its thesis
    table to 10^4 times the largest. Below, a sensor better than any of its class; above,
    a deviation 100 times the one measured is no sensor (the room above lets a tuning
    de-weight one)."""
    return min(table) / 1e3, max(table) * 1e4


def _variance(table: tuple[float, ...], source: str, unit: str) -> AfterValidator:
    return within(*variance_band(table),
                  f"{unit}, from 1/1000 to 10^4 x {source}'s: a variance of this sensor, not "
                  "a typo")


GyroVariance = Annotated[float, _variance(GYRO_VARIANCE_TABLE_6_3, "Table 6.3", "(rad/s)^2")]
AccVariance = Annotated[float, _variance(ACC_VARIANCE_TABLE_6_3, "Table 6.3", "(m/s^2)^2")]
ViconPositionVariance = Annotated[float, _variance(VICON_POSITION_VARIANCE_TABLE_6_1,
                                                   "Table 6.1", "m^2")]
ViconQuaternionVariance = Annotated[float, _variance(VICON_QUATERNION_VARIANCE_TABLE_6_1,
                                                     "Table 6.1", "quaternion units^2")]
RateLoopTau = Annotated[float, within(
    0.0, 1.0, "s: a rate loop slower than a second could not hold a hover (Fig. 3.8 rises "
    "in 0.14 s)", lo_open=True)]
CommandDelay = Annotated[float, within(
    0.0, 0.5, "s: one 50 Hz command period is 20 ms; half a second is 25 periods, more "
    "than any radio link of the class lags")]


_WEIGHT_WHY = ("weights are relative: six decades either side of 1, beyond which Q over R "
               "spans more than the 10^12 a Riccati solution in doubles resolves")
Weight = Annotated[float, within(1e-6, 1e6, _WEIGHT_WHY)]
IntegralWeight = Annotated[float, within(0.0, 1e6, f"0 turns one off; {_WEIGHT_WHY}")]
Weights4 = Annotated[list[Weight], Field(min_length=4, max_length=4)]
"""Four diagonal entries of a positive-definite weight matrix (LQR Q_e, R)."""
IntegralWeights4 = Annotated[list[IntegralWeight], Field(min_length=4, max_length=4)]
IntegralLimit = Annotated[float, within(
    0.0, LAB_EXTENT_M, "m s: a clamp beyond LAB_EXTENT_M m s clamps nothing in a lab",
    lo_open=True)]
LoopRate = Annotated[float, within(
    0.0, NYQUIST_RAD_S, "rad/s (or 1/s): no faster than the Nyquist frequency of the "
    "fastest command rate, pi x 100 Hz (NYQUIST_RAD_S)", lo_open=True)]
LoopGain = Annotated[float, within(0.0, NYQUIST_RAD_S, "1/s: no loop faster than the Nyquist "
                                   "frequency of the fastest command rate (NYQUIST_RAD_S)")]
VelocityGain = Annotated[float, within(
    0.0, 100.0, "x/y: rad of tilt, z: N, per m/s (or m/s^2, or m); at 100 the 20 deg tilt "
    "limit is reached at 3.5 mm/s and z asks 17 x the X-3D's weight per m/s")]


FLIGHT_MAX_S = 3600.0
"""Longest lap or flight time [s]: an hour outlasts any battery of the class (a 3S LiPo
keeps the X-3D up for a quarter of it)."""

FlightTime = Annotated[float, within(0.0, FLIGHT_MAX_S, "s: an hour outlasts any battery "
                                     "of the class (FLIGHT_MAX_S)", lo_open=True)]

MIN_MOTION_S = 0.2
"""Shortest duration or trajectory period accepted [s]: about the vehicle's rate-loop
rise time (0.14 s, thesis Fig. 3.8) plus its command delay, so nothing shorter can be
flown as asked; and twenty samples of the feasibility check's 10 ms, so nothing it
checks moves between two of them."""

LapTime = Annotated[float, within(MIN_MOTION_S, FLIGHT_MAX_S, "s: from the shortest motion "
                                  "the vehicle can fly as asked (MIN_MOTION_S) to an hour, "
                                  "which outlasts any battery of the class (FLIGHT_MAX_S)")]
Speed = Annotated[float, within(0.0, 20.0, "m/s: 20 m/s crosses Table B.1's 3 m volume in "
                                "0.15 s", lo_open=True)]

FifoPriority = Annotated[int, within(
    1, 98, "SCHED_FIFO priorities are 1-99; 99 belongs to the kernel's migration and watchdog "
    "threads")]


