"""Vicon datagram codec against hand-built datagrams (spec/vicon-udp.md byte tables).

Expected datagrams are built here with struct.pack straight from the spec's
tables, independently of groundstation.vicon.decoder's own Struct constants.
"""

from __future__ import annotations

import struct

import pytest
from hypothesis import given
from hypothesis import strategies as st

from groundstation.errors import ProtocolError
from groundstation.vicon.decoder import (
    ITEM_DATA_TRUNCATED,
    ITEM_HEADER_TRUNCATED,
    SHORT_HEADER,
    BadDatagram,
    DatagramDecoder,
    ObjectPose,
    ViconFrame,
    decode_datagram,
    encode_datagram,
)


def header(frame: int, count: int) -> bytes:
    """Spec: uint32 frame number, uint8 item count, little-endian."""
    return struct.pack("<I", frame) + struct.pack("<B", count)


def object_item(name: bytes, t: tuple[float, ...], r: tuple[float, ...]) -> bytes:
    """Spec: uint8 id 0, uint16 size 72, char[24] NUL-padded name, 6 x float64."""
    return (
        struct.pack("<B", 0)
        + struct.pack("<H", 72)
        + name + b"\0" * (24 - len(name))
        + b"".join(struct.pack("<d", v) for v in (*t, *r))
    )  # fmt: skip


QUAD = object_item(b"quad", (1.5, -2.25, 1000.0), (0.1, -0.2, 3.0))


def test_one_object() -> None:
    data = header(4242, 1) + QUAD
    assert len(data) == 5 + 75  # spec: an object item is 75 bytes
    result = decode_datagram(data)
    assert result == ViconFrame(4242, (ObjectPose("quad", (1.5, -2.25, 1000.0), (0.1, -0.2, 3.0)),))


def test_several_objects_in_order_and_find_by_name() -> None:
    wand = object_item(b"wand", (1.0, 2.0, 3.0), (0.0, 0.5, 0.0))
    box = object_item(b"box", (-4.0, 5.0, -6.0), (0.3, 0.0, -0.3))
    result = decode_datagram(header(7, 3) + wand + QUAD + box)
    assert isinstance(result, ViconFrame)
    assert [o.name for o in result.objects] == ["wand", "quad", "box"]
    found = result.find("box")
    assert found is not None
    assert found.translation == (-4.0, 5.0, -6.0)
    assert found.rotation == (0.3, 0.0, -0.3)
    assert result.find("absent") is None


@pytest.mark.parametrize("fill", [b"\0", b"\xa5"])
def test_padding_to_block_size_is_ignored(fill: bytes) -> None:
    body = header(1, 1) + QUAD
    padded = body + fill * (1024 - len(body))
    assert len(padded) == 1024
    assert decode_datagram(padded) == decode_datagram(body)


def test_unknown_item_and_wrong_object_size_are_skipped_by_size() -> None:
    unknown = struct.pack("<BH", 5, 10) + bytes(range(10))
    # id 0 but size 80: an object item of some other layout, skipped whole
    odd_object = struct.pack("<BH", 0, 80) + b"quad".ljust(24, b"\0") + bytes(56)
    empty_unknown = struct.pack("<BH", 9, 0)
    data = header(3, 4) + unknown + odd_object + empty_unknown + QUAD
    decoder = DatagramDecoder()
    result = decoder.decode(data)
    assert isinstance(result, ViconFrame)
    assert [o.name for o in result.objects] == ["quad"]
    assert result.objects[0].translation == (1.5, -2.25, 1000.0)
    assert result.skipped_items == 3
    assert decoder.skipped_items == 3


def test_23_character_name_and_bytes_after_first_nul() -> None:
    name = b"abcdefghijklmnopqrstuvw"
    assert len(name) == 23
    result = decode_datagram(header(1, 1) + object_item(name, (0, 0, 0), (0, 0, 0)))
    assert isinstance(result, ViconFrame)
    assert result.objects[0].name == name.decode()
    # Only bytes up to the first NUL are the name.
    garbage = object_item(b"ab\0cdef", (0, 0, 0), (0, 0, 0))
    result = decode_datagram(header(1, 1) + garbage)
    assert isinstance(result, ViconFrame)
    assert result.objects[0].name == "ab"
    # 24 non-NUL bytes (no terminator) still decode, never raise.
    full = decode_datagram(header(1, 1) + object_item(b"x" * 24, (0, 0, 0), (0, 0, 0)))
    assert isinstance(full, ViconFrame)
    assert full.objects[0].name == "x" * 24


def test_zero_items() -> None:
    assert decode_datagram(header(9, 0) + bytes(100)) == ViconFrame(9, ())


