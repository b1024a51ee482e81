"""The AscTec AutoPilot "LL" serial dialect, sans-IO: packets, polls, commands, acks.

The second dialect beside the X-3D one (``docs/protocol.md`` describes both; the facts
come from public AscTec host code). What differs from the X-3D dialect:

* **Downlink**: framed packets as in the X-3D dialect (same markers, length, CRC16) but
  with their own descriptor table (:data:`LL_MESSAGE_TYPES`): LL_STATUS (0x02),
  IMU_RAWDATA (0x01: the X-3D DATA's descriptor, never decoded as such),
  IMU_CALCDATA (0x03), RC_DATA (0x15), CONTROLLER_OUTPUT (0x11); and 5-byte
  acknowledgements ``>a`` + byte + ``a<`` after each command (:class:`LlDecoder`).
* **Uplink**, unframed and without CRC: a poll ``>*>p`` + uint16 mask (:func:`encode_poll`;
  the vehicle answers one packet per requested bit, and sends nothing unpolled), a
  command ``>*>di`` + the X-3D COMMAND's 12-byte payload (:func:`encode_command`), and an
  emergency ``>*>me`` (unverified; never sent by the ground station). The vehicle's side
  of the uplink is :class:`LlRequestDecoder` (the virtual vehicle uses it).

There is no sample counter: a repeated IMU sample is recognised by identical values
(thesis Algorithm 1), which :class:`RepeatCounter` turns into a counter.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, replace
from enum import IntFlag
from types import MappingProxyType
from typing import ClassVar, Final

from groundstation.asctec.crc import DEFAULT_PROFILE
from groundstation.asctec.decoder import (
    Ack,
    DecoderCounts,
    FrameDecoder,
    FrameType,
    RejectedFrame,
)
from groundstation.asctec.messages import (
    CommandMsg,
    PayloadError,
    RejectReason,
)
from groundstation.errors import ProtocolError

POLL_HEADER: Final = b">*>p"
COMMAND_HEADER: Final = b">*>di"
EMERGENCY: Final = b">*>me"
POLL_SIZE: Final = len(POLL_HEADER) + 2
COMMAND_SIZE: Final = len(COMMAND_HEADER) + 12
ACK_FRAME_SIZE: Final = 5
LL_THRUST_MAX: Final = 4095
"""The LL command's thrust range is 0..4095 (the X-3D's reaches 4096)."""

_POLL: Final = struct.Struct("<H")


class PollMask(IntFlag):
    """Request bits of a poll (which packets the vehicle answers with)."""

    LL_STATUS = 0x0001
    IMU_RAWDATA = 0x0002
    IMU_CALCDATA = 0x0004
    RC_DATA = 0x0008
    CONTROLLER_OUTPUT = 0x0010
    GPS_DATA = 0x0080
    GPS_DATA_ADVANCED = 0x0200


FLIGHT_MODE_SERIAL_ENABLED: Final = 0x20
"""LL_STATUS flightMode bit: the pilot's switch enables the serial interface (one public
driver; unverified elsewhere)."""
FLIGHT_MODE_SERIAL_ACTIVE: Final = 0x40
"""LL_STATUS flightMode bit: serial commands are being applied (same source)."""


def _payload(cls: type, payload: bytes) -> tuple[int, ...]:
    struct_: struct.Struct = cls.STRUCT  # type: ignore[attr-defined]
    try:
        return struct_.unpack_from(payload)
    except struct.error as exc:  # the decoder checks the length first; a direct caller may not
        raise PayloadError(RejectReason.BAD_LENGTH, f"{cls.__name__}: {exc}") from None


@dataclass(frozen=True, slots=True)
class LlStatus:
    """LL_STATUS (descriptor 0x02, 16 bytes).

    battery_mv_1, battery_mv_2 : battery voltages [mV]; status, cpu_load [control cycles
    per second, ~1000]; compass_enabled, chksum_error, flying, motors_on : flags;
    flight_mode : bits (0x20 serial interface enabled by the pilot's switch, 0x40 serial
    commands applied); up_time : [s].
    """

    DESCRIPTOR: ClassVar[int] = 0x02
    NAME: ClassVar[str] = "ll_status"
    STRUCT: ClassVar[struct.Struct] = struct.Struct("<hhhhbbbbhh")
    PAYLOAD_SIZES: ClassVar[frozenset[int]] = frozenset({16})

    battery_mv_1: int
    battery_mv_2: int = 0
    status: int = 0
    cpu_load: int = 1000
    compass_enabled: int = 0
    chksum_error: int = 0
    flying: int = 0
    motors_on: int = 0
    flight_mode: int = 0
    up_time: int = 0

    @property
    def serial_enabled(self) -> bool:
        """The pilot's switch enables the serial interface (flightMode 0x20)."""
        return bool(self.flight_mode & FLIGHT_MODE_SERIAL_ENABLED)

    @property
    def serial_active(self) -> bool:
        """Serial commands are being applied (flightMode 0x40)."""
        return bool(self.flight_mode & FLIGHT_MODE_SERIAL_ACTIVE)

    def pack(self) -> bytes:
        """The 16-byte payload."""
        return self.STRUCT.pack(self.battery_mv_1, self.battery_mv_2, self.status, self.cpu_load,
                                self.compass_enabled, self.chksum_error, self.flying,
                                self.motors_on, self.flight_mode, self.up_time)

    @classmethod
    def unpack(cls, payload: bytes) -> LlStatus:
        """Parse the 16-byte payload."""
        return cls(*_payload(cls, payload))


