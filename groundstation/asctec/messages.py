"""The three X-3D messages (spec section 3) and the descriptor registry.

Each message is a frozen, slotted dataclass with a class-level ``struct.Struct``
(or, for DATA, one per block), ``pack() -> bytes`` giving the frame *payload*
and ``unpack(payload) -> msg``. Framing (markers, length, CRC) is
:mod:`groundstation.asctec.decoder`'s job. :data:`MESSAGE_TYPES` maps each
descriptor to its class; it is built once at import and refuses duplicates.

Constructing a message validates it (a bad value is a sender bug and raises
:class:`~groundstation.errors.ProtocolError`). ``unpack`` raises
:class:`PayloadError`, a ProtocolError carrying the :class:`RejectReason` the
stream decoder counts.
"""

from __future__ import annotations

import operator
import struct
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from enum import StrEnum
from types import MappingProxyType
from typing import ClassVar, Final

from groundstation.asctec.blocks import (
    DATA_PAYLOAD_SIZES,
    DATA_SIZE_BY_MASK,
    KNOWN_SENSOR_MASK,
    PRESSURE_STRUCT,
    AxisCounts,
    RcBlock,
    StatusBlock,
)
from groundstation.errors import ProtocolError
from groundstation.types import CHANNELS, Channel

DESCRIPTOR_DATA: Final = 0x01
DESCRIPTOR_CONFIG: Final = 0x10
DESCRIPTOR_COMMAND: Final = 0x11


class RejectReason(StrEnum):
    """Why the decoder rejected a frame candidate (one counter each)."""

    BAD_LENGTH = "bad_length"  # N impossible for the descriptor (fixed size / no DATA mask fits)
    BAD_CRC = "bad_crc"  # CRC16 over the payload does not match
    BAD_END = "bad_end"  # end marker `<#<` missing where N says it is
    UNKNOWN_DESCRIPTOR = "unknown_descriptor"
    DATA_MASK = "data_mask"  # DATA mask has unknown bits or disagrees with N
    COMMAND_RANGE = "command_range"  # COMMAND value or ctrl mask out of range
    COMMAND_CHECKSUM = "command_checksum"  # COMMAND additive checksum wrong
    CONFIG_MASK = "config_mask"  # CONFIG asks for unknown sensor blocks
    BAD_ACK = "bad_ack"  # LL dialect: `>a` not followed by a byte and `a<`
    BAD_REQUEST = "bad_request"  # LL dialect, vehicle side: `>*>` + an unknown request


class PayloadError(ProtocolError):
    """A payload that passed framing but is not a valid message; ``reason`` says why."""

    def __init__(self, reason: RejectReason, message: str) -> None:
        super().__init__(message)
        self.reason = reason


# --- control channels (COMMAND ctrl mask, spec 3.2) -------------------------

# The channel names and their bit order: :data:`groundstation.types.CHANNELS`.
CHANNEL_BITS: Final[Mapping[Channel, int]] = MappingProxyType(
    {name: 1 << i for i, name in enumerate(CHANNELS)}
)
ALL_CHANNELS_MASK: Final = 0x0F
_BIT_BY_NAME: Final[dict[str, int]] = {name: 1 << i for i, name in enumerate(CHANNELS)}


def channel_mask(channels: Iterable[str]) -> int:
    """Ctrl mask with the bits of ``channels`` set; raises ProtocolError for unknown names."""
    mask = 0
    for name in channels:
        bit = _BIT_BY_NAME.get(name)
        if bit is None:
            raise ProtocolError(f"unknown channel {name!r} (known: {', '.join(CHANNELS)})")
        mask |= bit
    return mask


def mask_channels(mask: int) -> tuple[Channel, ...]:
    """The channels whose bits are set in ``mask``, in bit order (other bits ignored)."""
    return tuple(name for name in CHANNELS if mask & CHANNEL_BITS[name])


def _check_range(what: str, value: int, lo: int, hi: int) -> None:
    """Raise ProtocolError unless ``value`` is an integer in ``lo..hi``."""
    try:
        number = operator.index(value)
    except TypeError:
        raise ProtocolError(f"{what} must be an integer, got {value!r}") from None
    if not lo <= number <= hi:
        raise ProtocolError(f"{what} {number} outside {lo}..{hi}")


