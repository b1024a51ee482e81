"""Configuration: pydantic models for every part of the ground station.

A configuration is one YAML file (``config/lab.yaml`` for the real lab,
``config/sim.yaml`` for the virtual lab). :func:`load_config` reads and
validates it; any problem raises :class:`~groundstation.errors.ConfigError`
whose message names the field path, the offending value and the reason, one
line per problem. Unknown keys are errors (a typo must not silently fall back
to a default), and so are a key given twice, a number that is a boolean, a
fraction where an integer is meant, and any infinite or NaN number (see
:class:`ConfigModel`). :func:`check_files` checks the files a configuration names.

Every numeric default names its source in a comment: a thesis equation or
table ("eq. 3.7", "Table 6.2"), the spec, or the reason it was chosen where the
thesis is silent or its printed equation has a typo (derived again and tested).

Single fields can be overridden (the ``gs fly --serial-port ...`` options) with
:func:`apply_overrides`, which re-validates the whole model so an override is
checked exactly like the file.
"""

from __future__ import annotations

import copy
import ipaddress
import math
import os
import re
import stat
from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
import yaml
from pydantic import (
    AfterValidator,
    BaseModel,
    ConfigDict,
    Field,
    GetCoreSchemaHandler,
    SerializeAsAny,
    SkipValidation,
    ValidationError,
    ValidationInfo,
    field_validator,
    model_validator,
)
from pydantic_core import CoreSchema
from yaml.reader import ReaderError

from groundstation.errors import ConfigError
from groundstation.estimation.records import EkfParams
from groundstation.model.quadrotor import QuadrotorParams
from groundstation.model.sensors import (
    ACC_SATURATION_M_S2,
    ACC_VARIANCE_TABLE_6_3,
    GYRO_VARIANCE_TABLE_6_3,
    K_ACC_TABLE_6_2,
    K_GYRO_TABLE_6_2,
    VICON_POSITION_VARIANCE_TABLE_6_1,
    VICON_QUATERNION_VARIANCE_TABLE_6_1,
)
from groundstation.model.thrust import THRUST_POLY_EQ37

_QUAD = QuadrotorParams()
"""The vehicle model's defaults (groundstation.model.quadrotor): mass, g, rate gains,
induced inflow, rate-loop time constant; the vehicle section below takes them from it."""

CHANNELS = ("pitch", "roll", "yaw", "thrust")
"""Channel names, in the spec's ctrl-mask bit order (bit0 pitch ... bit3 thrust)."""

SENSOR_BLOCKS = ("status", "gyro", "acc", "pressure", "rc")
"""DATA block names, in the spec's mask bit order (bit0 status ... bit4 rc)."""

Channel = Literal["pitch", "roll", "yaw", "thrust"]
SensorBlock = Literal["status", "gyro", "acc", "pressure", "rc"]
Vec3 = Annotated[list[float], Field(min_length=3, max_length=3)]


PositiveFloat = Annotated[float, Field(gt=0)]
NonNegFloat = Annotated[float, Field(ge=0)]


# --------------------------------------------------------------------------- physical ranges
# Every number with a physical range is checked against it, not only for its type: a
# configuration with gyro_scale -187564 or a Vicon variance of 1.2e29 is a typo, and it
# must be refused before a flight, naming the field, the value, the range and its source.
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

_HOST_LABEL = re.compile(r"^(?!-)[A-Za-z0-9-]{1,63}(?<!-)$")


def _host(value: str) -> str:
    """An IPv4 address or a host name (RFC 1123: dot-separated labels of letters, digits
    and hyphens, at most 253 characters); ValueError naming what is wrong otherwise."""
    try:
        address = ipaddress.ip_address(value)
    except ValueError:
        address = None
    if address is not None:
        if address.version != 4:
            raise ValueError("an IPv6 address: this socket is IPv4 (AF_INET); give an IPv4 "
                             "address or a host name")
        return value
    labels = value.removesuffix(".").split(".")
    if (not value or len(value) > 253 or not all(_HOST_LABEL.match(x) for x in labels)
            or labels[-1].isdigit()):
        raise ValueError("not an IPv4 address (0.0.0.0: every interface) or a host name "
                         "(letters, digits, hyphens and dots)")
    return value


HostAddress = Annotated[str, AfterValidator(_host)]
"""The address of a UDP socket (IPv4: the Vicon client and sender are AF_INET)."""

IPC_PATH_MAX = 107
"""Longest ``ipc://`` path ZeroMQ accepts on Linux [bytes]: ``sockaddr_un.sun_path`` less
its terminating NUL."""


def zmq_endpoint(value: str) -> str:
    """A ZeroMQ endpoint a socket can bind: ``tcp://HOST:PORT`` (HOST ``*``, an IPv4
    address, ``[IPv6]``, a host or interface name; PORT 1-65535 or ``*`` for any free
    one), ``ipc://PATH`` or ``inproc://NAME``. ValueError naming what is wrong."""
    transport, sep, address = value.partition("://")
    if not sep or transport not in ("tcp", "ipc", "inproc"):
        raise ValueError("must be a ZeroMQ endpoint: tcp://HOST:PORT, ipc://PATH or "
                         "inproc://NAME")
    if transport == "ipc":
        if not address or "\0" in address or len(address.encode()) > IPC_PATH_MAX:
            raise ValueError(f"ipc:// needs a path of 1-{IPC_PATH_MAX} bytes (a Unix "
                             "socket's limit)")
        return value
    if transport == "inproc":
        if not address:
            raise ValueError("inproc:// needs a name")
        return value
    host, colon, port = address.rpartition(":")
    if not colon or not host:
        raise ValueError("tcp:// needs HOST:PORT, e.g. tcp://127.0.0.1:5556")
    if port != "*" and not (port.isdigit() and 1 <= int(port) <= 65535):
        raise ValueError(f"port {port!r}: a TCP port is 1-65535 (or * for any free one)")
    if host == "*":
        return value
    if host.startswith("[") and host.endswith("]"):
        try:
            ipaddress.IPv6Address(host[1:-1])
        except ValueError:
            raise ValueError(f"{host}: not an IPv6 address") from None
        return value
    try:
        _host(host)
    except ValueError:
        raise ValueError(f"host {host!r}: not *, an IPv4 address, [an IPv6 address], a host "
                         "name or an interface name") from None
    return value


ZmqEndpoint = Annotated[str, AfterValidator(zmq_endpoint)]


def _strict_scalars(schema: Any) -> None:
    """Mark every int, float and bool in a pydantic core schema strict, in place."""
    if isinstance(schema, dict):
        if schema.get("type") in ("int", "float", "bool"):
            schema["strict"] = True
        for value in schema.values():
            _strict_scalars(value)
    elif isinstance(schema, list):
        for value in schema:
            _strict_scalars(value)


class FieldValueError(ValueError):
    """A refusal by a model validator (one that sees several fields) that one field must
    fix: ``field`` (its name in the model) and its ``value``. The error report then names
    that field, its value and its line in the file, not the whole section."""

    def __init__(self, field: str, value: object, message: str) -> None:
        super().__init__(message)
        self.field = field
        self.value = value


class ConfigModel(BaseModel):
    """Base: unknown keys are errors, instances are immutable, numbers are numbers.

    Every number must be finite (``allow_inf_nan=False``: ``.inf`` is no time, rate or
    length), and numbers and booleans are strict, each in every model (issue 14): no
    ``true`` for a number (``vicon.port: true`` would be port 1), no ``1e30`` for an
    integer (``serial.baud``), no string for a number, no ``0``/``1`` for a boolean. An
    int is a float. The rest stays lax, as YAML needs it: a string is a path, a list a
    tuple. (pydantic's model-wide ``strict=True`` would refuse those, and validates
    defaults such as ``Path("flightlogs")`` against the JSON rules.)
    """

    model_config = ConfigDict(extra="forbid", frozen=True, validate_default=True,
                              allow_inf_nan=False)

    @classmethod
    def __get_pydantic_core_schema__(cls, source: type[BaseModel],
                                     handler: GetCoreSchemaHandler, /) -> CoreSchema:
        schema = handler(source)
        _strict_scalars(schema)
        return schema


_Model = ConfigModel  # the name the sections below were written with


def _matrix(value: list[float] | list[list[float]], n: int, name: str) -> np.ndarray:
    """A covariance given as a diagonal (list) or a full matrix (list of lists) -> (n, n)."""
    arr = np.asarray(value, dtype=float)
    if arr.ndim == 1:
        if arr.shape != (n,):
            raise ValueError(f"{name} diagonal must have {n} entries, found {arr.shape[0]}")
        arr = np.diag(arr)
    if arr.shape != (n, n):
        raise ValueError(f"{name} must be {n}x{n}, found {arr.shape[0]}x{arr.shape[1]}")
    return arr


def _check_covariance(value: list[float] | list[list[float]], n: int, name: str) -> None:
    """Raise ValueError unless ``value`` is a symmetric positive-definite n x n covariance."""
    arr = _matrix(value, n, name)
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} has non-finite entries")
    if not np.allclose(arr, arr.T, rtol=1e-9, atol=1e-15):
        raise ValueError(f"{name} is not symmetric")
    try:
        np.linalg.cholesky(arr)
    except np.linalg.LinAlgError:
        raise ValueError(f"{name} is not positive definite") from None


Covariance = list[float] | list[list[float]]


def _default_sensors() -> list[SensorBlock]:
    return ["status", "gyro", "acc", "rc"]


def _all_channels() -> list[Channel]:
    return ["pitch", "roll", "yaw", "thrust"]


# --------------------------------------------------------------------------- serial link
RcChannel = Annotated[int, within(0, 7, "an index into RC_DATA's channels_out[8] (spec)")]