@dataclass(frozen=True, slots=True)
class ImuRawData:
    """IMU_RAWDATA (descriptor 0x01, 28 bytes): raw counts on the body axes.

    pressure : 24-bit bias-free reading (int32); gyro, mag, acc : (x, y, z) int16 counts
    whose zero and scale are per vehicle (``vehicle.gyro_zero`` ... in the configuration);
    temp_gyro (uint16), temp_adc (uint32).
    """

    DESCRIPTOR: ClassVar[int] = 0x01
    NAME: ClassVar[str] = "imu_rawdata"
    STRUCT: ClassVar[struct.Struct] = struct.Struct("<i9hHI")
    PAYLOAD_SIZES: ClassVar[frozenset[int]] = frozenset({28})

    pressure: int
    gyro: tuple[int, int, int]
    mag: tuple[int, int, int]
    acc: tuple[int, int, int]
    temp_gyro: int = 0
    temp_adc: int = 0

    def pack(self) -> bytes:
        """The 28-byte payload."""
        return self.STRUCT.pack(self.pressure, *self.gyro, *self.mag, *self.acc, self.temp_gyro,
                                self.temp_adc)

    @classmethod
    def unpack(cls, payload: bytes) -> ImuRawData:
        """Parse the 28-byte payload."""
        v = _payload(cls, payload)
        return cls(v[0], (v[1], v[2], v[3]), (v[4], v[5], v[6]), (v[7], v[8], v[9]), v[10], v[11])

    def values(self) -> tuple[int, ...]:
        """What identifies a sample: gyro and acc counts (a repeat has them all equal)."""
        return self.gyro + self.acc


@dataclass(frozen=True, slots=True)
class RcData:
    """RC_DATA (descriptor 0x15, 33 bytes; one driver reads 34, a trailing pad byte).

    channels_in : 8 raw receiver values; channels_out : 8 bias-free values 0..4095;
    lock : valid reception (non-zero).
    """

    DESCRIPTOR: ClassVar[int] = 0x15
    NAME: ClassVar[str] = "rc_data"
    STRUCT: ClassVar[struct.Struct] = struct.Struct("<8H8HB")
    PAYLOAD_SIZES: ClassVar[frozenset[int]] = frozenset({33, 34})

    channels_in: tuple[int, ...]
    channels_out: tuple[int, ...]
    lock: int

    def pack(self) -> bytes:
        """The 33-byte payload."""
        return self.STRUCT.pack(*self.channels_in, *self.channels_out, self.lock)

    @classmethod
    def unpack(cls, payload: bytes) -> RcData:
        """Parse a 33- or 34-byte payload (the pad byte is ignored)."""
        v = _payload(cls, payload)
        return cls(tuple(v[0:8]), tuple(v[8:16]), v[16])


