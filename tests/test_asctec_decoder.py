"""Sans-IO stream decoder and frame encoder (spec sections 2 and 5)."""

from __future__ import annotations

import itertools
import random
import struct

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from test_asctec_messages import messages

from groundstation.asctec.blocks import AxisCounts, StatusBlock
from groundstation.asctec.crc import crc16
from groundstation.asctec.decoder import (
    MAX_FRAME_SIZE,
    START_MARKER,
    RejectedFrame,
    StreamDecoder,
    encode_frame,
)
from groundstation.asctec.messages import (
    CommandMsg,
    ConfigMsg,
    DataMsg,
    Message,
    RejectReason,
)

# Spec section 5, profile asctec: (message, frame bytes).
WORKED_FRAMES: list[tuple[Message, str]] = [
    (ConfigMsg(sensor_mask=0x0007, period_ms=10), "3E 2A 3E 04 00 10 07 00 0A 00 83 6F 3C 23 3C"),
    (
        CommandMsg(pitch=-100, roll=250, yaw=0, thrust=1800, ctrl=0x0F),
        "3E 2A 3E 0C 00 11 9C FF FA 00 00 00 08 07 0F 00 57 B2 B5 3C 3C 23 3C",
    ),
    (
        DataMsg(
            1234,
            status=StatusBlock(battery_mv=11800, flags=0b011, ctrl_mask=0x0F),
            gyro=AxisCounts(2048, 2050, 2046),
            acc=AxisCounts(2048, 2048, 1163),
        ),
        "3E 2A 3E 14 00 01 D2 04 07 00 18 2E 03 0F 00 08 02 08 FE 07 00"
        " 08 00 08 8B 04 0C 9A 3C 23 3C",
    ),
]
WORKED_IDS = ["config", "command", "data"]

# Enough marker-free bytes to resolve every pending candidate (see decoder docstring).
FLUSH = b"\x00" * MAX_FRAME_SIZE


def decoded(items: list[Message | RejectedFrame]) -> list[Message]:
    """The accepted messages among decoder output."""
    return [m for m in items if not isinstance(m, RejectedFrame)]


def raw_frame(descriptor: int, payload: bytes, length: int | None = None) -> bytes:
    """A hand-built frame with a correct CRC (to reach the checks behind the CRC)."""
    n = len(payload) if length is None else length
    crc = crc16(payload)
    return (
        START_MARKER + struct.pack("<HB", n, descriptor) + payload + struct.pack("<H", crc) + b"<#<"
    )


@pytest.mark.parametrize(("msg", "frame_hex"), WORKED_FRAMES, ids=WORKED_IDS)
def test_worked_frame_encodes_byte_for_byte(msg: Message, frame_hex: str) -> None:
    assert encode_frame(msg) == bytes.fromhex(frame_hex)


@pytest.mark.parametrize(("msg", "frame_hex"), WORKED_FRAMES, ids=WORKED_IDS)
def test_worked_frame_decodes_whole_and_byte_by_byte(msg: Message, frame_hex: str) -> None:
    frame = bytes.fromhex(frame_hex)
    assert StreamDecoder().feed(frame) == [msg]
    decoder = StreamDecoder()
    out: list[Message | RejectedFrame] = []
    for i in range(len(frame)):
        out += decoder.feed(frame[i : i + 1])
        assert out == ([] if i < len(frame) - 1 else [msg])  # complete only at the last byte
    counts = decoder.counts()
    assert counts.frames[msg.NAME] == 1
    assert counts.rejected_total == 0
    assert counts.bytes_skipped == 0


def test_profiles_must_match() -> None:
    msg = ConfigMsg(0x7, 10)
    assert StreamDecoder("kermit").feed(encode_frame(msg, "kermit")) == [msg]
    assert StreamDecoder("mcrf4xx").feed(encode_frame(msg, "mcrf4xx")) == [msg]
    (item,) = StreamDecoder("asctec").feed(encode_frame(msg, "kermit"))
    assert isinstance(item, RejectedFrame)
    assert item.reason is RejectReason.BAD_CRC