class LlConfig(ConfigModel):
    """The AscTec LL dialect's link schedule (``serial.protocol: asctec-ll``; docs/protocol.md).

    The vehicle sends only what is polled: IMU_RAWDATA every ``serial.data_period_ms``,
    LL_STATUS and RC_DATA with every ``status_every``-th and ``rc_every``-th of those polls.
    """

    status_every: Annotated[int, within(1, 1000, "polls per LL_STATUS: at 100 Hz polls "
                                        "1000 is one every 10 s; rarer and the battery "
                                        "and the pilot's switch go unseen")] = 10
    # LL_STATUS (battery, serial switch, commands applied) at 10 Hz with 100 Hz IMU polls:
    # 27 B each, 5 % of the line; slower delays the supervisor's "pilot took over"
    rc_every: Annotated[int, within(1, 1000, "polls per RC_DATA: at 100 Hz polls 1000 is "
                                    "one every 10 s; rarer and the pilot's sticks go "
                                    "unseen")] = 10
    # RC_DATA (the pilot's sticks) at 10 Hz; design choice within the line budget
    answer_timeout_ms: Annotated[float, within(
        0, 500.0, "the round trip is ~40 ms; half a second is 50 unanswered polls at 100 Hz",
        lo_open=True)] = 80.0
    # a poll not answered completely by then is counted unanswered: above the round trip
    # (57600 baud: 1 ms up, 7 ms down, the radio's latency: 30-40 ms in the virtual lab)
    ack_timeout_ms: Annotated[float, within(
        0, 500.0, "the round trip is ~40 ms; half a second is 25 commands at 50 Hz",
        lo_open=True)] = 80.0
    # a command whose 5-byte acknowledgement has not arrived by then is counted missing
    fallback_ms: Annotated[float, within(
        20.0, 1000.0, "the firmware's fallback: AscTec's SDK used 200 ms; below 20 ms no "
        "command link keeps it, beyond a second the vehicle flies on a stale command")] = 100.0
    # the LL firmware's fallback after the last command: undocumented; AscTec's later SDK
    # used 200 ms; 100 ms like the X-3D's watchdog until measured on the vehicle
    rc_channels: tuple[RcChannel, RcChannel, RcChannel, RcChannel] = (0, 1, 2, 3)
    # RC_DATA channels_out index of pitch, roll, thrust, yaw: AscTec SDK order, unverified
    motor_start_yaw: Literal[-2047, 2047] = -2047
    # the motor gesture's yaw to start (the opposite stops): drivers disagree on the sign
    motor_gesture_s: Annotated[float, within(
        0, 3.0, "public drivers hold the gesture about half a second; 3 s is ample",
        lo_open=True)] = 0.5  # how long the gesture is held

    @field_validator("rc_channels")
    @classmethod
    def _distinct(cls, value: tuple[int, ...]) -> tuple[int, ...]:
        if len(set(value)) != len(value):
            raise ValueError("a channel index given twice: pitch, roll, thrust and yaw are "
                             "four different sticks")
        return value


class SerialConfig(ConfigModel):
    """The serial link to the vehicle (X-3D dialect ``docs/protocol.md`` or the
    AscTec LL dialect; docs/protocol.md)."""

    protocol: Literal["x3d", "asctec-ll"] = "x3d"
    # the vehicle's dialect: configured, never guessed from the bytes (the dialects share
    # descriptor 0x01 for different packets)
    port: str = "/dev/ttyUSB0"  # the lab's XBee adapter; a pty path or pyserial URL also works
    baud: Annotated[int, within(1200, 4_000_000, "from the slowest rate an XBee radio "
                                "offers (BD=0) to the 4 Mbaud of the fastest USB UARTs")] = 57600
    # spec section 1 default (design choice)
    crc_profile: Literal["asctec", "kermit", "mcrf4xx"] = "asctec"  # spec section 2
    sensors: list[SensorBlock] = Field(default_factory=_default_sensors)
    # STATUS+GYRO+ACC+RC = 41 B/frame, 71% of 57600 baud at 100 Hz (spec section 6)
    data_period_ms: Annotated[int, within(1, 1000, "the X-3D streams at most every 1 ms; "
                                          "slower than 1 Hz is no IMU to fly on")] = 10
    # 100 Hz IMU, thesis Ch. 1.2.2
    command_rate_hz: Annotated[float, within(
        20.0, COMMAND_RATE_MAX_HZ, "spec section 4's target is 50-100 Hz; below 20 Hz a "
        "command period exceeds half the vehicle's 100 ms watchdog")] = 50.0
    # 50 Hz: spec section 4 target 50-100 Hz; thesis flew 33 Hz over XBee (App. A.3).
    stale_command_s: Annotated[float, within(
        0, 1.0, "the keep-alive flies the loop's last command this long: beyond a second "
        "a stalled loop would steer the vehicle", lo_open=True)] = 0.25
    # keep-alive resends the loop's last command only this long, then hands back (mask 0)
    handover_blend_s: Annotated[float, within(
        0.0, 10.0, "a blend longer than 10 s leaves the vehicle half with the pilot for "
        "longer than a take-off takes")] = 1.0  # bumpless-transfer blend time; thesis silent
    ll: LlConfig = LlConfig()  # read with protocol asctec-ll only

    @field_validator("sensors")
    @classmethod
    def _needs_imu(cls, value: list[str]) -> list[str]:
        if len(set(value)) != len(value):
            raise ValueError("sensor blocks listed twice")
        if "gyro" not in value or "acc" not in value:
            raise ValueError("the estimator needs the 'gyro' and 'acc' blocks")
        return value

    @model_validator(mode="after")
    def _commands_within_the_fallback(self) -> SerialConfig:
        if self.protocol == "asctec-ll" and 2000.0 / self.command_rate_hz > self.ll.fallback_ms:
            raise ValueError(
                f"command_rate_hz {self.command_rate_hz:g}: a command period of "
                f"{1000.0 / self.command_rate_hz:.0f} ms is more than half the vehicle's "
                f"{self.ll.fallback_ms:g} ms fallback (serial.ll.fallback_ms)")
        return self

    @property
    def sensor_mask(self) -> int:
        """DATA mask bits for :attr:`sensors` (spec section 3.3)."""
        return sum(1 << SENSOR_BLOCKS.index(name) for name in self.sensors)


class ChannelsConfig(ConfigModel):
    """Which channels the ground station controls (the rest stay with the RC pilot)."""

    auto: list[Channel] = Field(default_factory=_all_channels)

    @field_validator("auto")
    @classmethod
    def _unique(cls, value: list[str]) -> list[str]:
        if len(set(value)) != len(value):
            raise ValueError("channel listed twice")
        return value


# --------------------------------------------------------------------------- Vicon
class RotationConfig(ConfigModel):
    """A fixed rotation given as intrinsic X-Y-Z Euler angles in degrees."""

    euler_xyz_deg: list[TurnDeg] = Field(default_factory=lambda: [180.0, 0.0, 0.0],
                                         min_length=3, max_length=3)

    def as_matrix(self) -> np.ndarray:
        """(3, 3) rotation matrix Rx(a) @ Ry(b) @ Rz(c)."""
        from scipy.spatial.transform import Rotation

        return np.asarray(Rotation.from_euler("XYZ", self.euler_xyz_deg, degrees=True).as_matrix())


VICON_RATE_MAX_HZ = 2000.0
"""The fastest a Vicon system streams [Hz] (its cameras' top frame rate)."""

Box = tuple[tuple[float, float], tuple[float, float], tuple[float, float]]
"""An axis-aligned box ``((x_min, x_max), (y_min, y_max), (z_min, z_max))``, NED [m]."""


class ViconConfig(ConfigModel):
    """The Vicon UDP object stream (``docs/vicon-udp.md``)."""

    bind_address: HostAddress = "0.0.0.0"  # IPv4 (the client is AF_INET); 0.0.0.0: all
    port: Annotated[int, within(1, 65535, "a UDP port")] = 51001
    # Tracker's conventional UDP object-stream port
    object_name: str = Field("X3D", min_length=1, max_length=23)  # spec: at most 23 characters
    world_to_ned: RotationConfig = RotationConfig()  # Vicon z-up -> NED: 180 deg about x (spec)
    body_to_object: RotationConfig = RotationConfig()  # FRD body -> object frame: 180 deg about x
    latency_s: Annotated[float, within(0.0, 0.5, "spec: Tracker and the network add a few "
                                       "ms; half a second is no motion capture")] = 0.005
    # spec: "a few ms"; Tracker + network latency
    expected_rate_hz: Annotated[float, within(
        1.0, VICON_RATE_MAX_HZ, "the thesis flew down to 1 Hz (Ch. 11.1); Vicon cameras "
        "stream at most ~2000 Hz")] = 100.0  # thesis lab streamed 100 Hz (App. B)
    min_rate_hz: Annotated[float, within(
        0.0, VICON_RATE_MAX_HZ, "Vicon cameras stream at most ~2000 Hz",
        lo_open=True)] = 8.0  # warn below: the thesis flew at 10 Hz (Ch. 11.1)
    max_speed_m_s: Annotated[float, within(
        0.0, 50.0, "an outlier gate [m/s] (spec: 'a few m/s'); at 50 m/s it lets a pose "
        "cross the lab in one 100 Hz frame and gates nothing", lo_open=True)] = 5.0
    max_rotation_rate_rad_s: Annotated[float, within(
        0.0, 200.0, "an outlier gate [rad/s] (spec: 'tens of rad/s'); 200 rad/s is 32 turns "
        "a second, beyond any quadrotor", lo_open=True)] = 30.0
    restart_silence_s: Annotated[float, within(
        0.0, 60.0, "a longer silence is a Tracker restart (spec); the flight has landed on "
        "Vicon loss (safety.vicon_loss_land_s <= 30 s) long before a minute",
        lo_open=True)] = 1.0
    restart_backjump_frames: Annotated[int, within(
        1, 1_000_000, "frames [-]: a larger backward jump is a Tracker restart; 10^6 "
        "frames is 2.8 h at 100 Hz, beyond any reordering")] = 1000
    plausibility_margin_m: Annotated[float, within(
        0.0, LAB_EXTENT_M, "a margin beyond LAB_EXTENT_M accepts any pose [m]")] = 0.5
    # [m] a pose further than this outside safety.volume_x/y/z is refused as impossible
    # (issue 14). The supervisor lands at the volume's edge; braking from the fastest
    # reference (safety.max_speed_m_s, 1.5 m/s) at the 35 deg tilt limit takes 0.16 m,
    # and the cameras see a little beyond the volume (Table B.1): 0.5 m covers both
    reanchor_poses: Annotated[int, within(
        2, 100, "poses [-]: never one (a stray pose); 100 is 10 s at 10 Hz, longer than "
        "Vicon may be lost before the flight lands")] = 3
    # consistent poses in a row before a pose stream is believed: at start-up, after a
    # gap, for a new stream, and before the estimator re-anchors on poses it gated (issue
    # 14: never one pose). 3: 20 ms late at 100 Hz, 0.2 s at 10 Hz; one stray pose is not
    # enough, and a chance agreement of three is as unlikely as the gate allows
    source: Literal["udp", "zenoh"] = "udp"
    # where the object's datagrams come from: "udp", Tracker's stream on bind_address:port;
    # "zenoh", the fleet's `gs vicon-relay`, which receives that stream once for every
    # vehicle (key <fleet.name>/vicon/<object_name>; needs the fleet: section). Either
    # way the same pose filter, latency model and failsafes (groundstation/fleet)

    @field_validator("object_name")
    @classmethod
    def _printable(cls, value: str) -> str:
        if not value.isprintable():
            raise ValueError("holds a control character: Tracker's names are printable "
                             "text, NUL-padded on the wire (spec), so it would never match")
        return value

    @model_validator(mode="after")
    def _rates(self) -> ViconConfig:
        if self.min_rate_hz > self.expected_rate_hz:
            raise ValueError("min_rate_hz must not exceed expected_rate_hz")
        return self

    def plausible_volume(self, safety: SafetyConfig) -> Box:
        """Where a pose can be: ``safety.volume_x/y/z`` (NED [m]) grown by
        ``plausibility_margin_m`` on every side, as ``((x_min, x_max), (y_min, y_max),
        (z_min, z_max))``."""
        m = self.plausibility_margin_m
        x, y, z = safety.volume_x, safety.volume_y, safety.volume_z
        return ((x[0] - m, x[1] + m), (y[0] - m, y[1] + m), (z[0] - m, z[1] + m))