@dataclass(frozen=True, slots=True)
class ControllerOutput:
    """CONTROLLER_OUTPUT (descriptor 0x11, 16 bytes): the LL controller's int32 nick, roll,
    yaw and thrust outputs."""

    DESCRIPTOR: ClassVar[int] = 0x11
    NAME: ClassVar[str] = "controller_output"
    STRUCT: ClassVar[struct.Struct] = struct.Struct("<4i")
    PAYLOAD_SIZES: ClassVar[frozenset[int]] = frozenset({16})

    nick: int
    roll: int
    yaw: int
    thrust: int

    def pack(self) -> bytes:
        """The 16-byte payload."""
        return self.STRUCT.pack(self.nick, self.roll, self.yaw, self.thrust)

    @classmethod
    def unpack(cls, payload: bytes) -> ControllerOutput:
        """Parse the 16-byte payload."""
        return cls(*_payload(cls, payload))


@dataclass(frozen=True, slots=True)
class ImuCalcData:
    """IMU_CALCDATA (descriptor 0x03, 92 bytes): the vehicle's own attitude and calibrated
    values. Not needed to fly; kept as bytes."""

    DESCRIPTOR: ClassVar[int] = 0x03
    NAME: ClassVar[str] = "imu_calcdata"
    PAYLOAD_SIZES: ClassVar[frozenset[int]] = frozenset({92})

    raw: bytes

    def pack(self) -> bytes:
        """The payload as received."""
        return self.raw

    @classmethod
    def unpack(cls, payload: bytes) -> ImuCalcData:
        """Keep the payload."""
        return cls(bytes(payload))


LlMessage = LlStatus | ImuRawData | RcData | ControllerOutput | ImuCalcData
"""Any packet the LL vehicle sends."""


def _registry(*classes: type[FrameType]) -> MappingProxyType[int, type[FrameType]]:
    table: dict[int, type[FrameType]] = {}
    for cls in classes:
        if cls.DESCRIPTOR in table:
            raise ProtocolError(f"LL descriptor 0x{cls.DESCRIPTOR:02X} used twice")
        table[cls.DESCRIPTOR] = cls
    return MappingProxyType(table)


LL_MESSAGE_TYPES: Final = _registry(LlStatus, ImuRawData, ImuCalcData, RcData, ControllerOutput)
"""The LL dialect's descriptor table (vehicle -> host)."""

ANSWERS: Final[dict[PollMask, type[FrameType]]] = {
    PollMask.LL_STATUS: LlStatus, PollMask.IMU_RAWDATA: ImuRawData,
    PollMask.IMU_CALCDATA: ImuCalcData, PollMask.RC_DATA: RcData,
    PollMask.CONTROLLER_OUTPUT: ControllerOutput,
}
"""The packet each poll bit asks for (GPS bits: no packet this project decodes)."""


class LlDecoder(FrameDecoder[LlMessage | Ack]):
    """Host side: decode the vehicle's packets and acknowledgements (never raises)."""

    def __init__(self, profile: str = DEFAULT_PROFILE) -> None:
        super().__init__(LL_MESSAGE_TYPES, profile, acks=True)


# --- uplink -------------------------------------------------------------------


def encode_poll(mask: int) -> bytes:
    """``>*>p`` + uint16 request mask (:class:`PollMask` bits)."""
    if not 0 < mask <= 0xFFFF:
        raise ProtocolError(f"poll mask 0x{mask:X} is not a non-zero uint16")
    return POLL_HEADER + _POLL.pack(mask)


def encode_command(cmd: CommandMsg) -> bytes:
    """``>*>di`` + the 12-byte command payload (byte-identical to the X-3D COMMAND's);
    thrust above the LL range (4096) is sent as 4095."""
    if cmd.thrust > LL_THRUST_MAX:
        cmd = replace(cmd, thrust=LL_THRUST_MAX)
    return COMMAND_HEADER + cmd.pack()


def encode_ack(value: int = 0) -> bytes:
    """The vehicle's acknowledgement of a command: ``>a`` + byte + ``a<``."""
    return b">a" + bytes((value & 0xFF,)) + b"a<"