@pytest.mark.parametrize(
    ("data", "reason"),
    [
        (b"", SHORT_HEADER),
        (header(1, 1)[:4], SHORT_HEADER),
        (header(1, 1), ITEM_HEADER_TRUNCATED),  # announces an item, holds none
        (header(1, 2) + QUAD + b"\0\x48", ITEM_HEADER_TRUNCATED),  # 2 of 3 header bytes
        (header(1, 1) + QUAD[:-1], ITEM_DATA_TRUNCATED),  # last float cut by a byte
        (header(1, 2) + QUAD + QUAD[:40], ITEM_DATA_TRUNCATED),  # second item cut
        (header(1, 1) + struct.pack("<BH", 7, 500) + bytes(100), ITEM_DATA_TRUNCATED),
    ],
)
def test_truncated_datagrams_are_rejected_whole_and_counted(data: bytes, reason: str) -> None:
    decoder = DatagramDecoder()
    result = decoder.decode(data)
    assert isinstance(result, BadDatagram)
    assert result.reason == reason
    assert result.length == len(data)
    assert result.frame == (None if reason == SHORT_HEADER else 1)
    assert decoder.rejected[reason] == 1
    assert sum(decoder.rejected.values()) == 1
    assert decoder.datagrams == 1


@given(st.binary(max_size=2048))
def test_arbitrary_bytes_never_raise(data: bytes) -> None:
    result = decode_datagram(data)
    assert isinstance(result, ViconFrame | BadDatagram)


@given(st.integers(0, 255), st.lists(st.binary(max_size=120), max_size=8), st.binary(max_size=64))
def test_random_items_never_raise(count: int, items: list[bytes], tail: bytes) -> None:
    data = header(5, count) + b"".join(items) + tail
    result = decode_datagram(data)
    assert isinstance(result, ViconFrame | BadDatagram)


# --- encoder ------------------------------------------------------------------

finite = st.floats(allow_nan=False, allow_infinity=True, width=64)
names = st.text(
    alphabet=st.characters(codec="utf-8", exclude_characters="\0"),
    max_size=23,
).filter(lambda s: len(s.encode()) <= 23)
objects = st.builds(
    ObjectPose, names, st.tuples(finite, finite, finite), st.tuples(finite, finite, finite)
)


def test_encoder_matches_hand_built_bytes() -> None:
    obj = ObjectPose("quad", (1.5, -2.25, 1000.0), (0.1, -0.2, 3.0))
    body = header(4242, 1) + QUAD
    assert encode_datagram(4242, [obj], pad_to=None) == body
    assert encode_datagram(4242, [obj]) == body + bytes(1024 - len(body))


@pytest.mark.slow
@given(st.integers(0, 2**32 - 1), st.lists(objects, max_size=13))
def test_round_trip(frame: int, objs: list[ObjectPose]) -> None:
    # 13 objects: 5 + 13 * 75 = 980 bytes, the most that fit a 1024-byte block.
    data = encode_datagram(frame, objs)
    assert len(data) == 1024
    assert decode_datagram(data) == ViconFrame(frame, tuple(objs))
    assert decode_datagram(encode_datagram(frame, objs, pad_to=None)) == ViconFrame(
        frame, tuple(objs)
    )


@pytest.mark.slow
@given(st.lists(objects, min_size=1, max_size=4), st.data())
def test_every_cut_inside_the_items_is_rejected(
    objs: list[ObjectPose], data: st.DataObject
) -> None:
    full = encode_datagram(11, objs, pad_to=None)
    cut = data.draw(st.integers(0, len(full) - 1))
    assert isinstance(decode_datagram(full[:cut]), BadDatagram)


@pytest.mark.parametrize(
    ("frame", "objs", "pad_to"),
    [
        (-1, [], 1024),
        (2**32, [], 1024),
        (0, [ObjectPose("x" * 24, (0, 0, 0), (0, 0, 0))], 1024),
        (0, [ObjectPose("a\0b", (0, 0, 0), (0, 0, 0))], 1024),
        (0, [ObjectPose("é" * 12, (0, 0, 0), (0, 0, 0))], 1024),  # 24 UTF-8 bytes
        (0, [ObjectPose("q", (0, 0, 0), (0, 0, 0))] * 14, 1024),  # 1055 bytes
        (0, [ObjectPose("q", (0, 0, 0), (0, 0, 0))] * 256, None),
    ],
)
def test_encoder_refuses_what_the_wire_cannot_carry(
    frame: int, objs: list[ObjectPose], pad_to: int | None
) -> None:
    with pytest.raises(ProtocolError):
        encode_datagram(frame, objs, pad_to)