# --------------------------------------------------------------------------- vehicle
GRAVITY_RANGE_M_S2 = (9.76, 9.84)
"""Gravity at the Earth's surface [m/s^2]: 9.76 on the highest equatorial summits to 9.83
at the poles; the thesis's 9.82 (eq. 3.8) is Denmark's."""

THRUST_MAX_N = 500.0
"""Largest lift a thrust map may give over the stick range 0..4095 [N]: the heaviest vehicle
accepted (vehicle.mass_kg <= 20 kg) at a thrust-to-weight ratio of 2.5. The X-3D's eq. 3.7
gives 10 N at full stick."""

_K_RATE = max(abs(k) for k in _QUAD.k_rate)

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


class VehicleConfig(ConfigModel):
    """The X-3D model parameters (thesis Ch. 3 and 6)."""

    mass_kg: Annotated[float, within(
        0.01, 20.0, "kg: from a 27 g micro quadrotor to a 20 kg lifter")] = _QUAD.mass
    # not printed in the thesis: 0.60 kg makes the eq. 3.7 polynomial hover near mid-stick
    # (F_lift(2000) = -5.93 N = -0.603 kg * 9.82), DESIGN.md errata
    gravity: Annotated[float, within(*GRAVITY_RANGE_M_S2, "m/s^2: gravity at the Earth's "
                                     "surface (GRAVITY_RANGE_M_S2)")] = _QUAD.g
    # thesis eq. 3.8, Denmark
    k_rate: list[RateGain] = Field(default_factory=lambda: list(_QUAD.k_rate),
                                   min_length=3, max_length=3)
    # [K_phi, K_theta, K_psi] rad/s per stick unit: max roll step 2047 gave 2.25 rad/s
    # (Ch. 3.3.1), identified values not printed (DESIGN.md errata); yaw assumed the same
    thrust_poly: list[float] = Field(
        default_factory=lambda: list(THRUST_POLY_EQ37), min_length=4, max_length=4,
    )  # eq. 3.7, [a3, a2, a1, a0], body-z force [N] (negative = up); App. C.1's a2 is a typo
    induced_inflow: Annotated[float, within(
        _QUAD.inflow * 100, _QUAD.inflow / 100, "N s/m, negative (a climb meets the "
        "inflow's drag): two decades either side of eq. C.8's")] = _QUAD.inflow
    # I_i, eq. 3.9 and eq. C.8 [N s/m]
    gyro_scale: list[GyroScale] = Field(default_factory=lambda: list(K_GYRO_TABLE_6_2),
                                        min_length=3, max_length=3)
    # Table 6.2 K_gyro [rad/s per count]; negative for an axis mounted reversed
    acc_scale: list[AccScale] = Field(default_factory=lambda: list(K_ACC_TABLE_6_2),
                                      min_length=3, max_length=3)
    # Table 6.2 K_acc [m/s^2 per count]; negative for an axis mounted reversed
    gyro_zero: list[AdcZero] = Field(default_factory=lambda: [2048.0, 2048.0, 2048.0],
                                     min_length=3, max_length=3)
    # spec section 3.3: 12-bit counts, zero at mid-range (calibrate per vehicle)
    acc_zero: list[AdcZero] = Field(default_factory=lambda: [2048.0, 2048.0, 2048.0],
                                    min_length=3, max_length=3)  # as gyro_zero
    gyro_variance: list[GyroVariance] = Field(
        default_factory=lambda: list(GYRO_VARIANCE_TABLE_6_3), min_length=3, max_length=3)
    # Table 6.3 [(rad/s)^2]
    acc_variance: list[AccVariance] = Field(
        default_factory=lambda: list(ACC_VARIANCE_TABLE_6_3), min_length=3, max_length=3)
    # Table 6.3 [(m/s^2)^2]
    vicon_position_variance: list[ViconPositionVariance] = Field(
        default_factory=lambda: list(VICON_POSITION_VARIANCE_TABLE_6_1),
        min_length=3, max_length=3)
    # Table 6.1 [m^2]
    vicon_quaternion_variance: list[ViconQuaternionVariance] = Field(
        default_factory=lambda: list(VICON_QUATERNION_VARIANCE_TABLE_6_1),
        min_length=4, max_length=4)  # Table 6.1, q0..q3
    acc_saturation: Annotated[float, within(
        GRAVITY_RANGE_M_S2[1], 160.0, "m/s^2: above 1 g (the accelerometer must read the "
        "hover) and at most a MEMS accelerometer's widest range, 16 g")] = ACC_SATURATION_M_S2
    # Ch. 6.2: accelerometer saturation
    rate_loop_tau_s: RateLoopTau = _QUAD.rate_tau
    # on-board rate loop as a first-order lag: Fig. 3.8 rises (10-90 %) in 0.14 s = 2.2 tau.
    # The controller design, the virtual lab and the evaluation all use this one value
    command_delay_s: CommandDelay = 0.02
    # transport delay of a COMMAND (radio and firmware) before the vehicle applies it;
    # Ch. 3.3.1 identified the rate gains "with a time delay" without printing it; 20 ms
    # is one 50 Hz command period (XBee at 57600 baud, thesis App. A)

    @field_validator("thrust_poly")
    @classmethod
    def _lift_in_range(cls, value: list[float]) -> list[float]:
        # Horner in Python floats: a huge coefficient overflows to inf (or inf - inf to
        # nan), which the comparison refuses, without numpy's overflow warnings
        def lift(u: float) -> float:
            out = 0.0
            for a in value:
                out = out * u + a
            return out

        worst = next((f for f in (lift(u) for u in range(0, 4097, 64))
                      if not abs(f) <= THRUST_MAX_N), 0.0)
        if worst:
            raise ValueError(f"gives {worst:g} N within the stick range 0..4095: outside "
                             f"[-{THRUST_MAX_N:g}, {THRUST_MAX_N:g}] N (THRUST_MAX_N: the "
                             "heaviest vehicle accepted at a thrust-to-weight ratio of 2.5)")
        return value

    @model_validator(mode="after")
    def _can_hover(self) -> VehicleConfig:
        max_lift = -min(float(np.polyval(self.thrust_poly, u)) for u in range(0, 4097, 64))
        weight = self.mass_kg * self.gravity
        if max_lift <= weight:
            # blame the field the file set: the mass, unless only thrust_poly was given
            given = self.model_fields_set
            if "thrust_poly" in given and "mass_kg" not in given:
                raise FieldValueError("thrust_poly", self.thrust_poly, (
                    f"lifts at most {max_lift:.2f} N, less than the weight {weight:.2f} N "
                    f"(mass_kg {self.mass_kg:g} kg): the vehicle could not hover"))
            raise FieldValueError("mass_kg", self.mass_kg, (
                f"weighs {weight:.2f} N, more than thrust_poly lifts at most "
                f"({max_lift:.2f} N): the vehicle could not hover (the mass of this "
                "vehicle, or a thrust_poly fitted to it: gs identify thrust)"))
        return self


# --------------------------------------------------------------------------- estimator
DiagonalBand = tuple[int, int, float, float, str]
"""Entries ``[start, stop)`` of a covariance's diagonal lie in ``[lo, hi]``: what they are."""

R_DIAGONAL_BANDS: tuple[DiagonalBand, ...] = (
    (0, 3, *variance_band(VICON_POSITION_VARIANCE_TABLE_6_1),
     "Vicon position variances [m^2], 1/1000 to 10^4 x Table 6.1's"),
    (3, 7, *variance_band(VICON_QUATERNION_VARIANCE_TABLE_6_1),
     "Vicon quaternion variances, 1/1000 to 10^4 x Table 6.1's"),
)

P0_DIAGONAL_BANDS: tuple[DiagonalBand, ...] = (
    # the lower bound: a prior tighter than 1e-12 is below what the filter's doubles
    # separate from its other variances; the upper: a spread no lab or vehicle has
    (0, 3, 1e-12, LAB_EXTENT_M ** 2, "position variances [m^2], at most a lab's extent "
     "squared"),
    (3, 7, 1e-12, 1.0, "quaternion variances: a unit quaternion's entries lie in [-1, 1]"),
    (7, 10, 1e-12, 2500.0, "velocity variances [(m/s)^2], at most (50 m/s)^2"),
    (10, 13, 1e-12, 1.0, "gyro bias variances [(rad/s)^2], at most (1 rad/s)^2"),
    (13, 16, 1e-12, 100.0, "accelerometer bias variances [(m/s^2)^2], at most 1 g squared"),
)


def _check_diagonal(value: Covariance, n: int, bands: tuple[DiagonalBand, ...]) -> None:
    """Raise ValueError naming the first diagonal entry outside its band."""
    diagonal = np.diag(_matrix(value, n, "covariance"))
    for start, stop, lo, hi, what in bands:
        for i in range(start, stop):
            if not lo <= diagonal[i] <= hi:
                raise ValueError(f"diagonal entry {i} = {diagonal[i]:g} outside "
                                 f"[{lo:g}, {hi:g}]: {what}")


