"""X-3D message payloads (spec section 3): layout, validation, registry, block table."""

from __future__ import annotations

import struct

import pytest
from hypothesis import given
from hypothesis import strategies as st

from groundstation.asctec.blocks import (
    KNOWN_SENSOR_MASK,
    SENSOR_BLOCKS,
    AxisCounts,
    RcBlock,
    StatusBlock,
    block_names,
    data_payload_size,
    sensor_mask,
)
from groundstation.asctec.messages import (
    CHANNELS,
    MAX_PAYLOAD_SIZE,
    MESSAGE_TYPES,
    CommandMsg,
    ConfigMsg,
    DataMsg,
    Message,
    PayloadError,
    RejectReason,
    build_registry,
    channel_mask,
    mask_channels,
)
from groundstation.errors import ProtocolError
from groundstation.types import Sticks

# Hypothesis strategies for valid messages (also imported by test_asctec_decoder).
u8 = st.integers(0, 0xFF)
u16 = st.integers(0, 0xFFFF)
stick = st.integers(-2048, 2047)
thrust = st.integers(0, 4096)

configs = st.builds(ConfigMsg, st.integers(0, KNOWN_SENSOR_MASK), u16)
commands = st.builds(CommandMsg, stick, stick, stick, thrust, st.integers(0, 0x0F))
axes = st.builds(AxisCounts, u16, u16, u16)
datas = st.builds(
    DataMsg,
    u16,
    st.none() | st.builds(StatusBlock, u16, u8, u8),
    st.none() | axes,
    st.none() | axes,
    st.none() | st.integers(-(2**31), 2**31 - 1),
    st.none() | st.builds(RcBlock, stick, stick, stick, thrust, u16),
)
messages: st.SearchStrategy[Message] = st.one_of(configs, commands, datas)

# --- COMMAND -------------------------------------------------------------------


def test_command_wire_order_is_pitch_roll_yaw_thrust() -> None:
    # Spec 3.2: offsets 0, 2, 4, 6 hold pitch, roll, yaw, thrust (AscTec order), not the
    # thesis input order [roll, pitch, thrust, yaw]. Distinct values make a swap visible.
    payload = CommandMsg(pitch=-7, roll=11, yaw=-13, thrust=17, ctrl=0b0101).pack()
    assert payload[0:2] == struct.pack("<h", -7)
    assert payload[2:4] == struct.pack("<h", 11)
    assert payload[4:6] == struct.pack("<h", -13)
    assert payload[6:8] == struct.pack("<h", 17)
    assert payload[8:10] == b"\x05\x00"


def test_command_checksum_of_the_worked_frame() -> None:
    # Spec 5: -100 + 250 + 0 + 1800 + 15 + 0xAAAA = 45655 = 0xB257, sent as 57 B2.
    msg = CommandMsg(pitch=-100, roll=250, yaw=0, thrust=1800, ctrl=0x0F)
    assert msg.checksum == 0xB257
    assert msg.pack() == bytes.fromhex("9C FF FA 00 00 00 08 07 0F 00 57 B2")


def test_command_checksum_extremes() -> None:
    # Hand sums (spec 3.2, fields as int16): -3*2048 + 0 + 0 + 0xAAAA = 37546 = 0x92AA and
    # 3*2047 + 4096 + 15 + 0xAAAA = 53942 = 0xD2B6. Legal values never wrap past 2^16.
    low = CommandMsg(-2048, -2048, -2048, 0, 0)
    high = CommandMsg(2047, 2047, 2047, 4096, 15)
    assert low.checksum == 0x92AA
    assert high.checksum == 0xD2B6
    assert low.pack()[10:12] == b"\xaa\x92"


@pytest.mark.parametrize(
    "kwargs",
    [
        {"pitch": -2049},
        {"pitch": 2048},
        {"roll": -2049},
        {"roll": 2048},
        {"yaw": 2048},
        {"yaw": -2049},
        {"thrust": -1},
        {"thrust": 4097},
        {"ctrl": 0x10},
        {"ctrl": -1},
        {"pitch": 1.5},
    ],
)
def test_command_out_of_range_is_a_protocol_error(kwargs: dict[str, object]) -> None:
    with pytest.raises(ProtocolError):
        CommandMsg(**kwargs)  # type: ignore[arg-type]  # deliberately wrong types included


def test_command_range_limits_are_inclusive() -> None:
    # Spec 3.2: -2048..2047 and 0..4096 are legal.
    for msg in (CommandMsg(-2048, -2048, -2048, 0, 0), CommandMsg(2047, 2047, 2047, 4096, 15)):
        assert CommandMsg.unpack(msg.pack()) == msg


def test_command_unpack_reasons() -> None:
    good = CommandMsg(1, 2, 3, 4, 0xF).pack()
    bad_sum = good[:10] + bytes([good[10] ^ 1, good[11]])
    with pytest.raises(PayloadError) as info:
        CommandMsg.unpack(bad_sum)
    assert info.value.reason is RejectReason.COMMAND_CHECKSUM
    # thrust 5000 with a correct checksum: a range error, not a checksum error.
    over = struct.pack("<hhhhHH", 0, 0, 0, 5000, 0, (5000 + 0xAAAA) & 0xFFFF)
    with pytest.raises(PayloadError) as info:
        CommandMsg.unpack(over)
    assert info.value.reason is RejectReason.COMMAND_RANGE


def test_release_command_hands_every_channel_back() -> None:
    assert CommandMsg.release().ctrl == 0


# --- CONFIG --------------------------------------------------------------------