# --- CONFIG ------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class ConfigMsg:
    """CONFIG (ground station -> X-3D, descriptor 0x10, N = 4).

    sensor_mask : DATA blocks to stream (see blocks.SENSOR_BLOCKS; bits 0..4 only)
    period_ms : DATA period [ms] (10 = 100 Hz; 0 = stop streaming), uint16
    """

    DESCRIPTOR: ClassVar[int] = DESCRIPTOR_CONFIG
    NAME: ClassVar[str] = "config"
    STRUCT: ClassVar[struct.Struct] = struct.Struct("<HH")
    PAYLOAD_SIZES: ClassVar[frozenset[int]] = frozenset({4})

    sensor_mask: int
    period_ms: int

    def __post_init__(self) -> None:
        _check_range("CONFIG sensor mask (bits 0..4)", self.sensor_mask, 0, KNOWN_SENSOR_MASK)
        _check_range("CONFIG period [ms]", self.period_ms, 0, 0xFFFF)

    def pack(self) -> bytes:
        """The 4-byte payload."""
        return self.STRUCT.pack(self.sensor_mask, self.period_ms)

    @classmethod
    def unpack(cls, payload: bytes) -> ConfigMsg:
        """Parse a 4-byte payload; PayloadError(CONFIG_MASK) for unknown block bits."""
        mask, period = cls.STRUCT.unpack(payload)
        if mask & ~KNOWN_SENSOR_MASK:
            raise PayloadError(RejectReason.CONFIG_MASK, f"CONFIG mask 0x{mask:04X}")
        return cls(mask, period)


# --- COMMAND -----------------------------------------------------------------

STICK_MIN: Final = -2048
STICK_MAX: Final = 2047
THRUST_MIN: Final = 0
THRUST_MAX: Final = 4096
CHECKSUM_SEED: Final = 0xAAAA


def command_checksum(pitch: int, roll: int, yaw: int, thrust: int, ctrl: int) -> int:
    """(pitch + roll + yaw + thrust + ctrl + 0xAAAA) mod 2^16, fields as int16 (spec 3.2)."""
    return (pitch + roll + yaw + thrust + ctrl + CHECKSUM_SEED) & 0xFFFF


@dataclass(frozen=True, slots=True)
class CommandMsg:
    """COMMAND (ground station -> X-3D, descriptor 0x11, N = 12). Fields in wire order.

    pitch, roll, yaw : -2048..2047 RC units, 0 = neutral; positive = positive body
        rate about FRD y, x, z (yaw is a yaw-rate command)
    thrust : 0..4096 RC units (collective)
    ctrl : channel mask, bit0 pitch, bit1 roll, bit2 yaw, bit3 thrust; a set bit puts
        the channel under ground-station control, 0 leaves everything to the pilot
    The checksum is computed by :meth:`pack`, never stored.
    """

    DESCRIPTOR: ClassVar[int] = DESCRIPTOR_COMMAND
    NAME: ClassVar[str] = "command"
    STRUCT: ClassVar[struct.Struct] = struct.Struct("<hhhhHH")
    PAYLOAD_SIZES: ClassVar[frozenset[int]] = frozenset({12})

    pitch: int = 0
    roll: int = 0
    yaw: int = 0
    thrust: int = 0
    ctrl: int = 0

    def __post_init__(self) -> None:
        _check_range("COMMAND pitch", self.pitch, STICK_MIN, STICK_MAX)
        _check_range("COMMAND roll", self.roll, STICK_MIN, STICK_MAX)
        _check_range("COMMAND yaw", self.yaw, STICK_MIN, STICK_MAX)
        _check_range("COMMAND thrust", self.thrust, THRUST_MIN, THRUST_MAX)
        _check_range("COMMAND ctrl mask (bits 0..3)", self.ctrl, 0, ALL_CHANNELS_MASK)

    @property
    def checksum(self) -> int:
        """The additive checksum sent in the last two payload bytes."""
        return command_checksum(self.pitch, self.roll, self.yaw, self.thrust, self.ctrl)

    def pack(self) -> bytes:
        """The 12-byte payload: pitch, roll, yaw, thrust, ctrl, checksum."""
        return self.STRUCT.pack(
            self.pitch, self.roll, self.yaw, self.thrust, self.ctrl, self.checksum
        )

    @classmethod
    def unpack(cls, payload: bytes) -> CommandMsg:
        """Parse a 12-byte payload; PayloadError(COMMAND_CHECKSUM or COMMAND_RANGE)."""
        pitch, roll, yaw, thrust, ctrl, checksum = cls.STRUCT.unpack(payload)
        if checksum != command_checksum(pitch, roll, yaw, thrust, ctrl):
            raise PayloadError(RejectReason.COMMAND_CHECKSUM, f"COMMAND checksum 0x{checksum:04X}")
        try:
            return cls(pitch, roll, yaw, thrust, ctrl)
        except ProtocolError as exc:
            raise PayloadError(RejectReason.COMMAND_RANGE, str(exc)) from None

    @classmethod
    def release(cls) -> CommandMsg:
        """The hand-back command: ctrl mask 0 (every channel to the pilot), neutral values."""
        return cls(0, 0, 0, 0, 0)


# --- DATA --------------------------------------------------------------------

_DATA_HEADER: Final = struct.Struct("<HH")
_STATUS = StatusBlock.STRUCT
_AXES = AxisCounts.STRUCT
_RC = RcBlock.STRUCT