class EstimatorConfig(ConfigModel):
    """The IMU-driven EKF (thesis Ch. 7). Sensor variances come from the vehicle section."""

    gyro_bias_walk: Annotated[float, within(
        1e-10, 1e-2, "(rad/s)^2/s, four decades either side of the tuned default: at 1e-2 "
        "the bias wanders 0.1 rad/s in a second, no gyro's")] = 1e-6
    # gyro bias random walk [(rad/s)^2/s]: tuned (thesis: Q "determined by manual tuning")
    acc_bias_walk: Annotated[float, within(
        1e-8, 1.0, "(m/s^2)^2/s, four decades either side of the tuned default: at 1 the "
        "bias wanders 1 m/s^2 in a second, no accelerometer's")] = 1e-4
    # accelerometer bias random walk [(m/s^2)^2/s], tuned
    process_noise_scale: Annotated[float, within(
        1e-3, 1e3, "three decades either side of the measured Table 6.3 variances")] = 1.0
    # multiplies the Table 6.3 IMU variances used as process noise (1 = as measured)
    r_override: Covariance | None = None
    # optional 7x7 (or diagonal 7) Vicon R replacing Table 6.1 [m^2, -]
    initial_covariance: Covariance = Field(
        default_factory=lambda: [1e-4] * 3 + [1e-4] * 4 + [1e-2] * 3 + [1e-3] * 3 + [1e-1] * 3
    )  # 16 diagonal: P, q, v, gyro bias, acc bias; loose enough for biases to settle in ~3 s
    gate_probability: Annotated[float, within(
        0.5, 1.0, "a probability: at 0.5 the gate refuses half the honest poses, at 1 it "
        "gates nothing", lo_open=True, hi_open=True)] = 0.9999
    # chi-square innovation gate; 1e-4 false-reject rate per update
    divergence_trace: Annotated[float, within(
        0.0, 1e4, "16-layout units: a trace of 10^4 is a 58 m spread per axis, a failsafe "
        "that never fires in a lab", lo_open=True)] = 10.0
    # covariance trace above which the estimate is declared diverged (failsafe)
    max_vicon_delay_s: Annotated[float, within(
        0.0, 1.0, "s: poses arrive a few ms late (spec); a second-old pose is history",
        lo_open=True)] = 0.2  # older poses are dropped instead of re-propagated
    settle_time_s: Annotated[float, within(
        0.0, 60.0, "s: a minute on the ground is 20 times Ch. 7.4's settling",
        lo_open=True)] = 3.0  # on the ground before take-off, thesis Ch. 7.4 (~3 s)

    @field_validator("r_override")
    @classmethod
    def _r_pd(cls, value: Covariance | None) -> Covariance | None:
        if value is not None:
            _check_covariance(value, 7, "r_override")
            _check_diagonal(value, 7, R_DIAGONAL_BANDS)
        return value

    @field_validator("initial_covariance")
    @classmethod
    def _p0_pd(cls, value: Covariance) -> Covariance:
        _check_covariance(value, 16, "initial_covariance")
        _check_diagonal(value, 16, P0_DIAGONAL_BANDS)
        return value

    @model_validator(mode="after")
    def _starts_converged(self) -> EstimatorConfig:
        trace = float(np.trace(_matrix(self.initial_covariance, 16, "initial_covariance")))
        if trace >= self.divergence_trace:
            raise ValueError(f"divergence_trace {self.divergence_trace:g} is not above the "
                             f"trace of initial_covariance ({trace:g}): the estimator would "
                             "be declared diverged before it started")
        return self


# --------------------------------------------------------------------------- controller
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


class LqrConfig(ConfigModel):
    """LQR with a reference model (thesis Ch. 9). Weights on the error e = r - y."""

    q_error: Weights4 = Field(default_factory=lambda: [8.0, 8.0, 20.0, 2.0])
    # Q_e on [x, y, z, q3] errors (eq. 9.18) [1/m^2, -]; tuned for ~0.2 Hz x/y as Ch. 11.2
    r_input: Weights4 = Field(default_factory=lambda: [4.0, 4.0, 4.0, 2.0])
    # R on [omega_x, omega_y, omega_z, F_z] [1/(rad/s)^2, 1/N^2]: the body-rate form of
    # eq. 4.31's input (sticks = omega / K), tuned
    q_integral: IntegralWeights4 | None = None
    # weights on the integrated [x, y, z, q3] errors; None = no integrators (the
    # disturbance observer below already removes the steady-state error)
    integral_limit: IntegralLimit = 2.0
    # anti-windup clamp on each integrated error [m s]; 0.5 saturated under a 10 % thrust
    # error in the virtual lab (tests/test_control_disturbance.py)
    disturbance_tau_s: Annotated[float, within(
        0.0, 100.0, "s: an observer slower than 100 s (five 20 s laps) removes nothing "
        "within a flight", lo_open=True)] | None = 1.0
    # constant-disturbance observer time constant; beyond the thesis: zero steady-state
    # error under thrust error, droop, wrong mass or accelerometer bias (issue 7)
    velocity_source: Literal["reference", "samples"] = "reference"
    # constant-velocity model: the trajectory's own velocity, or filtered sample
    # differences as the thesis did (eq. 9.22-9.26)
    velocity_filter: Annotated[float, within(
        0.0, 1.0, "a weight of the previous velocity: at 1 the velocity never changes",
        hi_open=True)] = 0.5
    # weight of the previous velocity when velocity_source is "samples", tuned
    design_model: Literal["rate-loop", "thesis"] = "rate-loop"
    # rate-loop: design on the hover model with the rate-loop lag and the command delay
    # (vehicle section), as the thesis concludes it must (Ch. 10.3, 12); thesis: its
    # ideal-rate-loop model (Ch. 9)


class PidConfig(ConfigModel):
    """Cascaded position/velocity/attitude PID (thesis Ch. 8 baseline)."""

    position_kp: list[LoopGain] = Field(default_factory=lambda: [0.8, 0.8, 1.2],
                                        min_length=3, max_length=3)  # [1/s], tuned
    velocity_kp: list[VelocityGain] = Field(default_factory=lambda: [0.25, 0.25, 4.0],
                                            min_length=3, max_length=3)
    # x/y: rad tilt per m/s; z: N per m/s; tuned
    velocity_ki: list[VelocityGain] = Field(default_factory=lambda: [0.05, 0.05, 1.5],
                                            min_length=3, max_length=3)  # tuned
    velocity_kd: list[VelocityGain] = Field(default_factory=lambda: [0.0, 0.0, 0.0],
                                            min_length=3, max_length=3)  # tuned
    attitude_kp: list[LoopGain] = Field(default_factory=lambda: [4.0, 4.0, 2.0],
                                        min_length=3, max_length=3)
    # rate set point per rad of attitude error [1/s], tuned
    max_tilt_deg: TiltDeg = 20.0  # tilt command limit, tuned


class HinfConfig(ConfigModel):
    """H-infinity controller (thesis Ch. 10): the loop uses a stored gain."""

    gain_file: FilePath | None = None
    # a gain written by `gs synth hinf`; None = the packaged design selected below
    include_rate_loop: bool = True
    # design on the model with the rate-loop lag (Ch. 10.3): the thesis's model without
    # it gave a controller that did not stabilise the real vehicle
    # The packaged rate-loop gain is robust and has integral action (control/hinf.py):
    # the weights below are what `gs synth hinf` designs a new gain with
    epsilon: Weight = 0.1  # D12 input weight (eq. 10.5), tuned
    reference_pole: LoopRate = 1.0  # a_i of W_r (eq. 10.10) [rad/s], tuned
    noise_gain: Weight = 0.01  # k of W_n (eq. 10.9), tuned
    integral_scale: IntegralWeights4 | None = Field(
        default_factory=lambda: [0.3, 0.3, 1.0, 0.1])
    # weights of the integrated [x, y, z, q3] errors (beyond the thesis: zero steady-state
    # error under a thrust-map error, issue 13); null: the thesis's design, no integrators
    robust_range: Annotated[float, within(
        0.0, 1.0, "a fraction: at 1 a rate gain or the thrust could be zero",
        hi_open=True)] = 0.3
    # design for rate gains, rate-loop time constant and thrust per newton within +- this
    # fraction (issue 13: 30 %); 0 = the nominal plant only, as the thesis
    pole_radius_rad_s: LoopRate | None = 12.0
    # keep the closed-loop poles in this disc: no loop faster than the 50 Hz, ~40 ms
    # delayed command link carries; null = unconstrained, as the thesis
    min_decay_per_s: LoopRate | None = 0.6
    # and left of -min_decay: no loop slower (tuned on `gs eval --perturb`; must stay
    # below reference_pole); null = unconstrained, as the thesis
    integral_limit: IntegralLimit = 2.0  # anti-windup clamp on each integrated error [m s]


class ExternalForceConfig(ConfigModel):
    """The external force from the accelerometer (control/external_force.py): the specific
    force measured against the lift the COMMANDs sent predict, cancelled by the controller
    (INDI's correction as a disturbance observer; beyond the thesis)."""

    enabled: bool = True
    # false: the integrators alone reject disturbances (as before)
    fast_jerk_m_s4: Annotated[float, within(
        0.0, 1000.0, "m/s^4: the rate noise of a filter; at 1000 it passes the noise",
        lo_open=True)] = 10.0
    # the vertical alpha-beta filter (4.0 Hz): the loop it closes through a mispredicted
    # lift stays below 1 (small gain) for lift 0.74-1.35 x the model, delay +-15 ms
    horizontal_jerk_m_s4: Annotated[float, within(
        0.0, 1000.0, "m/s^4: the rate noise of a filter; at 1000 it passes the noise",
        lo_open=True)] = 600.0
    # the fast horizontal alpha-beta filter, on while a horizontal disturbance moves
    quiet_tau_s: Annotated[float, within(
        0.002, 60.0, "s: from a fifth of the fastest command period to a minute (the "
        "integrators' job)")] = 2.0
    # the horizontal estimate while nothing moves (0.08 Hz): below the position loop's 0.4 Hz
    # mode, where the accelerometer's noise (vehicle.acc_variance) would add to the hover
    detect_sigmas: Annotated[float, within(
        2.0, 20.0, "innovation standard deviations: below 2 the noise switches the fast "
        "filter on all the time, above 20 a payload would go unseen")] = 4.0
    # a change is detected beyond this many standard deviations of the noise (Gaussian:
    # a false switch every ~80 s, each 0.5 s of the fast filter)
    hold_s: Annotated[float, within(
        0.0, 10.0, "s: the fast filter's noise for longer than 10 s is the quiet one's job")] \
        = 0.5
    # the fast filter stays on this long after the last detection
    vertical_lead_s: Annotated[float, within(
        0.0, 1.0, "s: a lead longer than a second extrapolates noise, not a disturbance")] \
        = 0.07
    # the thrust takes the vertical estimate this far ahead (estimate + lead x rate): the
    # input delay, the motors' lag and the loop's response; tuned on gs eval --perturb
    motor_tau_s: Annotated[float, within(
        0.0, 1.0, "s: motors slower than a second could not hold a hover")] = 0.02
    # the lift's lag behind the command in the prediction; thesis silent, 20 ms typical of
    # the class (sim.motor_tau_s)
    min_height_m: Annotated[float, within(
        0.0, 1.0, "m: above a metre the estimate would never learn in a lab")] = 0.01
    # learns only this far above where the vehicle stood at take-off: below, the floor's
    # contact force may act, and cancelling it winds up like an integrator
    limit_m_s2: Annotated[float, within(
        0.0, 14.0, "m/s^2: the accelerometer's range (vehicle.acc_saturation)",
        lo_open=True)] = 8.0
    # clamp per axis: 0.8 g, what a +20 % payload asks on a vehicle whose mass and thrust
    # map are 15 % off the model and whose battery has lost 10 % (1.2 x 1.15 / 0.85 / 0.9)


