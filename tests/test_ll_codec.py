"""The AscTec LL dialect's codec against the spec's byte-exact test vectors.

Every vector of ``asctec-ll-protocol.md`` section 4 goes through the project's encoder
and, where the project decodes that direction, back through its decoder. The vectors
were taken from public AscTec host code, so they are independent of this code.
"""

from __future__ import annotations

import random

import pytest

from groundstation.asctec.crc import crc16, profile_init
from groundstation.asctec.decoder import Ack, RejectedFrame, StreamDecoder, encode_frame
from groundstation.asctec.ll import (
    Emergency,
    ImuRawData,
    LlDecoder,
    LlRequestDecoder,
    LlStatus,
    Poll,
    PollMask,
    RcData,
    RepeatCounter,
    encode_ack,
    encode_command,
    encode_poll,
    motor_gesture,
)
from groundstation.asctec.messages import CommandMsg, DataMsg, RejectReason


def hexbytes(text: str) -> bytes:
    return bytes.fromhex(text.replace(" ", ""))


LL_STATUS_FRAME = hexbytes("3E 2A 3E 10 00 02 18 2E 18 2E 00 00 E8 03 01 00 01 01 21 00 3C 00 "
                           "AD B1 3C 23 3C")
LL_STATUS = LlStatus(battery_mv_1=11800, battery_mv_2=11800, status=0, cpu_load=1000,
                     compass_enabled=1, chksum_error=0, flying=1, motors_on=1,
                     flight_mode=0x0021, up_time=60)

COMMANDS = [
    (CommandMsg(ctrl=0x0C), "3E 2A 3E 64 69 00 00 00 00 00 00 00 00 0C 00 B6 AA"),
    (CommandMsg(yaw=-2047, ctrl=0x0C), "3E 2A 3E 64 69 00 00 00 00 01 F8 00 00 0C 00 B7 A2"),
    (CommandMsg(yaw=-2048, ctrl=0x0F), "3E 2A 3E 64 69 00 00 00 00 00 F8 00 00 0F 00 B9 A2"),
    # the X-3D spec's worked COMMAND (section 5) in this dialect
    (CommandMsg(pitch=-100, roll=250, yaw=0, thrust=1800, ctrl=0x0F),
     "3E 2A 3E 64 69 9C FF FA 00 00 00 08 07 0F 00 57 B2"),
]

POLLS = [
    (PollMask.LL_STATUS, "3E 2A 3E 70 01 00"),
    (PollMask.IMU_RAWDATA, "3E 2A 3E 70 02 00"),
    (PollMask.IMU_CALCDATA, "3E 2A 3E 70 04 00"),
    (PollMask.GPS_DATA, "3E 2A 3E 70 80 00"),
    (0x0185, "3E 2A 3E 70 85 01"),
]


def test_crc_check_value() -> None:
    assert crc16(b"123456789", profile_init("asctec")) == 0x9DB8


def test_ll_status_vector_encodes_and_decodes() -> None:
    assert encode_frame(LL_STATUS) == LL_STATUS_FRAME
    (decoded,) = LlDecoder().feed(LL_STATUS_FRAME)
    assert decoded == LL_STATUS
    assert isinstance(decoded, LlStatus)
    assert decoded.serial_enabled is True and decoded.serial_active is False  # 0x21


@pytest.mark.parametrize(("cmd", "frame"), COMMANDS)
def test_command_vectors(cmd: CommandMsg, frame: str) -> None:
    assert encode_command(cmd) == hexbytes(frame)
    (decoded,) = LlRequestDecoder().feed(hexbytes(frame))
    assert decoded == cmd


def test_motor_gesture_is_the_spec_vector() -> None:
    assert encode_command(motor_gesture(start=True)) == hexbytes(COMMANDS[1][1])
    assert motor_gesture(start=False).yaw == 2047


@pytest.mark.parametrize(("mask", "frame"), POLLS)
def test_poll_vectors(mask: int, frame: str) -> None:
    assert encode_poll(mask) == hexbytes(frame)
    (decoded,) = LlRequestDecoder().feed(hexbytes(frame))
    assert decoded == Poll(mask)


def test_thrust_above_the_ll_range_is_sent_as_4095() -> None:
    wire = encode_command(CommandMsg(thrust=4096, ctrl=0x08))
    (decoded,) = LlRequestDecoder().feed(wire)
    assert isinstance(decoded, CommandMsg) and decoded.thrust == 4095


