"""CRC16 of the X-3D serial frames (spec section 2, "CRC16").

Reflected CCITT: polynomial 0x1021 processed LSB-first (0x8408), no final XOR,
computed over the frame payload only and sent low byte first. The initial value
is the only parameter that differs between the profiles:

=========  =======  ==========================================
profile    init     check value of ASCII ``123456789``
=========  =======  ==========================================
asctec     0x00FF   0x9DB8 (the project default, AscTec LL)
kermit     0x0000   0x2189
mcrf4xx    0xFFFF   0x6F91
=========  =======  ==========================================

Three implementations compute the same function (cross-checked in the tests):

* :func:`crc16_reference`: bit by bit, the readable definition;
* :func:`crc16_table`: one 256-entry table lookup per byte, pure Python;
* :func:`crc16`: the fast path used by the decoder. A reflected CRC is the
  mirror image of the non-reflected one, so it runs the C-coded
  ``binascii.crc_hqx`` (CCITT, MSB-first, table driven) on bit-reversed bytes
  with a bit-reversed initial value and reverses the 16-bit result.
"""

from __future__ import annotations

import binascii
from collections.abc import Mapping
from types import MappingProxyType
from typing import Final

from groundstation.errors import ProtocolError

POLY_REFLECTED: Final = 0x8408
"""CCITT polynomial 0x1021 with its bits reversed (LSB-first processing)."""

CRC_PROFILES: Final[Mapping[str, int]] = MappingProxyType(
    {"asctec": 0x00FF, "kermit": 0x0000, "mcrf4xx": 0xFFFF}
)
"""Profile name -> initial register value."""

DEFAULT_PROFILE: Final = "asctec"

ASCTEC_INIT: Final = 0x00FF


def crc16_reference(data: bytes | bytearray | memoryview, init: int = ASCTEC_INIT) -> int:
    """Bit-by-bit reflected CRC16-CCITT of ``data`` (readable reference, slow).

    init : initial register value (0..0xFFFF), see :data:`CRC_PROFILES`.
    Returns the 16-bit CRC (no final XOR).
    """
    crc = init
    for byte in bytes(data):
        crc ^= byte
        for _ in range(8):
            crc = (crc >> 1) ^ POLY_REFLECTED if crc & 1 else crc >> 1
    return crc


_TABLE: Final[tuple[int, ...]] = tuple(crc16_reference(bytes((i,)), 0) for i in range(256))
"""CRC register after shifting one byte ``i`` through a zero register."""


def crc16_table(data: bytes | bytearray | memoryview, init: int = ASCTEC_INIT) -> int:
    """Table-driven reflected CRC16-CCITT, one lookup per byte (pure Python)."""
    crc = init
    table = _TABLE
    for byte in bytes(data):
        crc = (crc >> 8) ^ table[(crc ^ byte) & 0xFF]
    return crc


_REV8: Final[bytes] = bytes(int(f"{i:08b}"[::-1], 2) for i in range(256))
"""Byte ``i`` with its 8 bits in reverse order (a ``bytes.translate`` table)."""


def _reverse16(value: int) -> int:
    """Reverse the order of the 16 bits of ``value``."""
    return (_REV8[value & 0xFF] << 8) | _REV8[value >> 8]


def crc16(data: bytes | bytearray, init: int = ASCTEC_INIT) -> int:
    """Fast reflected CRC16-CCITT (C speed): same result as :func:`crc16_reference`.

    data : the frame payload.
    init : initial register value, see :data:`CRC_PROFILES`.
    """
    return _reverse16(binascii.crc_hqx(data.translate(_REV8), _reverse16(init)))


def profile_init(profile: str) -> int:
    """Initial CRC value of a named profile; raises ProtocolError for unknown names."""
    try:
        return CRC_PROFILES[profile]
    except KeyError:
        known = ", ".join(sorted(CRC_PROFILES))
        raise ProtocolError(f"unknown CRC profile {profile!r} (known: {known})") from None