class LqrFfConfig(ConfigModel):
    """LQR with the feed-forward reference model (beyond the thesis, control/lqr_ff.py),
    designed on the vehicle with its rate loop and command delay. Weights on e = x - x_ref."""

    q_error: Weights4 = Field(default_factory=lambda: [100.0, 100.0, 300.0, 20.0])
    # Q_e on [x, y, z, q3] errors [1/m^2, -]: ~0.8 Hz horizontal bandwidth; tuned for the
    # worst case of `gs eval --perturb` (rate gains +-30 %, tau +-30 %, delay 5-30 ms); z
    # 300: a +20 % payload peaks 2.3 cm (100: 2.6); 1000 lost the vertical loop with the
    # external-force estimate on the corner plant (lift 1.35 x the model, delay 30 ms)
    r_input: Weights4 = Field(default_factory=lambda: [1.0, 1.0, 1.0, 0.5])
    # R on [omega_x, omega_y, omega_z, F_z] [1/(rad/s)^2, 1/N^2], tuned with q_error
    q_integral: IntegralWeights4 = Field(default_factory=lambda: [20.0, 20.0, 60.0, 2.0])
    # weights on the integrated [x, y, z, q3] errors: zero steady-state error under a
    # thrust-map error, a wrong mass or battery droop (issue 13); 0 turns one off. z is
    # weighted 3x: with mass and thrust map 15 % off, 20 left a 2 cm take-off tail in TRACK
    integral_limit: IntegralLimit = 2.0  # anti-windup clamp on each integrated error [m s]
    external_force: ExternalForceConfig = ExternalForceConfig()
    # cancel the external force the accelerometer measures (payload, wind, drag, ground
    # effect, a sagging battery) within ~0.1 s; the integrators keep what remains


class ControllerConfig(ConfigModel):
    """Which controller flies and how it is tuned. Every controller is designed at the
    command period (1 / serial.command_rate_hz) and steps once per COMMAND."""

    type: Literal["lqr-ff", "lqr-cv", "lqr-cp", "pid", "hinf"] = "lqr-ff"
    # lqr-ff: feed-forward reference model (beyond the thesis; best in `gs eval`);
    # lqr-cv / lqr-cp: the thesis's constant-velocity / constant-position models (Ch. 9, 11)
    lqr_ff: LqrFfConfig = LqrFfConfig()
    lqr: LqrConfig = LqrConfig()
    pid: PidConfig = PidConfig()
    hinf: HinfConfig = HinfConfig()

    @model_validator(mode="after")
    def _hinf_gain(self) -> ControllerConfig:
        gain = self.hinf.gain_file
        if self.type == "hinf" and gain is not None and not gain.is_file():
            raise ValueError(f"hinf.gain_file {str(gain)!r} does not exist (see `gs synth hinf`)")
        return self


# --------------------------------------------------------------------------- trajectory
FLIGHT_MAX_S = 3600.0
"""Longest lap or flight time [s]: an hour outlasts any battery of the class (a 3S LiPo
keeps the X-3D up for a quarter of it)."""

FlightTime = Annotated[float, within(0.0, FLIGHT_MAX_S, "s: an hour outlasts any battery "
                                     "of the class (FLIGHT_MAX_S)", lo_open=True)]
Speed = Annotated[float, within(0.0, 20.0, "m/s: 20 m/s crosses Table B.1's 3 m volume in "
                                "0.15 s", lo_open=True)]

TrajectoryName = Literal[
    "hover", "step-x", "step-y", "step-z", "square", "yz-rectangle", "low-hover",
    "figure-eight", "yaw-turn", "waypoints", "sysid", "none",
]
# sysid: the identification flight (doublets on each rate stick, climbs and descents;
# groundstation/control/excitation.py), at center, heading yaw_deg (null: north)


class TrajectoryConfig(ConfigModel):
    """The trajectory flown after take-off (thesis Ch. 11)."""

    name: TrajectoryName = "square"
    center: list[LabCoordinate] = Field(default_factory=lambda: [0.0, 0.0, -1.0],
                                        min_length=3, max_length=3)
    # hover point / square centre, NED [m]: 1 m above the floor as Ch. 11.1 and 11.3;
    # in the lab's frame (from Tracker's origin on the floor), not from the take-off
    # point: a flight climbs above where it stands, then flies here (docs/lab-setup.md)
    size_m: LabLength = 0.75  # square side, Ch. 11.3 (0.75 m x 0.75 m)
    period_s: FlightTime = 20.0  # one lap, Ch. 11.3
    step_m: LabLength = 0.5  # step amplitude for step-x/y/z, tuned to stay in the volume
    low_height_m: LabLength = 0.02  # low-hover height, Ch. 11.4 (2 cm)
    corner_smoothing_s: Annotated[float, within(
        0.0, FLIGHT_MAX_S, "s: no longer than the longest lap (FLIGHT_MAX_S)")] = 0.0
    # 0 = sharp corners as in the thesis
    file: FilePath | None = None
    # for name 'waypoints': a waypoint CSV (t, x, y, z[, yaw]) or a uav_trajectories /
    # Crazyswarm polynomial file (Duration,x^0,...), told apart by the header (README)
    yaw_deg: TurnDeg | None = None
    # heading to fly at [deg from north]; null keeps the heading the vehicle was placed at
    # (a waypoint CSV's yaw column, when present, gives the heading instead)
    yaw_turn_deg: Annotated[float, within(
        -3600.0, 3600.0, "deg: at most ten turns either way in one lap")] = 360.0
    # 'yaw-turn': turn this far over period_s, holding position
    shaping: Literal["min-jerk", "none"] = "min-jerk"
    # min-jerk: make the reference flyable before flight (start and stop at rest, corners
    # and velocity steps blended within the safety limits, path through the corners);
    # none: the thesis's raw reference (sharp corners), for the Ch. 11 comparison
    polynomial_positions: Literal["relative", "absolute"] = "relative"
    # a polynomial file's positions: relative to its start, which is placed at center (as
    # the Crazyflie's start_trajectory(relative=True)), or absolute lab coordinates

    @model_validator(mode="after")
    def _file(self) -> TrajectoryConfig:
        if self.name == "waypoints" and self.file is None:
            raise ValueError("trajectory 'waypoints' needs 'file'")
        return self


