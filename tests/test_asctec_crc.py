"""CRC16 of the X-3D frames: spec check values and reference vs fast paths."""

from __future__ import annotations

from collections.abc import Callable

import pytest
from hypothesis import given
from hypothesis import strategies as st

from groundstation.asctec.crc import (
    CRC_PROFILES,
    crc16,
    crc16_reference,
    crc16_table,
    profile_init,
)
from groundstation.errors import ProtocolError

CrcFn = Callable[[bytes, int], int]
IMPLEMENTATIONS: list[CrcFn] = [crc16_reference, crc16_table, crc16]

# Spec section 2 "CRC16": check values, (profile, input, expected). The kermit and
# mcrf4xx values for "123456789" are also the catalogue values of CRC-16/KERMIT
# and CRC-16/MCRF4XX (reveng CRC catalogue).
SPEC_CHECK_VALUES = [
    ("asctec", b"", 0x00FF),
    ("asctec", b"\x00", 0x0F78),
    ("asctec", b"123456789", 0x9DB8),
    ("kermit", b"123456789", 0x2189),
    ("mcrf4xx", b"123456789", 0x6F91),
]


@pytest.mark.parametrize("fn", IMPLEMENTATIONS, ids=lambda f: f.__name__)
@pytest.mark.parametrize(("profile", "data", "expected"), SPEC_CHECK_VALUES)
def test_spec_check_values(fn: CrcFn, profile: str, data: bytes, expected: int) -> None:
    assert fn(data, profile_init(profile)) == expected


def test_profiles_are_the_spec_initial_values() -> None:
    # Spec section 2: asctec 0x00FF (default), kermit 0x0000, mcrf4xx 0xFFFF.
    assert dict(CRC_PROFILES) == {"asctec": 0x00FF, "kermit": 0x0000, "mcrf4xx": 0xFFFF}
    assert crc16(b"123456789") == 0x9DB8  # default profile is asctec


@pytest.mark.parametrize(
    ("payload_hex", "crc_bytes_hex"),
    [
        # Spec section 5 worked frames: payload and the CRC bytes sent (low byte first).
        ("07 00 0A 00", "83 6F"),
        ("9C FF FA 00 00 00 08 07 0F 00 57 B2", "B5 3C"),
        ("D2 04 07 00 18 2E 03 0F 00 08 02 08 FE 07 00 08 00 08 8B 04", "0C 9A"),
    ],
)
def test_worked_frame_crcs(payload_hex: str, crc_bytes_hex: str) -> None:
    payload = bytes.fromhex(payload_hex)
    expected = int.from_bytes(bytes.fromhex(crc_bytes_hex), "little")
    for fn in IMPLEMENTATIONS:
        assert fn(payload, 0x00FF) == expected


@pytest.mark.slow
@given(data=st.binary(max_size=300), init=st.integers(0, 0xFFFF))
def test_reference_table_and_fast_path_agree(data: bytes, init: int) -> None:
    expected = crc16_reference(data, init)
    assert crc16_table(data, init) == expected
    assert crc16(data, init) == expected


@given(data=st.binary(min_size=1, max_size=64), bit=st.integers(0, 7), index=st.integers())
def test_every_single_bit_error_changes_the_crc(data: bytes, bit: int, index: int) -> None:
    # A CRC with a polynomial having more than one term detects all single-bit errors.
    i = index % len(data)
    corrupted = bytearray(data)
    corrupted[i] ^= 1 << bit
    assert crc16(bytes(corrupted)) != crc16(data)


def test_crc_is_linear_in_the_register() -> None:
    # Independent property of a CRC without final XOR: appending the CRC (low byte
    # first, reflected algorithm) drives the register to zero.
    for data in (b"", b"\x00", b"123456789", bytes(range(256))):
        crc = crc16(data)
        assert crc16(data + crc.to_bytes(2, "little")) == 0


def test_unknown_profile_is_refused() -> None:
    with pytest.raises(ProtocolError, match="known: asctec"):
        profile_init("xmodem")