def test_config_payload_and_validation() -> None:
    assert ConfigMsg(0x0007, 10).pack() == bytes.fromhex("07 00 0A 00")  # spec 5
    with pytest.raises(ProtocolError):
        ConfigMsg(0x20, 10)
    with pytest.raises(ProtocolError):
        ConfigMsg(0x1, 70000)
    with pytest.raises(PayloadError) as info:
        ConfigMsg.unpack(b"\x20\x00\x0a\x00")
    assert info.value.reason is RejectReason.CONFIG_MASK


# --- DATA and the block table --------------------------------------------------


def test_block_table_matches_spec() -> None:
    # Spec 3.3 table: (name, bit, size).
    assert [(b.name, b.bit, b.size) for b in SENSOR_BLOCKS] == [
        ("status", 0, 4),
        ("gyro", 1, 6),
        ("acc", 2, 6),
        ("pressure", 3, 4),
        ("rc", 4, 10),
    ]


def test_sensor_mask_and_payload_sizes() -> None:
    assert sensor_mask(["status", "gyro", "acc"]) == 0x0007
    assert block_names(0x0007) == ("status", "gyro", "acc")
    # Spec 5 worked DATA frame: mask 0x0007 has N = 0x14 = 20.
    assert data_payload_size(0x0007) == 20
    # Spec 6: STATUS+GYRO+ACC frames are 31 bytes, all five blocks 45 bytes (N + 11).
    assert data_payload_size(0x0007) + 11 == 31
    assert data_payload_size(sensor_mask(b.name for b in SENSOR_BLOCKS)) + 11 == 45
    assert data_payload_size(0) == 4
    assert MAX_PAYLOAD_SIZE == 34
    with pytest.raises(ProtocolError):
        data_payload_size(0x20)
    with pytest.raises(ProtocolError, match="magnetometer"):
        sensor_mask(["gyro", "magnetometer"])


def test_data_payload_of_the_worked_frame() -> None:
    msg = DataMsg(
        1234,
        status=StatusBlock(11800, 0b011, 0x0F),
        gyro=AxisCounts(2048, 2050, 2046),
        acc=AxisCounts(2048, 2048, 1163),
    )
    assert msg.mask == 0x0007
    expected = bytes.fromhex("D2 04 07 00 18 2E 03 0F 00 08 02 08 FE 07 00 08 00 08 8B 04")
    assert msg.pack() == expected
    assert DataMsg.unpack(expected) == msg
    assert msg.status is not None
    assert msg.status.serial_active and msg.status.motors_on and not msg.status.rc_valid


def test_data_block_order_is_bit_order() -> None:
    msg = DataMsg(7, pressure=-5, rc=RcBlock(pitch=1, roll=2, yaw=3, thrust=4, switch=3000))
    assert msg.mask == 0x18
    assert msg.pack() == struct.pack("<HH", 7, 0x18) + struct.pack("<i", -5) + struct.pack(
        "<hhhhH", 1, 2, 3, 4, 3000
    )


def test_data_unpack_rejects_mask_mismatch_and_unknown_bits() -> None:
    payload = DataMsg(1, gyro=AxisCounts(1, 2, 3)).pack()
    for bad in (
        payload[:2] + b"\x03\x00" + payload[4:],  # mask says status+gyro, N fits gyro only
        payload[:2] + b"\x22\x00" + payload[4:],  # unknown bit 5
    ):
        with pytest.raises(PayloadError) as info:
            DataMsg.unpack(bad)
        assert info.value.reason is RejectReason.DATA_MASK


def test_data_pack_out_of_range_is_a_protocol_error() -> None:
    with pytest.raises(ProtocolError):
        DataMsg(70000).pack()
    with pytest.raises(ProtocolError):
        DataMsg(1, gyro=AxisCounts(-1, 0, 0)).pack()


def test_rc_block_to_sticks_and_switch() -> None:
    rc = RcBlock(pitch=10, roll=-20, yaw=30, thrust=2000, switch=2049)
    assert rc.sticks() == Sticks(roll=-20, pitch=10, yaw=30, thrust=2000)
    assert rc.serial_enabled
    assert not RcBlock(0, 0, 0, 0, 2048).serial_enabled  # spec: > 2048 = enabled


# --- channels and registry -----------------------------------------------------


def test_channel_mask_bits() -> None:
    # Spec 3.2: bit0 pitch, bit1 roll, bit2 yaw, bit3 thrust.
    assert CHANNELS == ("pitch", "roll", "yaw", "thrust")
    assert channel_mask(["pitch"]) == 0x1
    assert channel_mask(["roll"]) == 0x2
    assert channel_mask(["yaw"]) == 0x4
    assert channel_mask(["thrust"]) == 0x8
    assert channel_mask(["thrust", "roll"]) == 0xA
    assert mask_channels(0xA) == ("roll", "thrust")
    with pytest.raises(ProtocolError):
        channel_mask(["collective"])


def test_registry_holds_the_three_descriptors_and_refuses_duplicates() -> None:
    assert {d: c.__name__ for d, c in MESSAGE_TYPES.items()} == {
        0x01: "DataMsg",
        0x10: "ConfigMsg",
        0x11: "CommandMsg",
    }
    with pytest.raises(ProtocolError, match="0x10"):
        build_registry(ConfigMsg, CommandMsg, ConfigMsg)


def test_messages_are_frozen_and_slotted() -> None:
    msg = CommandMsg()
    with pytest.raises(AttributeError):
        msg.pitch = 3  # type: ignore[misc]  # the point of the test
    assert not hasattr(msg, "__dict__")


@pytest.mark.slow
@given(messages)
def test_payload_round_trip(msg: Message) -> None:
    payload = msg.pack()
    assert len(payload) in type(msg).PAYLOAD_SIZES
    assert type(msg).unpack(payload) == msg