# --------------------------------------------------------------------------- safety
class SafetyConfig(ConfigModel):
    """Limits and failsafe times the supervisor enforces."""

    volume_x: tuple[LabCoordinate, LabCoordinate] = (-1.5, 1.5)  # Table B.1 tracked volume [m]
    volume_y: tuple[LabCoordinate, LabCoordinate] = (-1.5, 1.5)  # Table B.1
    volume_z: tuple[LabCoordinate, LabCoordinate] = (-2.0, 0.05)
    # Table B.1 height 0..2 m, NED (z up is -)
    max_tilt_deg: TiltDeg = 35.0  # beyond this Vicon tracking is unreliable; tuned
    handback_tilt_deg: Annotated[float, within(0.0, 180.0, "deg: a tilt is at most 180",
                                               lo_open=True)] = 60.0
    # a landing that tilts this far has lost the attitude (the controller that tripped
    # max_tilt_deg is still flying): hand back to the pilot at once
    # The failsafe times are bounded: a finite but huge value would switch the failsafe off.
    vicon_loss_hold_s: Annotated[float, within(
        0.0, 5.0, "s: the IMU alone drifts; a hold on it longer than 5 s flies blind",
        lo_open=True)] = 0.5
    # hold on the IMU estimate after this (PX4 figure); at most 5 s: the IMU alone drifts
    vicon_loss_land_s: Annotated[float, within(
        0.0, 30.0, "s: the landing on the IMU alone must begin within 30 s",
        lo_open=True)] = 2.0  # land if Vicon has not returned
    link_loss_s: Annotated[float, within(
        0.0, 2.0, "s: the vehicle's own watchdog is 100 ms; at 2 s a lost link goes "
        "unnoticed for 200 DATA frames", lo_open=True)] = 0.3
    # no DATA this long = link lost; at most 2 s (the vehicle's own watchdog is 100 ms)
    takeoff_speed_m_s: Speed = 0.5  # climb rate for take-off, tuned
    land_speed_m_s: Speed = 0.3  # descent rate when landing, tuned
    preflight_timeout_s: Annotated[float, within(
        0.0, 600.0, "s: ten minutes of preflight is a hung check", lo_open=True)] = 10.0
    # give up if checks do not pass
    takeoff_timeout_s: Annotated[float, within(
        0.0, 300.0, "s: a take-off not done in five minutes is a stuck one",
        lo_open=True)] = 20.0
    # land if the take-off has not reached the trajectory's start in this time (a 1 m
    # climb at 0.5 m/s takes ~4 s after the 1 s handover blend); tuned
    trajectory_tilt_deg: TiltDeg = 20.0
    # most tilt a reference may ask for; the rest of max_tilt_deg is left to the feedback
    max_speed_m_s: Speed = 1.5  # fastest reference speed accepted [m/s]
    max_yaw_rate_deg_s: Annotated[float, within(
        0.0, 3600.0, "deg/s: ten turns a second, beyond any quadrotor's yaw authority",
        lo_open=True)] = 90.0  # fastest heading change of a reference, tuned
    volume_margin_m: Annotated[float, within(0.0, LAB_EXTENT_M, "m: within a lab "
                                             "(LAB_EXTENT_M)")] = 0.1
    # a reference must stay this far inside volume_x/y/z (tracking error, braking room)
    gravity_check_deg: Annotated[float, within(
        0.0, 180.0, "deg: an angle between two directions is at most 180",
        lo_open=True)] = EkfParams().gravity_check_deg
    # [deg] preflight: the accelerometer's gravity must agree with the Vicon attitude
    on_signal: Literal["land", "handback"] = "land"  # what SIGINT/SIGTERM does
    on_geofence: Literal["handback", "land"] = "handback"
    # what leaving the volume does (the estimate or Vicon outside safety.volume_x/y/z):
    # hand back to the pilot at once by default, as PX4's geofence "return to the pilot"
    # action: a vehicle that left the volume is beyond what the controller was trusted with
    on_overruled: Literal["handback", "land"] = "handback"
    # what an estimate proven wrong does (Vicon poses that agree with each other re-anchored
    # it: a thrust fault or a knock the IMU could not measure): hand back at once, or land
    # on the re-anchored estimate (a forged stream that outlived the real one would then
    # fly the landing)
    on_second_stream: Literal["land", "hold"] = "land"
    # what a second Vicon pose stream for our object does (another sender, a misconfigured
    # Tracker): land, or hold position until it stops (landing if it lasts vicon_loss_land_s)
    landing_confirm_s: Annotated[float, within(
        0.0, 30.0, "s: the landing creeps down at 0.15 m/s meanwhile; in 30 s that is "
        "4.5 m, more than the lab is high", lo_open=True)] = 5.0
    # a landing whose estimate reached the floor without evidence (Vicon, or the
    # accelerometer's floor contact) for this long hands back with thrust at hover [s]:
    # the landing creeps on down at 0.15 m/s meanwhile, 0.75 m, more than the
    # supervisor's contact_height_m of dead-reckoning drift
    second_signal_after_s: Annotated[float, within(
        0.0, 10.0, "s: a signal 10 s after the first is a new request, never the same one")] = 0.5
    # a second SIGINT/SIGTERM hands back at once only this long after the first [s];
    # closer ones are the same request: GNU `timeout` signals the process and then its
    # group within ~1 ms (issue 14), and a person pressing Ctrl-C twice on purpose takes
    # longer than half a second
    battery_land_v: Annotated[float, within(
        0.0, 65.535, "V: the X-3D's STATUS carries the voltage as uint16 mV (spec section "
        "3.3)", lo_open=True)] | None = 10.5
    # land when the battery the X-3D reports (STATUS) stays below this [V]; 10.5 V is a
    # 3S LiPo at 3.5 V a cell, ArduPilot's copter default (BATT_LOW_VOLT); also refuses a
    # take-off. null: no battery failsafe (a vehicle without the STATUS block)
    battery_grace_s: Annotated[float, within(
        0.0, 120.0, "s: two minutes below the landing voltage drains a LiPo",
        lo_open=True)] = 10.0
    # ... for this long without a sample above it [s]: a voltage sag under load is not an
    # empty battery (ArduPilot's BATT_LOW_TIMER default, 10 s)

    @field_validator("volume_x", "volume_y", "volume_z")
    @classmethod
    def _ordered(cls, value: tuple[float, float]) -> tuple[float, float]:
        if not value[0] < value[1]:
            raise ValueError("volume bounds must be (min, max) with min < max")
        return value

    @model_validator(mode="after")
    def _order(self) -> SafetyConfig:
        if self.handback_tilt_deg <= self.max_tilt_deg:
            raise ValueError("handback_tilt_deg must exceed max_tilt_deg")
        if self.vicon_loss_land_s < self.vicon_loss_hold_s:
            raise ValueError("vicon_loss_land_s must not be shorter than vicon_loss_hold_s")
        return self


# --------------------------------------------------------------------------- telemetry, logging
def local_endpoint(endpoint: str) -> bool:
    """Whether a ZeroMQ bind endpoint reaches only this machine: TCP on a loopback address
    (127.0.0.0/8, ``::1``, ``localhost``, the ``lo`` interface), IPC or in-process.
    ``tcp://*:5557``, ``tcp://0.0.0.0:5557``, another address or an interface name are not."""
    transport, sep, address = endpoint.partition("://")
    if not sep:
        return False
    if transport in ("ipc", "inproc"):
        return True
    if transport != "tcp":
        return False
    host = address.rpartition(":")[0].removeprefix("[").removesuffix("]")
    if host in ("localhost", "lo"):
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:  # "*", an interface or a host name
        return False


class TelemetryConfig(ConfigModel):
    """The pyzmq PUB socket, and the control socket ``gs channels`` talks to.

    The control socket changes what flies, so it binds to loopback unless it
    authenticates its clients with CURVE (:mod:`groundstation.telemetry.curve`):
    ``control_server_key`` and ``control_client_keys`` together turn CURVE on, and an
    endpoint beyond loopback is refused without them.
    """

    enabled: bool = True
    endpoint: ZmqEndpoint = "tcp://127.0.0.1:5556"
    # loopback by default; bind to * to serve the lab
    rate_hz: Annotated[float, within(
        0.0, 100.0, "Hz: at most one message per IMU sample (100 Hz)",
        lo_open=True)] = 20.0  # enough for a live view, light on the loop
    # (the two key fields come before control_endpoint so its check can see them)
    control_server_key: FilePath | None = None
    # the daemon's CURVE key pair: a `.key_secret` file of zmq.auth.create_certificates
    control_client_keys: DirectoryPath | None = None
    # directory of the public keys (`*.key`) of the clients allowed to connect
    control_endpoint: str | None = "tcp://127.0.0.1:5557"
    # REP socket for run-time requests (`gs channels`); loopback only by default, null disables

    @field_validator("control_client_keys")
    @classmethod
    def _keys_in_pairs(cls, value: Path | None, info: ValidationInfo) -> Path | None:
        if (value is None) != (info.data.get("control_server_key") is None):
            raise ValueError("control_server_key and control_client_keys go together: "
                             "set both to authenticate clients with CURVE, or neither")
        return value

    @field_validator("control_endpoint")
    @classmethod
    def _control_bind(cls, value: str | None, info: ValidationInfo) -> str | None:
        if value is None:
            return value
        zmq_endpoint(value)
        if not local_endpoint(value) and info.data.get("control_server_key") is None:
            raise ValueError("reaches beyond loopback without authentication: set "
                             "telemetry.control_server_key and telemetry.control_client_keys "
                             "(CURVE), or bind tcp://127.0.0.1:PORT")
        return value


class LoggingConfig(ConfigModel):
    """Console/JSON logging and the flight recorder."""

    level: Literal["debug", "info", "warning", "error"] = "info"
    format: Literal["auto", "console", "json"] = "auto"  # auto: console on a TTY, else JSON
    flight_log_dir: DirectoryPath = Path("flightlogs")
    # a directory, or one the recorder can make (with its parents)
    mcap: bool = False
    # also write the flight as flight.mcap (gs export --format mcap) beside flight.npy
    # when the daemon closes its log (needs the analysis extra; the loop never waits)


FifoPriority = Annotated[int, within(
    1, 98, "SCHED_FIFO priorities are 1-99; 99 belongs to the kernel's migration and watchdog "
    "threads")]


class RealtimeConfig(ConfigModel):
    """What the daemon asks of the OS while it flies (see groundstation/loop/realtime.py)."""

    cpu_dma_latency_us: Annotated[int, within(
        0, 10_000, "us: a wake-up latency longer than the 10 ms IMU period protects no "
        "tick (null asks nothing)")] | None = 0
    # PM QoS wake-up latency bound held while flying; 0 keeps the CPUs out of idle
    # states (measured: 3-6x cheaper ticks on a VM). null leaves the idle states alone
    fifo_priority: FifoPriority | None = 10
    # SCHED_FIFO priority of the flight loop and its threads while flying (needs
    # CAP_SYS_NICE or LimitRTPRIO; without, a warning and the normal policy). Under two
    # busy processes the normal policy let COMMAND gaps reach 114 ms (issue 14); null
    # asks for nothing
    switch_interval_ms: Annotated[float, within(
        0.0, 5.0, "ms: the longest a reader thread may delay a 10 ms tick; Python's own "
        "default is 5 ms", lo_open=True)] = 0.5
    # GIL switch interval while flying: the longest a reader thread can delay a tick
    paced_gc: bool = True
    # freeze the start-up objects and run full garbage collections only right after a
    # COMMAND went out (realtime.CollectorPacer): the interpreter's own full collection
    # walked all ~93,000 objects in ~64 ms and the vehicle's 100 ms watchdog expired in
    # the air (issue 14). false: the interpreter's own collector


# --------------------------------------------------------------------------- api
class ApiConfig(ConfigModel):
    """Motions commanded at run time (``trajectory.name: none``; ``groundstation.client``,
    ``gs goto``): the flight takes off to ``trajectory.center`` and holds there until a
    client asks for a motion; each is checked against the safety limits and volume."""

    idle_land_s: Annotated[float, within(
        0.0, FLIGHT_MAX_S, "s: an hour of hovering outlasts any battery of the class",
        lo_open=True)] = 60.0
    # land after holding this long without a motion command [s]; tuned for experiments
    # driven from a notebook (a minute to type the next command)
    speed_m_s: Speed = 0.5
    # mean speed of a go-to without a duration [m/s]; the take-off's climb speed
    arrival_tolerance_m: LabLength = 0.05
    # a motion has arrived once its reference is at rest and the estimate this close [m]
    plan_timeout_s: Annotated[float, within(
        0.0, 60.0, "s: the longest motion plans in about 2 s; a minute's wait is a hung "
        "planner", lo_open=True)] = 5.0
    # longest a motion request may take to plan [s] (in the planner process, off the
    # flight loop): a plan not made by then is refused and the planner restarted. The
    # longest motion (600 s) takes about 2 s on the project's VM
    start_horizon_s: Annotated[float, within(
        0.0, FLIGHT_MAX_S, "s: a start beyond an hour outlasts any battery of the class",
        lo_open=True)] = 300.0
    # how far from now a follow's start_at may be [s]; a few minutes to line up clients


