"""Sensor blocks of the DATA message (spec section 3.3) and their mask arithmetic.

A DATA payload is a 4-byte header (sample counter, block mask) followed by one
block per set mask bit, in bit order. :data:`SENSOR_BLOCKS` is the single table
of block name, mask bit and size; the names and their order are
:data:`groundstation.types.SENSOR_BLOCK_NAMES` (the configuration names blocks by
them) and :func:`sensor_mask` turns the names into the mask sent in CONFIG.

Raw values stay in wire units here (ADC counts, mV, RC units); scaling to SI is
the model's job (``model/`` sensor scaling).
"""

from __future__ import annotations

import struct
from collections.abc import Iterable
from dataclasses import dataclass
from typing import ClassVar, Final

from groundstation.errors import ProtocolError
from groundstation.types import SENSOR_BLOCK_NAMES, SensorBlockName, Sticks


@dataclass(frozen=True, slots=True)
class SensorBlock:
    """One row of the DATA block table: ``name``, mask ``bit`` (0..4), ``size`` [bytes]."""

    name: SensorBlockName
    bit: int
    size: int

    @property
    def mask(self) -> int:
        """The block's mask value, ``1 << bit``."""
        return 1 << self.bit


_BLOCK_SIZES: Final = (4, 6, 6, 4, 10)
"""Bytes of status, gyro, acc, pressure and rc (spec section 3.3), in bit order."""

SENSOR_BLOCKS: Final[tuple[SensorBlock, ...]] = tuple(
    SensorBlock(name, bit, size)
    for bit, (name, size) in enumerate(zip(SENSOR_BLOCK_NAMES, _BLOCK_SIZES, strict=True)))
"""The DATA blocks in wire (bit) order, spec section 3.3."""

BLOCKS_BY_NAME: Final[dict[str, SensorBlock]] = {b.name: b for b in SENSOR_BLOCKS}

KNOWN_SENSOR_MASK: Final = sum(b.mask for b in SENSOR_BLOCKS)
"""All defined block bits (0x001F); any other bit set makes a mask invalid."""

DATA_HEADER_SIZE: Final = 4


def sensor_mask(names: Iterable[str]) -> int:
    """Mask selecting the named blocks, e.g. ``sensor_mask(["status", "gyro", "acc"]) == 0x7``.

    Raises ProtocolError naming any unknown block.
    """
    mask = 0
    for name in names:
        block = BLOCKS_BY_NAME.get(name)
        if block is None:
            known = ", ".join(BLOCKS_BY_NAME)
            raise ProtocolError(f"unknown sensor block {name!r} (known: {known})")
        mask |= block.mask
    return mask


def block_names(mask: int) -> tuple[str, ...]:
    """Names of the blocks selected by ``mask``, in wire order (unknown bits ignored)."""
    return tuple(b.name for b in SENSOR_BLOCKS if mask & b.mask)


def data_payload_size(mask: int) -> int:
    """DATA payload length N [bytes] for a block mask: 4 + sum of selected block sizes.

    Raises ProtocolError if ``mask`` has bits outside :data:`KNOWN_SENSOR_MASK`.
    """
    if mask & ~KNOWN_SENSOR_MASK or mask < 0:
        raise ProtocolError(f"sensor mask 0x{mask:04X} has unknown bits")
    return DATA_HEADER_SIZE + sum(b.size for b in SENSOR_BLOCKS if mask & b.mask)


DATA_SIZE_BY_MASK: Final[tuple[int, ...]] = tuple(
    data_payload_size(m) for m in range(KNOWN_SENSOR_MASK + 1)
)
"""``DATA_SIZE_BY_MASK[mask]`` is the payload size for every valid mask."""

DATA_PAYLOAD_SIZES: Final[frozenset[int]] = frozenset(DATA_SIZE_BY_MASK)
"""Every payload length a valid DATA frame can have (4..34)."""


@dataclass(frozen=True, slots=True)
class StatusBlock:
    """STATUS block (bit 0, 4 bytes).

    battery_mv : battery voltage [mV] (uint16)
    flags : bit0 serial control active, bit1 motors on, bit2 RC link valid (uint8)
    ctrl_mask : channel mask the vehicle currently applies (uint8, bits as COMMAND)
    """

    STRUCT: ClassVar[struct.Struct] = struct.Struct("<HBB")

    battery_mv: int
    flags: int
    ctrl_mask: int

    @property
    def serial_active(self) -> bool:
        """The X-3D is applying ground-station commands (flag bit 0)."""
        return bool(self.flags & 0x01)

    @property
    def motors_on(self) -> bool:
        """Motors are running (flag bit 1)."""
        return bool(self.flags & 0x02)

    @property
    def rc_valid(self) -> bool:
        """The RC transmitter link is valid (flag bit 2)."""
        return bool(self.flags & 0x04)


@dataclass(frozen=True, slots=True)
class AxisCounts:
    """GYRO or ACC block (bits 1 and 2, 6 bytes): raw 12-bit ADC counts on body axes.

    x, y, z : uint16 counts on the FRD body axes (zero near 2048 by default).
    """

    STRUCT: ClassVar[struct.Struct] = struct.Struct("<HHH")

    x: int
    y: int
    z: int


PRESSURE_STRUCT: Final = struct.Struct("<i")
"""PRESSURE block (bit 3, 4 bytes): one int32 raw reading, carried as a plain int."""


@dataclass(frozen=True, slots=True)
class RcBlock:
    """RC block (bit 4, 10 bytes): the pilot's sticks in wire order and the serial switch.

    pitch, roll, yaw : int16, -2048..2047 (command ranges)
    thrust : int16, 0..4096
    switch : uint16 serial-enable switch; > 2048 means enabled
    """

    STRUCT: ClassVar[struct.Struct] = struct.Struct("<hhhhH")

    pitch: int
    roll: int
    yaw: int
    thrust: int
    switch: int

    @property
    def serial_enabled(self) -> bool:
        """The pilot's serial-enable switch is on (value > 2048)."""
        return self.switch > 2048

    def sticks(self) -> Sticks:
        """The pilot's sticks as :class:`~groundstation.types.Sticks` (thesis meaning)."""
        return Sticks(roll=self.roll, pitch=self.pitch, yaw=self.yaw, thrust=self.thrust)