@dataclass(frozen=True, slots=True)
class DataMsg:
    """DATA (X-3D -> ground station, descriptor 0x01): one sensor sample.

    counter : sample counter, uint16, +1 per sample, wraps at 65536
    status, gyro, acc, pressure, rc : the blocks present (None = not in the mask);
        ``pressure`` is the int32 raw reading. The block mask is derived from which
        blocks are present (:attr:`mask`), so it cannot disagree with the payload.
    Out-of-range field values are caught by :meth:`pack` (ProtocolError).
    """

    DESCRIPTOR: ClassVar[int] = DESCRIPTOR_DATA
    NAME: ClassVar[str] = "data"
    PAYLOAD_SIZES: ClassVar[frozenset[int]] = DATA_PAYLOAD_SIZES

    counter: int
    status: StatusBlock | None = None
    gyro: AxisCounts | None = None
    acc: AxisCounts | None = None
    pressure: int | None = None
    rc: RcBlock | None = None

    @property
    def mask(self) -> int:
        """Block mask of the blocks present (bit order as blocks.SENSOR_BLOCKS)."""
        return (
            (self.status is not None)
            | (self.gyro is not None) << 1
            | (self.acc is not None) << 2
            | (self.pressure is not None) << 3
            | (self.rc is not None) << 4
        )

    def pack(self) -> bytes:
        """Header and the present blocks in bit order."""
        try:
            parts = [_DATA_HEADER.pack(self.counter, self.mask)]
            if (s := self.status) is not None:
                parts.append(_STATUS.pack(s.battery_mv, s.flags, s.ctrl_mask))
            for axes in (self.gyro, self.acc):
                if axes is not None:
                    parts.append(_AXES.pack(axes.x, axes.y, axes.z))
            if self.pressure is not None:
                parts.append(PRESSURE_STRUCT.pack(self.pressure))
            if (r := self.rc) is not None:
                parts.append(_RC.pack(r.pitch, r.roll, r.yaw, r.thrust, r.switch))
        except struct.error as exc:
            raise ProtocolError(f"DATA field out of range: {exc}") from exc
        return b"".join(parts)

    @classmethod
    def unpack(cls, payload: bytes) -> DataMsg:
        """Parse a DATA payload; PayloadError(DATA_MASK) if the mask is unknown or
        disagrees with the payload length (hot path: one check, one unpack per block)."""
        counter, mask = _DATA_HEADER.unpack_from(payload, 0)
        if mask > KNOWN_SENSOR_MASK or DATA_SIZE_BY_MASK[mask] != len(payload):
            raise PayloadError(RejectReason.DATA_MASK, f"DATA mask 0x{mask:04X}, N={len(payload)}")
        off = 4
        status: StatusBlock | None = None
        gyro: AxisCounts | None = None
        acc: AxisCounts | None = None
        pressure: int | None = None
        rc: RcBlock | None = None
        if mask & 0x01:
            status = StatusBlock(*_STATUS.unpack_from(payload, off))
            off += 4
        if mask & 0x02:
            gyro = AxisCounts(*_AXES.unpack_from(payload, off))
            off += 6
        if mask & 0x04:
            acc = AxisCounts(*_AXES.unpack_from(payload, off))
            off += 6
        if mask & 0x08:
            (pressure,) = PRESSURE_STRUCT.unpack_from(payload, off)
            off += 4
        if mask & 0x10:
            rc = RcBlock(*_RC.unpack_from(payload, off))
        return cls(counter, status, gyro, acc, pressure, rc)


# --- registry ----------------------------------------------------------------

Message = ConfigMsg | CommandMsg | DataMsg
"""Any decodable X-3D message."""

MessageType = type[ConfigMsg] | type[CommandMsg] | type[DataMsg]


def build_registry(*classes: MessageType) -> Mapping[int, MessageType]:
    """Descriptor -> class map; raises ProtocolError if two classes share a descriptor."""
    registry: dict[int, MessageType] = {}
    for cls in classes:
        if cls.DESCRIPTOR in registry:
            other = registry[cls.DESCRIPTOR].__name__
            raise ProtocolError(
                f"descriptor 0x{cls.DESCRIPTOR:02X} used by both {other} and {cls.__name__}"
            )
        registry[cls.DESCRIPTOR] = cls
    return MappingProxyType(registry)


MESSAGE_TYPES: Final[Mapping[int, MessageType]] = build_registry(ConfigMsg, CommandMsg, DataMsg)
"""The one descriptor -> message class registry (spec section 3)."""

MAX_PAYLOAD_SIZE: Final = max(max(cls.PAYLOAD_SIZES) for cls in MESSAGE_TYPES.values())
"""Largest valid payload of any descriptor (34, a DATA frame with every block)."""