# --------------------------------------------------------------------------- fleet
# Several vehicles on one Vicon (groundstation/fleet, README "Fleet"). A fleet.yaml file
# (groundstation/fleet/fleetfile.py) writes this section for each of its daemons; a
# single-vehicle configuration has none. Nothing here imports the fleet package.
FLEET_NAME = r"^[A-Za-z0-9][A-Za-z0-9_-]{0,31}$"
"""A fleet's or a vehicle's name: one Zenoh key chunk (letters, digits, - and _; no /,
*, $, # or ?: those are Zenoh's wildcards and separators)."""

RESERVED_NAMES = ("vicon", "relay")
"""Key chunks under a fleet's prefix that are not vehicles: the relayed Vicon poses and
the relay's own health."""

_ZENOH_ENDPOINT = re.compile(r"^(tcp|tls|udp|quic)/(\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9.-]+):"
                             r"([0-9]{1,5})$")


def zenoh_endpoint(value: str) -> str:
    """A Zenoh locator ``PROTOCOL/HOST:PORT`` (tcp, tls, udp or quic; HOST an address, a
    [IPv6] or a name; PORT 0-65535, 0 for any free one). ValueError naming what is
    wrong."""
    match = _ZENOH_ENDPOINT.match(value)
    if match is None:
        raise ValueError("must be a Zenoh endpoint PROTOCOL/HOST:PORT, e.g. "
                         "tcp/127.0.0.1:7447 (tcp, tls, udp or quic)")
    if int(match.group(3)) > 65535:
        raise ValueError(f"port {match.group(3)}: a port is 0-65535")
    return value


def zenoh_local(endpoint: str) -> bool:
    """Whether a Zenoh endpoint reaches only this machine: a loopback address (127.0.0.0/8,
    [::1]) or ``localhost``. ``tcp/0.0.0.0:7447``, another address or a name are not."""
    host = endpoint.partition("/")[2].rpartition(":")[0].removeprefix("[").removesuffix("]")
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:  # a host name: it may resolve anywhere
        return False


ZenohEndpoint = Annotated[str, AfterValidator(zenoh_endpoint)]
FleetName = Annotated[str, Field(pattern=FLEET_NAME)]


class ZenohConfig(ConfigModel):
    """How this process joins the fleet's Zenoh network: peer to peer, no multicast
    scouting, explicit endpoints. Anything beyond loopback needs TLS with client
    certificates (mTLS) signed by ``tls_root_ca``; the fleet's access rules are then on,
    by certificate common name (groundstation/fleet/session.py)."""

    listen: list[ZenohEndpoint] = Field(default_factory=list)
    # where this process accepts the others' links (a daemon: its own port; a client: none)
    connect: list[ZenohEndpoint] = Field(default_factory=lambda: ["tcp/127.0.0.1:7447"])
    # the others' listen endpoints (the relay's and every other daemon's): a full mesh, so
    # any one process may stop without cutting the others apart; retried while absent
    tls_root_ca: FilePath | None = None
    # PEM certificate of the lab's CA: every member's certificate must be signed by it
    tls_certificate: FilePath | None = None
    # this process's PEM certificate; its common name is its name in the access rules
    tls_private_key: FilePath | None = None  # its PEM private key
    operators: list[FleetName] = Field(default_factory=list)
    # certificate common names allowed to send requests (go_to, follow, hold, land) and
    # read telemetry beyond the vehicles themselves (a lab member's laptop, `gs fleet`)

    @model_validator(mode="after")
    def _access(self) -> ZenohConfig:
        tls = (self.tls_root_ca, self.tls_certificate, self.tls_private_key)
        if any(v is not None for v in tls) and not all(v is not None for v in tls):
            raise FieldValueError("tls_root_ca", self.tls_root_ca, "tls_root_ca, "
                                  "tls_certificate and tls_private_key go together (mTLS)")
        secured = self.tls_root_ca is not None
        for field in ("listen", "connect"):
            for endpoint in getattr(self, field):
                if secured and not endpoint.startswith(("tls/", "quic/")) \
                        and not zenoh_local(endpoint):
                    raise FieldValueError(field, endpoint, f"{endpoint}: a plain link beyond "
                                          "loopback: use tls/HOST:PORT with TLS on")
                if not secured and not zenoh_local(endpoint):
                    raise FieldValueError(field, endpoint, f"{endpoint} reaches beyond "
                                          "loopback without TLS: set fleet.zenoh.tls_root_ca, "
                                          "tls_certificate and tls_private_key (mTLS and the "
                                          "fleet's access rules), or use tcp/127.0.0.1:PORT")
        return self


class FleetConfig(ConfigModel):
    """This daemon as one vehicle of a fleet: its keys, its peers and the separation kept
    between them (README "Fleet")."""

    name: FleetName = "lab"
    # the key prefix: every key of the fleet is <name>/..., so two fleets on one network
    # never mix
    vehicle: FleetName = "x3d"
    # this vehicle's name: its telemetry and requests are under <name>/<vehicle>/
    peers: list[FleetName] = Field(default_factory=list)
    # the other vehicles of the fleet, whose estimated poses this daemon watches
    separation_m: Annotated[float, within(0.0, LAB_EXTENT_M, "m: a distance within a "
                                          "lab (LAB_EXTENT_M)", lo_open=True)] | None = None
    # least distance between two vehicles [m], kept at planning (a motion that would bring
    # them closer is refused) and in flight (closer: both hold; closer than half of it:
    # both land). null: off, and then no two vehicles' volumes may overlap (fleet.yaml)
    separation_hold_s: Annotated[float, within(
        0.0, 30.0, "s: a hold beside a peer longer than 30 s is a stand-off, not a pause",
        lo_open=True)] = 3.0
    # held closer than separation_m this long without the gap opening again: land
    peer_timeout_s: Annotated[float, within(
        0.0, 5.0, "s: a peer silent for 5 s may be anywhere a vehicle can fly in 5 s",
        lo_open=True)] = 0.5
    # a peer whose pose is older than this is silent: new motions are refused (the one
    # in progress, already checked, is flown); the Vicon loss-hold time, by analogy
    pose_rate_hz: Annotated[float, within(
        0.0, 100.0, "Hz: at most one pose per IMU sample (100 Hz)", lo_open=True)] = 50.0
    # estimated pose published for the peers' separation checks (the command rate)
    zenoh: ZenohConfig = ZenohConfig()

    @model_validator(mode="after")
    def _names(self) -> FleetConfig:
        for field, names in (("vehicle", [self.vehicle]), ("peers", self.peers)):
            for name in names:
                if name in RESERVED_NAMES:
                    raise FieldValueError(field, name, f"{name!r} is a key of the fleet "
                                          f"itself ({', '.join(RESERVED_NAMES)}), not a vehicle")
        if self.vehicle in self.peers or len(set(self.peers)) != len(self.peers):
            raise FieldValueError("peers", self.peers, "each peer once, and not this "
                                  "vehicle itself")
        return self


# --------------------------------------------------------------------------- top level
class GroundStationConfig(ConfigModel):
    """The whole configuration file."""

    serial: SerialConfig = SerialConfig()
    channels: ChannelsConfig = ChannelsConfig()
    vicon: ViconConfig = ViconConfig()
    vehicle: VehicleConfig = VehicleConfig()
    estimator: EstimatorConfig = EstimatorConfig()
    controller: ControllerConfig = ControllerConfig()
    trajectory: TrajectoryConfig = TrajectoryConfig()
    safety: SafetyConfig = SafetyConfig()
    telemetry: TelemetryConfig = TelemetryConfig()
    logging: LoggingConfig = LoggingConfig()
    realtime: RealtimeConfig = RealtimeConfig()
    api: ApiConfig = ApiConfig()
    fleet: FleetConfig | None = None
    # this vehicle in a fleet (fleet.yaml writes it): null flies alone
    sim: SkipValidation[SerializeAsAny[BaseModel] | None] = None
    # the virtual lab's section (config/sim.yaml): the ground station never reads it;
    # validate_config has the installed lab validate it (groundstation.lab)

    @model_validator(mode="after")
    def _vicon_source(self) -> GroundStationConfig:
        if self.vicon.source == "zenoh" and self.fleet is None:
            raise FieldValueError("vicon.source", "zenoh", "takes the poses from the fleet's "
                                  "relay: it needs a fleet: section (name, zenoh endpoints)")
        return self


# --------------------------------------------------------------------------- loading
MAX_FILE_BYTES = 1 << 20
"""Largest configuration file read [bytes]; the shipped ones are a few KiB."""

MAX_YAML_VALUES = 100_000
"""Most values a file may expand to through YAML aliases (a "billion laughs" file would
otherwise take the validator and the error messages exponential time)."""

_YAML12_EXPONENT_FLOAT = re.compile(r"^[-+]?[0-9][0-9_]*(?:\.[0-9_]*)?[eE][-+]?[0-9]+$")


class _Loader(yaml.SafeLoader):
    """PyYAML's safe loader, reading ``1e-3`` and ``1e30`` as numbers (YAML 1.2; PyYAML
    follows YAML 1.1 and reads them as strings, which strict numbers would refuse)."""


_Loader.add_implicit_resolver("tag:yaml.org,2002:float", _YAML12_EXPONENT_FLOAT,
                              list("-+0123456789"))


def _check_keys(root: yaml.Node, source: str) -> dict[str, int]:
    """Refuse a mapping key given twice (YAML would keep the last silently) and a file
    that expands past :data:`MAX_YAML_VALUES` values. Walks aliases as expanded.

    Returns the line (from 1) of every key and list item by its dotted path
    (``vehicle.mass_kg``, ``safety.volume_x.0``), for error messages."""
    lines: dict[str, int] = {}
    budget = MAX_YAML_VALUES
    stack: list[tuple[yaml.Node, str]] = [(root, "")]
    while stack:
        node, path = stack.pop()
        budget -= 1
        if budget < 0:
            raise ConfigError(f"{source}: expands to more than {MAX_YAML_VALUES} values "
                              "(through YAML aliases): not a configuration")
        if isinstance(node, yaml.SequenceNode):
            for i, item in enumerate(node.value):
                here = f"{path}.{i}" if path else str(i)
                lines.setdefault(here, item.start_mark.line + 1)
                stack.append((item, here))
        elif isinstance(node, yaml.MappingNode):
            first: dict[str, int] = {}
            for key, value in node.value:
                name = key.value if isinstance(key, yaml.ScalarNode) else "<complex key>"
                line = key.start_mark.line + 1
                here = f"{path}.{name}" if path else name
                if key.tag != "tag:yaml.org,2002:merge" and isinstance(key, yaml.ScalarNode):
                    if name in first:
                        reason = (f"duplicate key (first at line {first[name]}; YAML would keep "
                                  "only the last)")
                        raise ConfigError(f"{source}:{line}: {here}: {reason}",
                                          [(here, name, reason)])
                    first[name] = line
                lines.setdefault(here, line)
                stack.append((value, here))
    return lines


