"""Sans-IO codec for the Vicon Tracker UDP object stream (``docs/vicon-udp.md``).

One UDP datagram carries one Tracker frame::

    uint32 frame number | uint8 item count | item 0 | item 1 | ... | padding

    item: uint8 id | uint16 size (bytes after this field) | payload[size]
    object item (id 0, size 72): char[24] name (NUL-padded) |
        float64 x, y, z [mm] | float64 rx, ry, rz [rad]   (all little-endian)

:func:`decode_datagram` walks items by their size field, skips items it does not
understand (another id, or an object item whose size is not 72), ignores the
trailing padding and never infers anything from the datagram length. A datagram
shorter than its header, or whose items run past its end, is rejected whole and
returned as a :class:`BadDatagram` with its reason; nothing in this module raises on
bad input. :class:`DatagramDecoder` wraps it with per-reason counters.
:func:`encode_datagram` is the inverse (the virtual Vicon sends with it).

No socket, clock or thread here: the client feeds bytes in.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Final

from groundstation.errors import ProtocolError

HEADER: Final = struct.Struct("<IB")
"""Datagram header: frame number (uint32), item count (uint8)."""
ITEM_HEADER: Final = struct.Struct("<BH")
"""Item header: item id (uint8), data size in bytes after this field (uint16)."""
OBJECT_DATA: Final = struct.Struct("<24s6d")
"""Object item data: name, translation x, y, z [mm], rotation x, y, z [rad]."""

OBJECT_ITEM_ID: Final = 0
OBJECT_DATA_SIZE: Final = OBJECT_DATA.size  # 72
OBJECT_ITEM_SIZE: Final = ITEM_HEADER.size + OBJECT_DATA_SIZE  # 75
NAME_FIELD_SIZE: Final = 24
MAX_NAME_BYTES: Final = NAME_FIELD_SIZE - 1  # at least one NUL terminator
MAX_ITEMS: Final = 255
DEFAULT_BLOCK_SIZE: Final = 1024

# Rejection reasons (BadDatagram.reason); the decoder counts each separately.
SHORT_HEADER: Final = "short_header"
"""Fewer than 5 bytes: no frame number and item count."""
ITEM_HEADER_TRUNCATED: Final = "item_header_truncated"
"""The header announces more items than the datagram holds item headers for."""
ITEM_DATA_TRUNCATED: Final = "item_data_truncated"
"""An item's size field runs past the end of the datagram."""
REJECT_REASONS: Final = (SHORT_HEADER, ITEM_HEADER_TRUNCATED, ITEM_DATA_TRUNCATED)


@dataclass(frozen=True, slots=True)
class ObjectPose:
    """One object item, in Vicon's own units and frames (no conversion).

    name : object name as defined in Tracker (bytes up to the first NUL, UTF-8,
        undecodable bytes replaced)
    translation : (x, y, z) of the object origin in the Vicon world frame [mm]
    rotation : (rx, ry, rz) Euler angles, intrinsic X then Y then Z [rad]:
        R_obj_in_vicon = Rx(rx) @ Ry(ry) @ Rz(rz)
    """

    name: str
    translation: tuple[float, float, float]
    rotation: tuple[float, float, float]


@dataclass(frozen=True, slots=True)
class ViconFrame:
    """A decoded datagram.

    frame : Tracker frame number (uint32)
    objects : the object items in datagram order (may be empty)
    skipped_items : items skipped by their size field (unknown id or an object
        item whose size is not 72)
    """

    frame: int
    objects: tuple[ObjectPose, ...]
    skipped_items: int = 0

    def find(self, name: str) -> ObjectPose | None:
        """Return the first object called ``name``, or None if it is not in the frame."""
        for obj in self.objects:
            if obj.name == name:
                return obj
        return None


@dataclass(frozen=True, slots=True)
class BadDatagram:
    """A datagram rejected whole.

    reason : one of :data:`REJECT_REASONS`
    length : datagram length [bytes]
    frame : the frame number if the header could be read, else None
    """

    reason: str
    length: int
    frame: int | None = None