def test_acks_between_frames_split_at_every_byte() -> None:
    raw = ImuRawData(0x000123, (10, -20, 30), (1, 2, 3), (-4000, 5, 16000), 300, 70000)
    rc = RcData(tuple(range(8)), tuple(range(100, 108)), 1)
    stream = (encode_ack(7) + encode_frame(raw) + b"\x00junk" + encode_ack(0)
              + encode_frame(rc) + LL_STATUS_FRAME)
    expected = [Ack(7), raw, Ack(0), rc, LL_STATUS]
    for cut in range(1, len(stream)):
        decoder = LlDecoder()
        items = decoder.feed(stream[:cut]) + decoder.feed(stream[cut:])
        assert items == expected, cut
    counts = decoder.counts()
    assert counts.frames["ack"] == 2 and counts.frames["imu_rawdata"] == 1


def test_rc_data_of_34_bytes_is_read() -> None:
    rc = RcData(tuple(range(8)), tuple(range(8)), 1)

    class Padded:
        DESCRIPTOR = RcData.DESCRIPTOR

        def pack(self) -> bytes:
            return rc.pack() + b"\x00"

    assert LlDecoder().feed(encode_frame(Padded())) == [rc]


def test_a_broken_ack_is_counted_not_taken() -> None:
    decoder = LlDecoder()
    items = decoder.feed(b">a\x01xx" + encode_ack(3))
    assert items[-1] == Ack(3)
    assert any(isinstance(i, RejectedFrame) and i.reason is RejectReason.BAD_ACK for i in items)


def test_the_dialects_do_not_take_each_others_packets() -> None:
    """The hazard of spec section 5: an LL IMU_RAWDATA whose pressure lies in 0x1B0000..
    0x1BFFFF is a valid X-3D DATA frame (mask 0x1B, 28 bytes). The X-3D decoder takes it
    (which is why the dialect is configured, never guessed); the LL decoder reads it as
    what it is, and an X-3D DATA frame of the default blocks is refused by the LL one."""
    raw = ImuRawData(0x1B1234, (1, 2, 3), (0, 0, 0), (4, 5, 6))
    frame = encode_frame(raw)
    (as_x3d,) = StreamDecoder().feed(frame)
    assert isinstance(as_x3d, DataMsg) and as_x3d.mask == 0x1B  # the hazard exists
    assert LlDecoder().feed(frame) == [raw]
    x3d = encode_frame(DataMsg.unpack(hexbytes("0500 0600") + bytes(12)))  # gyro, acc
    (refused,) = LlDecoder().feed(x3d)
    assert isinstance(refused, RejectedFrame) and refused.reason is RejectReason.BAD_LENGTH


def test_request_decoder_rejects_garbage_and_bad_checksums() -> None:
    good = encode_command(CommandMsg(pitch=5, thrust=100, ctrl=0x0F))
    bad = bytearray(good)
    bad[-1] ^= 0x01  # checksum
    decoder = LlRequestDecoder()
    items = decoder.feed(b">*>x\x00" + bytes(bad) + b">*>me" + good + encode_poll(0x0002))
    kinds = [type(i).__name__ for i in items]
    assert kinds == ["RejectedFrame", "RejectedFrame", "Emergency", "CommandMsg", "Poll"]
    assert items[2] == Emergency()
    reasons = {i.reason for i in items if isinstance(i, RejectedFrame)}
    assert reasons == {RejectReason.BAD_REQUEST, RejectReason.COMMAND_CHECKSUM}


def test_corrupted_streams_never_raise_and_clean_frames_survive() -> None:
    rng = random.Random(5)
    frames = [encode_frame(ImuRawData(i, (i, 2, 3), (0, 0, 0), (4, 5, i))) + encode_ack(i % 256)
              for i in range(300)]
    stream = bytearray(b"".join(frames))
    for _ in range(200):
        stream[rng.randrange(len(stream))] ^= 1 << rng.randrange(8)
    decoder = LlDecoder()
    out = []
    pos = 0
    while pos < len(stream):
        step = rng.randint(1, 60)
        out += decoder.feed(bytes(stream[pos:pos + step]))
        pos += step
    raws = [i for i in out if isinstance(i, ImuRawData)]
    assert len(raws) >= 300 - 200 and all(r.pressure == r.gyro[0] for r in raws)
    assert decoder.counts().rejected_total > 0


def test_repeat_counter_is_algorithm_1() -> None:
    counter = RepeatCounter()
    values = [(1, 2), (1, 2), (1, 3), (1, 3), (1, 3), (2, 2)]
    assert [counter.update(v) for v in values] == [1, 1, 2, 2, 2, 3]
    assert counter.repeats == 3