def _parse_yaml(raw: bytes, source: str) -> tuple[Any, dict[str, int]]:
    """The YAML document in ``raw`` and the line of each key (:func:`_check_keys`);
    ConfigError (one line) for anything that is not one UTF-8 YAML document without
    repeated keys."""
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        where = _line_column(raw[:exc.start].decode("utf-8"))
        raise ConfigError(f"{source}:{where}: not UTF-8 text (byte 0x{raw[exc.start]:02x}): "
                          "save the file as UTF-8") from None
    try:
        loader = _Loader(text)  # refuses characters YAML does not allow, all at once
    except ReaderError as exc:
        code = exc.character if isinstance(exc.character, int) else ord(exc.character)
        name = " (a NUL byte)" if code == 0 else ""
        raise ConfigError(f"{source}:{_line_column(text[:exc.position])}: not valid YAML: "
                          f"character U+{code:04X}{name} is not allowed (YAML refuses "
                          "control characters other than tab and line breaks)") from None
    try:
        node = loader.get_single_node()
        if node is None:
            return None, {}
        lines = _check_keys(node, source)
        return loader.construct_document(node), lines
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        where = f"{source}:{mark.line + 1}:{mark.column + 1}" if mark else source
        why = ", ".join(part for part in (exc.context, exc.problem) if part)
        raise ConfigError(f"{where}: not valid YAML: {why}") from None
    except yaml.YAMLError as exc:
        raise ConfigError(f"{source}: not valid YAML: {exc}") from None
    except RecursionError:
        raise ConfigError(f"{source}: not valid YAML: nested too deeply") from None
    finally:
        loader.dispose()


def _line_column(before: str) -> str:
    """``LINE:COLUMN`` (both from 1, the column in characters) of the character that
    follows the text ``before``, as editors count them."""
    return f"{before.count(chr(10)) + 1}:{len(before) - before.rfind(chr(10))}"


def _clip(value: object, chars: int = 1000) -> str:
    text = repr(value)
    return text if len(text) <= chars else text[:chars - 3] + "..."


def _problems(exc: ValidationError) -> list[tuple[str, object, str]]:
    """One (field path, value, reason) per pydantic error; a :class:`FieldValueError` is
    reported at the field it names."""
    out = []
    for err in exc.errors(include_url=False):
        loc = tuple(err["loc"])
        reason = err["msg"].removeprefix("Value error, ")
        value = err.get("input")
        cause = (err.get("ctx") or {}).get("error")
        if isinstance(cause, FieldValueError):  # the value as the file wrote it
            loc = (*loc, cause.field)
            value = value.get(cause.field, cause.value) if isinstance(value, dict) \
                else cause.value
        path = ".".join(str(p) for p in loc) or "<root>"
        if err["type"] == "extra_forbidden":
            reason = "unknown key"
        elif err["type"] == "missing":
            reason = "required field is missing"
        elif err["type"] in ("int_type", "float_type") and isinstance(value, bool):
            reason = f"{reason}, not a boolean"
        elif err["type"] == "int_type" and isinstance(value, float):
            reason = f"{reason}, not a fraction or exponent (whole numbers only)"
        elif err["type"] == "finite_number":
            reason = f"{reason}: a time, rate, length or gain is never infinite or NaN"
        out.append((path, value, reason))
    return out


def describe_problems(exc: ValidationError) -> str:
    """Every problem of ``exc`` on one line: ``field: reason; field: reason``."""
    return "; ".join(f"{path}: {reason}" for path, _value, reason in _problems(exc))


def _line_of(path: str, lines: dict[str, int]) -> int | None:
    """The line of ``path`` in the file, else of its nearest enclosing key (a missing
    field: its section), else None."""
    while path:
        if path in lines:
            return lines[path]
        path = path.rpartition(".")[0]
    return None


def _raise(problems: list[tuple[str, object, str]], source: str,
           lines: dict[str, int] | None = None) -> None:
    """ConfigError with one line per problem: ``SOURCE:LINE: field: value: reason``
    (``SOURCE: field: ...`` where the line is not known: defaults, overrides)."""
    out = []
    for path, value, reason in problems:
        line = _line_of(path, lines or {})
        where = source if line is None else f"{source}:{line}"
        out.append(f"{where}: {path}: {_clip(value)}: {reason}")
    raise ConfigError("\n".join(out), problems)


def validate_config(data: dict[str, Any], source: str = "<config>",
                    lines: dict[str, int] | None = None) -> GroundStationConfig:
    """Validate a parsed mapping; raise ConfigError naming every bad field (and its line,
    from ``lines``: dotted path -> line in the file, as :func:`_check_keys` finds them)."""
    if not isinstance(data, dict):
        _raise([("<root>", data, "the file must hold a mapping of sections")], source)
    problems: list[tuple[str, object, str]] = []
    sections = {key: value for key, value in data.items() if key != "sim"}
    config = None
    try:
        config = GroundStationConfig.model_validate(sections)
    except ValidationError as exc:
        problems += _problems(exc)
    sim = _lab_section(data.get("sim"), problems)
    if problems or config is None:
        _raise(problems, source, lines)
        raise AssertionError("unreachable")
    return config if sim is None else config.model_copy(update={"sim": sim})


def _lab_section(data: object, problems: list[tuple[str, object, str]]) -> BaseModel | None:
    """The ``sim:`` section validated by the installed virtual lab; its problems are
    added to ``problems`` with paths under ``sim``."""
    if data is None:
        return None
    from groundstation.lab import LabNotInstalledError, virtual_lab

    try:
        return virtual_lab().validate_section(data)
    except ValidationError as exc:
        problems += [("sim" if path == "<root>" else f"sim.{path}", value, reason)
                     for path, value, reason in _problems(exc)]
    except LabNotInstalledError as exc:
        problems.append(("sim", "...", f"a virtual lab's section, but {exc}"))
    return None


def load_config(path: str | Path) -> GroundStationConfig:
    """Read and validate a YAML configuration file.

    Raises ConfigError, with a one-line reason, if the file is missing, larger than
    :data:`MAX_FILE_BYTES`, not UTF-8, not one YAML document, repeats a key, or holds
    nothing; and naming every bad field if it fails validation. Files the configuration
    names are checked by :func:`check_files`.
    """
    path = Path(path)
    try:
        with path.open("rb") as file:
            raw = file.read(MAX_FILE_BYTES + 1)
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read: {exc.strerror}") from exc
    if len(raw) > MAX_FILE_BYTES:
        raise ConfigError(f"{path}: larger than {MAX_FILE_BYTES >> 10} KiB: "
                          "not a configuration")
    data, lines = _parse_yaml(raw, str(path))
    if data is None:
        raise ConfigError(f"{path}: empty (no sections, only comments or nothing): a "
                          "configuration names at least one section; see config/lab.yaml")
    return validate_config(data, str(path), lines)


def key_lines(path: str | Path) -> dict[str, int]:
    """The line of every key of a configuration file by its dotted path (empty if the
    file cannot be read or parsed: then :func:`load_config` says why)."""
    try:
        raw = Path(path).read_bytes()[:MAX_FILE_BYTES + 1]
        return _parse_yaml(raw, str(path))[1]
    except (OSError, ConfigError):
        return {}


def check_files(config: GroundStationConfig, source: str = "<config>",
                lines: dict[str, int] | None = None) -> None:
    """Check that the files the configuration names exist and can be used, as the flight
    will open them: the waypoint CSV, the H-infinity gain, the control socket's CURVE
    keys. Raises ConfigError naming every field whose file cannot be used (and its line in
    the file: ``lines`` as :func:`key_lines` gives them).

    Relative paths are taken from the working directory, as the flight takes them.
    """
    problems: list[tuple[str, object, str]] = []

    def readable(field: str, path: Path | None) -> None:
        if path is None:
            return
        if not path.exists():
            problems.append((field, str(path), "no such file"))
        elif not path.is_file():
            problems.append((field, str(path), "not a file"))
        elif not os.access(path, os.R_OK):
            problems.append((field, str(path), "not readable"))

    readable("trajectory.file", config.trajectory.file)
    readable("controller.hinf.gain_file", config.controller.hinf.gain_file)
    t = config.telemetry
    if t.control_endpoint is not None and t.control_server_key is not None:
        from groundstation.telemetry.curve import read_key_pair, read_public_keys

        try:
            read_key_pair(t.control_server_key)
        except ValueError as exc:
            problems.append(("telemetry.control_server_key", str(t.control_server_key),
                             str(exc)))
        try:
            read_public_keys(t.control_client_keys or Path())  # set: the validator pairs them
        except ValueError as exc:
            problems.append(("telemetry.control_client_keys", str(t.control_client_keys),
                             str(exc)))
    if problems:
        _raise(problems, source, lines)


def apply_overrides(
    config: GroundStationConfig, overrides: dict[str, Any]
) -> GroundStationConfig:
    """Return a copy with dotted-path fields replaced, re-validated as a whole.

    ``apply_overrides(cfg, {"serial.port": "/dev/pts/3", "vicon.port": 51002})``.
    ``None`` values are skipped (an option the user did not give). An unknown
    path or an invalid value raises ConfigError naming the path.
    """
    data = config.model_dump(mode="json")
    for dotted, value in overrides.items():
        if value is None:
            continue
        node = data
        *parents, leaf = dotted.split(".")
        for i, key in enumerate(parents):
            if node.get(key) is None:
                node[key] = {}
            if not isinstance(node[key], dict):
                _raise([(".".join(parents[:i + 1]), node[key], "not a section")], "override")
            node = node[key]
        node[leaf] = copy.deepcopy(value)
    return validate_config(data, "override")


def dump_config(config: GroundStationConfig) -> str:
    """The validated configuration as YAML (what `gs check-config` prints)."""
    return yaml.safe_dump(config.model_dump(mode="json"), sort_keys=False)