def _bad_frames() -> list[tuple[RejectReason, bytes]]:
    good = encode_frame(CommandMsg(1, 2, 3, 4, 0xF))
    data_payload = DataMsg(5, gyro=AxisCounts(1, 2, 3)).pack()
    bad_sum = CommandMsg(1, 2, 3, 4, 0xF).pack()[:10] + b"\x00\x00"
    thrust_5000 = struct.pack("<hhhhHH", 0, 0, 0, 5000, 0, (5000 + 0xAAAA) & 0xFFFF)
    return [
        (RejectReason.BAD_LENGTH, raw_frame(0x10, b"\x07\x00\x0a\x00\x00")),  # CONFIG N=5
        (RejectReason.BAD_CRC, good[:8] + bytes([good[8] ^ 0x40]) + good[9:]),
        (RejectReason.BAD_END, good[:-1] + b"!"),
        (RejectReason.UNKNOWN_DESCRIPTOR, raw_frame(0x42, b"\x00\x00\x00\x00")),
        # DATA N=10 is a valid size (gyro only) but the mask says status+gyro (N=14).
        (
            RejectReason.DATA_MASK,
            raw_frame(0x01, data_payload[:2] + b"\x03\x00" + data_payload[4:]),
        ),
        (
            RejectReason.DATA_MASK,
            raw_frame(0x01, data_payload[:2] + b"\x42\x00" + data_payload[4:]),
        ),
        (RejectReason.COMMAND_RANGE, raw_frame(0x11, thrust_5000)),
        (RejectReason.COMMAND_CHECKSUM, raw_frame(0x11, bad_sum)),
        (RejectReason.CONFIG_MASK, raw_frame(0x10, b"\x20\x00\x0a\x00")),
    ]


@pytest.mark.parametrize(("reason", "frame"), _bad_frames(), ids=lambda x: getattr(x, "value", ""))
def test_each_rejection_reason_is_counted_and_the_next_frame_survives(
    reason: RejectReason, frame: bytes
) -> None:
    follower = ConfigMsg(0x1F, 20)
    decoder = StreamDecoder()
    out = decoder.feed(frame + encode_frame(follower))
    rejected = [r for r in out if isinstance(r, RejectedFrame)]
    assert [r.reason for r in rejected] == [reason]
    assert rejected[0].raw.startswith(START_MARKER)
    assert decoded(out) == [follower]
    counts = decoder.counts()
    assert counts.rejections[reason.value] == 1
    assert counts.rejected_total == 1
    assert counts.frames == {"config": 1, "command": 0, "data": 0}


def test_huge_length_is_rejected_without_waiting() -> None:
    decoder = StreamDecoder()
    # DATA with N = 65535: no valid DATA payload is longer than 34 bytes.
    out = decoder.feed(START_MARKER + b"\xff\xff\x01")
    assert [r.reason for r in out if isinstance(r, RejectedFrame)] == [RejectReason.BAD_LENGTH]
    assert decoder.buffered < MAX_FRAME_SIZE
    # N = 35, one past the largest valid payload, likewise.
    out = decoder.feed(START_MARKER + b"\x23\x00\x01")
    assert [r.reason for r in out if isinstance(r, RejectedFrame)] == [RejectReason.BAD_LENGTH]


def test_frame_starting_inside_a_rejected_candidate_is_found() -> None:
    # A false marker with a plausible COMMAND header, then a real frame 2 bytes later:
    # the false candidate spans the real frame, is rejected, and scanning resumes
    # inside it.
    msg = CommandMsg(-100, 250, 0, 1800, 0x0F)
    stream = START_MARKER + b"\x0c\x00\x11" + b"ab" + encode_frame(msg) + FLUSH
    out = StreamDecoder().feed(stream)
    assert decoded(out) == [msg]
    assert [r.reason for r in out if isinstance(r, RejectedFrame)] == [RejectReason.BAD_END]


def test_overlapping_markers() -> None:
    # ">*>*>" holds markers at offsets 0 and 2; the real frame starts at offset 2.
    msg = ConfigMsg(1, 10)
    out = StreamDecoder().feed(b">*" + encode_frame(msg))
    assert decoded(out) == [msg]


# --- properties ----------------------------------------------------------------


def truncated_frame(msg: Message, k: int) -> bytes:
    """The first ``k`` bytes (modulo its size) of ``msg``'s frame: never the whole frame."""
    frame = encode_frame(msg)
    return frame[: k % len(frame)]


# Garbage that is likely to confuse a decoder: random bytes, bare markers, headers
# with plausible lengths, and truncated real frames.
garbage_piece = st.one_of(
    st.binary(max_size=12),
    st.just(START_MARKER),
    st.sampled_from([b"\x04\x00\x10", b"\x0c\x00\x11", b"\x14\x00\x01", b"\x22\x00\x01"]),
    st.builds(truncated_frame, messages, st.integers(0, 44)),
)
garbage = st.lists(garbage_piece, max_size=6).map(b"".join)


def split(data: bytes, cuts: list[int]) -> list[bytes]:
    """``data`` cut at the given offsets (taken modulo len + 1, sorted)."""
    points = sorted({c % (len(data) + 1) for c in cuts})
    bounds = [0, *points, len(data)]
    return [data[a:b] for a, b in itertools.pairwise(bounds)]