def motor_gesture(start: bool, start_yaw: int = -2047) -> CommandMsg:
    """The stick gesture that starts (or stops) the motors: thrust 0, yaw full one way
    (``start_yaw`` to start, the opposite to stop: drivers disagree on the sign), ctrl
    0x0C (yaw and thrust). Hold it about half a second; only on an operator's request."""
    yaw = start_yaw if start else -start_yaw
    return CommandMsg(pitch=0, roll=0, yaw=yaw, thrust=0, ctrl=0x0C)


@dataclass(frozen=True, slots=True)
class Poll:
    """A poll the vehicle received: answer one packet per set bit."""

    mask: int


@dataclass(frozen=True, slots=True)
class Emergency:
    """``>*>me`` (unverified e-stop of one driver)."""


LlRequest = Poll | CommandMsg | Emergency


class LlRequestDecoder:
    """Vehicle side: decode the host's unframed polls, commands and emergencies.

    Sans-IO and never raises. A ``>*>`` followed by anything else, or a command whose
    checksum or ranges are wrong, is rejected and scanning resumes one byte later.
    """

    def __init__(self) -> None:
        self._buf = bytearray()
        self._bytes_in = 0
        self._skipped = 0
        self._frames = {"poll": 0, "command": 0, "emergency": 0}
        self._rejections: dict[RejectReason, int] = dict.fromkeys(RejectReason, 0)

    def counts(self) -> DecoderCounts:
        """A snapshot of the counters."""
        return DecoderCounts(bytes_in=self._bytes_in, bytes_skipped=self._skipped,
                             frames=dict(self._frames),
                             rejections={r.value: n for r, n in self._rejections.items()})

    def feed(self, data: bytes | bytearray) -> list[LlRequest | RejectedFrame]:
        """Add received bytes; return the requests they completed, in order."""
        buf = self._buf
        buf += data
        self._bytes_in += len(data)
        out: list[LlRequest | RejectedFrame] = []
        pos, n = 0, len(buf)
        while True:
            start = buf.find(b">*>", pos)
            if start < 0:
                keep = max(pos, n - 2)
                self._skipped += keep - pos
                pos = keep
                break
            self._skipped += start - pos
            pos = start
            if n - pos < 5:
                break
            kind = bytes(buf[pos + 3:pos + 5])
            if kind[:1] == b"p":
                if n - pos < POLL_SIZE:
                    break
                (mask,) = _POLL.unpack_from(buf, pos + 4)
                out.append(Poll(mask))
                self._frames["poll"] += 1
                pos += POLL_SIZE
            elif kind == b"di":
                if n - pos < COMMAND_SIZE:
                    break
                try:
                    out.append(CommandMsg.unpack(bytes(buf[pos + 5:pos + COMMAND_SIZE])))
                except PayloadError as exc:
                    out.append(self._reject(exc.reason, buf, pos, COMMAND_SIZE))
                    pos += 1
                    continue
                self._frames["command"] += 1
                pos += COMMAND_SIZE
            elif kind == b"me":
                out.append(Emergency())
                self._frames["emergency"] += 1
                pos += 5
            else:
                out.append(self._reject(RejectReason.BAD_REQUEST, buf, pos, 5))
                pos += 1
        del buf[:pos]
        return out

    def _reject(self, reason: RejectReason, buf: bytearray, pos: int,
                size: int) -> RejectedFrame:
        self._rejections[reason] += 1
        self._skipped += 1
        return RejectedFrame(reason, buf[pos + 3], bytes(buf[pos:pos + size]))


class RepeatCounter:
    """A sample counter for a dialect without one (thesis Algorithm 1): it advances when
    the IMU values change and stays when a sample repeats the previous one's values
    exactly, so the ground station's repeat detection sees the repeat (uint16, wraps)."""

    def __init__(self) -> None:
        self._last: tuple[int, ...] | None = None
        self.value = 0
        self.repeats = 0

    def update(self, values: tuple[int, ...]) -> int:
        """The counter for a sample with ``values``."""
        if values == self._last:
            self.repeats += 1
        else:
            self.value = (self.value + 1) & 0xFFFF
            self._last = values
        return self.value