def decode_datagram(data: bytes | bytearray | memoryview) -> ViconFrame | BadDatagram:
    """Decode one datagram; never raises on malformed input.

    Items are walked by their size field; trailing bytes after the last
    announced item are padding and ignored.
    """
    length = len(data)
    if length < HEADER.size:
        return BadDatagram(SHORT_HEADER, length)
    frame, count = HEADER.unpack_from(data, 0)
    offset = HEADER.size
    objects: list[ObjectPose] = []
    skipped = 0
    for _ in range(count):
        if offset + ITEM_HEADER.size > length:
            return BadDatagram(ITEM_HEADER_TRUNCATED, length, frame)
        item_id, size = ITEM_HEADER.unpack_from(data, offset)
        start = offset + ITEM_HEADER.size
        offset = start + size
        if offset > length:
            return BadDatagram(ITEM_DATA_TRUNCATED, length, frame)
        if item_id != OBJECT_ITEM_ID or size != OBJECT_DATA_SIZE:
            skipped += 1
            continue
        raw_name, x, y, z, rx, ry, rz = OBJECT_DATA.unpack_from(data, start)
        name = raw_name.split(b"\0", 1)[0].decode("utf-8", "replace")
        objects.append(ObjectPose(name, (x, y, z), (rx, ry, rz)))
    return ViconFrame(frame, tuple(objects), skipped)


class DatagramDecoder:
    """:func:`decode_datagram` plus counters for telemetry.

    Attributes
    ----------
    datagrams : datagrams fed in
    rejected : per-reason count of rejected datagrams (keys :data:`REJECT_REASONS`)
    skipped_items : items skipped in accepted datagrams
    """

    __slots__ = ("datagrams", "rejected", "skipped_items")

    def __init__(self) -> None:
        self.datagrams = 0
        self.rejected: dict[str, int] = dict.fromkeys(REJECT_REASONS, 0)
        self.skipped_items = 0

    def decode(self, data: bytes | bytearray | memoryview) -> ViconFrame | BadDatagram:
        """Decode one datagram and update the counters; never raises on bad input."""
        self.datagrams += 1
        result = decode_datagram(data)
        if isinstance(result, BadDatagram):
            self.rejected[result.reason] += 1
        else:
            self.skipped_items += result.skipped_items
        return result


def encode_datagram(
    frame: int, objects: Sequence[ObjectPose], pad_to: int | None = DEFAULT_BLOCK_SIZE
) -> bytes:
    """Encode one datagram in exactly the spec's layout (inverse of :func:`decode_datagram`).

    frame : Tracker frame number, 0 <= frame < 2**32
    objects : object items in order; names at most 23 UTF-8 bytes, no NUL
    pad_to : pad with NUL bytes to this length (Tracker's "data block size"),
        or None for no padding

    Raises ProtocolError if a field does not fit the wire format or the items
    do not fit in ``pad_to`` bytes.
    """
    if not 0 <= frame <= 0xFFFF_FFFF:
        raise ProtocolError(f"frame number {frame} does not fit uint32")
    if len(objects) > MAX_ITEMS:
        raise ProtocolError(f"{len(objects)} objects; at most {MAX_ITEMS} fit one datagram")
    parts = [HEADER.pack(frame, len(objects))]
    for obj in objects:
        raw_name = obj.name.encode("utf-8")
        if len(raw_name) > MAX_NAME_BYTES or b"\0" in raw_name:
            raise ProtocolError(f"object name {obj.name!r}: at most {MAX_NAME_BYTES} bytes, no NUL")
        parts.append(ITEM_HEADER.pack(OBJECT_ITEM_ID, OBJECT_DATA_SIZE))
        parts.append(OBJECT_DATA.pack(raw_name, *obj.translation, *obj.rotation))
    body = b"".join(parts)
    if pad_to is None:
        return body
    if len(body) > pad_to:
        raise ProtocolError(f"{len(body)} bytes of items do not fit a {pad_to}-byte block")
    return body.ljust(pad_to, b"\0")