@given(messages)
def test_encode_decode_round_trip(msg: Message) -> None:
    assert StreamDecoder().feed(encode_frame(msg)) == [msg]


@pytest.mark.slow
@given(st.lists(messages, max_size=8), st.lists(st.integers(min_value=0), max_size=20))
def test_stream_split_at_arbitrary_points(msgs: list[Message], cuts: list[int]) -> None:
    stream = b"".join(encode_frame(m) for m in msgs)
    decoder = StreamDecoder()
    out: list[Message | RejectedFrame] = []
    for chunk in split(stream, cuts):
        out += decoder.feed(chunk)
    assert out == msgs
    assert decoder.buffered == 0


@pytest.mark.slow
@settings(max_examples=200)
@given(
    st.lists(st.tuples(garbage, messages), max_size=6),
    garbage,
    st.lists(st.integers(0), max_size=10),
)
def test_garbage_between_frames(
    pairs: list[tuple[bytes, Message]], tail: bytes, cuts: list[int]
) -> None:
    stream = b"".join(g + encode_frame(m) for g, m in pairs) + tail + FLUSH
    decoder = StreamDecoder()
    out: list[Message | RejectedFrame] = []
    for chunk in split(stream, cuts):
        out += decoder.feed(chunk)
    # Every real frame is recovered, in order. The garbage may itself complete a valid
    # frame (a truncated frame followed by the right bytes), which is then rightly
    # accepted too, so the real frames must be a subsequence of the output.
    remaining = iter(decoded(out))
    assert all(any(m == got for got in remaining) for _, m in pairs)


@given(garbage, messages, garbage)
def test_frame_surrounded_by_garbage_is_recovered(
    before: bytes, msg: Message, after: bytes
) -> None:
    out = StreamDecoder().feed(before + encode_frame(msg) + after + FLUSH)
    assert msg in decoded(out)


@pytest.mark.slow
@settings(max_examples=300)
@given(st.binary(max_size=3000) | garbage, st.lists(st.integers(0), max_size=30))
def test_random_bytes_never_raise_and_never_pile_up(data: bytes, cuts: list[int]) -> None:
    decoder = StreamDecoder()
    for chunk in split(data, cuts):
        out = decoder.feed(chunk)
        assert isinstance(out, list)
        assert decoder.buffered < MAX_FRAME_SIZE
    counts = decoder.counts()
    assert counts.bytes_in == len(data)
    assert counts.bytes_skipped + decoder.buffered <= len(data)


# --- robustness figure ---------------------------------------------------------


@pytest.mark.slow
def test_corrupted_stream_accepts_no_corrupted_frame_and_recovers_the_rest() -> None:
    """10,000 STATUS+GYRO+ACC DATA frames, 1% of the bytes XORed with a random
    non-zero value (seed 3). Counters are unique (< 65536), so an accepted message
    is correct iff it equals the original with its counter."""
    rng = random.Random(3)
    originals = [
        DataMsg(
            i,
            StatusBlock(11000 + rng.randrange(1000), 0b111, 0x0F),
            AxisCounts(*(rng.randrange(4096) for _ in range(3))),
            AxisCounts(*(rng.randrange(4096) for _ in range(3))),
        )
        for i in range(10_000)
    ]
    frame_size = 31  # spec section 6
    stream = bytearray(b"".join(encode_frame(m) for m in originals))
    assert len(stream) == frame_size * len(originals)
    flipped = rng.sample(range(len(stream)), len(stream) // 100)
    for p in flipped:
        stream[p] ^= rng.randrange(1, 256)
    touched = {p // frame_size for p in flipped}
    untouched = set(range(len(originals))) - touched

    decoder = StreamDecoder()
    accepted: list[DataMsg] = []
    pos = 0
    while pos < len(stream):  # serial-read-sized chunks
        step = rng.randrange(1, 128)
        accepted += [m for m in decoder.feed(stream[pos : pos + step]) if isinstance(m, DataMsg)]
        pos += step

    assert all(m == originals[m.counter] for m in accepted)  # nothing corrupted accepted
    counters = [m.counter for m in accepted]
    assert len(counters) == len(set(counters))  # nothing delivered twice
    assert not set(counters) & touched  # no touched frame was accepted
    recovered = len(set(counters) & untouched) / len(untouched)
    print(
        f"\nrobustness: {len(untouched)} untouched of {len(originals)} frames, "
        f"recovered {recovered:.2%}; rejections {decoder.counts().rejected_total}"
    )
    assert recovered > 0.99
