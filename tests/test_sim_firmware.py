"""The virtual X-3D's firmware: watchdog, channel arbitration, CONFIG, IMU counts.

Expected values come from the spec (100 ms watchdog, flags, RC switch > 2048,
12-bit counts), the link arithmetic (23-byte COMMAND, 10 bits a byte), thesis
Table 6.2/6.3 (scales, variances) and Ch. 6.2 (accelerometer saturation 14 m/s^2),
with the ground-station side's own scaling (groundstation.model.sensors) reading the counts.
"""

from __future__ import annotations

import math
import struct
from typing import Any

import numpy as np
import pytest

from groundstation.asctec.crc import crc16
from groundstation.asctec.decoder import encode_frame
from groundstation.asctec.messages import CommandMsg, ConfigMsg, DataMsg
from groundstation.model.sensors import ImuScaling
from groundstation.types import Sticks
from sim_device import ImuParams, LabParams, PilotParams, PlantParams, VirtualLab

DT = 0.002
COMMAND_TIME = 23 * 10 / 57600  # COMMAND frame on the wire at the default baud [s]
DELAY = 0.020  # default command transport delay [s]


def arrival_step(t_write: float) -> float:
    """First 2 ms step boundary at or after the COMMAND's arrival."""
    return math.ceil((t_write + COMMAND_TIME + DELAY) / DT - 1e-9) * DT


def mask_log(lab: VirtualLab) -> tuple[np.ndarray, np.ndarray]:
    log = lab.truth_log.arrays()
    return log["t"], log["ctrl_mask"]


def make_lab(**kwargs: Any) -> VirtualLab:
    return VirtualLab(LabParams(truth_period=DT, **kwargs), seed=2)


def test_watchdog_hands_back_100ms_after_the_last_valid_command() -> None:
    lab = make_lab()
    lab.advance(0.2)
    lab.send(CommandMsg(thrust=1000, ctrl=0x0F))
    lab.advance(0.3)
    lab.send(CommandMsg(thrust=1000, ctrl=0x0F))
    lab.advance(0.1)
    t, mask = mask_log(lab)
    on = arrival_step(0.2)
    assert set(mask[t < on - 1e-9]) == {0}
    held = t[mask == 0x0F]
    assert held[0] == pytest.approx(on)
    first_run = held[held < 0.45]
    # alive while t - t_cmd < 100 ms: the last held step is 98 ms after, the pilot's at 100 ms
    assert first_run[-1] == pytest.approx(on + 0.098)
    assert mask[np.isclose(t, on + 0.100)] == 0
    assert held[held > 0.45][0] == pytest.approx(arrival_step(0.5))  # back on the next one
    assert lab.stats().handbacks == 1


def test_status_and_rc_blocks_report_control() -> None:
    lab = make_lab()
    lab.set_pilot(Sticks(roll=-300, thrust=500))
    lab.send(ConfigMsg(0x11, 10))  # STATUS + RC
    lab.advance(0.1)
    lab.send(CommandMsg(pitch=100, thrust=1500, ctrl=0x09))
    msgs = [m for _, m in lab.advance_messages(0.09)]
    last = msgs[-1]
    assert last.status is not None and last.rc is not None
    assert last.status.ctrl_mask == 0x09 and last.status.flags == 0b111
    assert (last.rc.pitch, last.rc.roll, last.rc.yaw, last.rc.thrust) == (0, -300, 0, 500)
    assert last.rc.switch > 2048
    lab.set_pilot(serial_enable=False)
    lab.send(CommandMsg(pitch=100, thrust=1500, ctrl=0x09))
    last = lab.advance_messages(0.05)[-1][1]
    assert last.status is not None and last.rc is not None
    assert last.status.ctrl_mask == 0 and last.status.flags == 0b110  # motors, RC link
    assert last.rc.switch <= 2048
    assert lab.truth.sticks == Sticks(roll=-300, thrust=500)


@pytest.mark.parametrize(
    ("ctrl", "expected"),
    [
        (0x08, Sticks(roll=-300, pitch=40, yaw=7, thrust=1500)),
        (0x02, Sticks(roll=111, pitch=40, yaw=7, thrust=900)),
        (0x05, Sticks(roll=-300, pitch=222, yaw=-333, thrust=900)),
        (0x0F, Sticks(roll=111, pitch=222, yaw=-333, thrust=1500)),
    ],
)
def test_commands_apply_per_channel_by_ctrl_mask(ctrl: int, expected: Sticks) -> None:
    lab = make_lab()
    lab.set_pilot(Sticks(roll=-300, pitch=40, yaw=7, thrust=900))
    lab.send(CommandMsg(pitch=222, roll=111, yaw=-333, thrust=1500, ctrl=ctrl))
    lab.advance(0.05)
    assert lab.truth.sticks == expected
    assert lab.truth.ctrl_mask == ctrl


def _command_frame(payload: bytes) -> bytes:
    """A COMMAND frame around a hand-made payload, with a correct CRC."""
    return b">*>" + struct.pack("<HB", len(payload), 0x11) + payload + struct.pack(
        "<H", crc16(payload)) + b"<#<"


def test_corrupted_commands_do_not_feed_the_watchdog() -> None:
    lab = make_lab()
    lab.send(CommandMsg(thrust=1000, ctrl=0x0F))
    good = encode_frame(CommandMsg(thrust=1000, ctrl=0x0F))
    bad_crc = good[:-5] + bytes([good[-5] ^ 0x01]) + good[-4:]
    bad_sum = _command_frame(struct.pack("<hhhhHH", 0, 0, 0, 1000, 0x0F, 0x1234))
    value_sum = (5000 + 0x0F + 0xAAAA) & 0xFFFF
    bad_range = _command_frame(struct.pack("<hhhhHH", 0, 0, 0, 5000, 0x0F, value_sum))
    lab.advance(0.04)
    for _ in range(10):
        for frame in (bad_crc, bad_sum, bad_range):
            lab.write(frame)
            lab.advance(0.01)
    lab.advance(0.05)  # the last ones are still in flight (transport delay)
    t, mask = mask_log(lab)
    on = arrival_step(0.0)
    assert t[mask == 0x0F][-1] == pytest.approx(on + 0.098)
    assert lab.stats().commands == 1
    assert lab.stats().uplink_rejected == {"bad_crc": 10, "command_checksum": 10,
                                           "command_range": 10}


def test_config_sets_blocks_period_and_stop() -> None:
    lab = make_lab()
    assert lab.advance(0.5) == []  # nothing streams before a CONFIG
    lab.send(ConfigMsg(0x07, 20))
    frames = lab.advance(1.0)
    assert len(frames) == pytest.approx(50, abs=1)
    assert {len(f) for _, f in frames} == {11 + 4 + 4 + 6 + 6}
    msgs = lab.advance_messages(0.5)
    counters = [m.counter for _, m in msgs]
    assert np.all(np.diff(counters) == 1)
    lab.send(ConfigMsg(0x07, 0))
    lab.advance(0.1)
    assert lab.advance(0.5) == []


def _acc_and_gyro_si(msgs: list[tuple[float, DataMsg]]) -> tuple[np.ndarray, np.ndarray]:
    scaling = ImuScaling()  # Table 6.2, zero 2048: what the ground station assumes
    acc, gyro = [], []
    for _, m in msgs:
        assert m.acc is not None and m.gyro is not None
        acc.append(scaling.acc.to_si(np.array([m.acc.x, m.acc.y, m.acc.z])))
        gyro.append(scaling.gyro.to_si(np.array([m.gyro.x, m.gyro.y, m.gyro.z])))
    return np.array(acc), np.array(gyro)


@pytest.mark.slow
def test_imu_at_rest_reads_gravity_with_table_6_3_noise() -> None:
    clean = ImuParams(gyro_bias=(0.0, 0.0, 0.0), acc_bias=(0.0, 0.0, 0.0), scale_error=0.0)
    lab = make_lab(imu=clean)
    lab.send(ConfigMsg(0x07, 10))
    acc, gyro = _acc_and_gyro_si(lab.advance_messages(10.0))
    assert len(acc) >= 990
    np.testing.assert_allclose(acc.mean(axis=0), [0.0, 0.0, -9.82], atol=0.01)
    np.testing.assert_allclose(gyro.mean(axis=0), [0.0, 0.0, 0.0], atol=0.005)
    # Table 6.3 variances plus the rounding to counts (uniform, K^2 / 12)
    k_acc, k_gyro = np.array([0.0086, 0.0077, 0.0111]), np.array([0.0144, 0.0143, 0.0127])
    np.testing.assert_allclose(acc.var(axis=0), np.array([4.60e-3, 2.62e-3, 3.54e-3])
                               + k_acc**2 / 12, rtol=0.15)
    np.testing.assert_allclose(gyro.var(axis=0), np.array([1.24e-4, 1.94e-4, 8.54e-4])
                               + k_gyro**2 / 12, rtol=0.15)


@pytest.mark.slow
def test_imu_bias_and_scale_error_show_in_the_mean() -> None:
    lab = make_lab()  # default biases and up to 2 % scale error
    lab.send(ConfigMsg(0x07, 10))
    acc, gyro = _acc_and_gyro_si(lab.advance_messages(10.0))
    imu = lab.firmware.imu
    gain_acc, gain_gyro = np.array(imu.acc_scale_true), np.array(imu.gyro_scale_true)
    assert np.all(np.abs(gain_acc - 1.0) <= 0.02) and np.any(gain_acc != 1.0)
    expected_acc = gain_acc * np.array([0.0 + 0.05, 0.0 - 0.05, -9.82 + 0.1])  # truth + bias
    np.testing.assert_allclose(acc.mean(axis=0), expected_acc, atol=0.01)
    np.testing.assert_allclose(gyro.mean(axis=0), gain_gyro * [0.01, -0.02, 0.005], atol=0.005)


def test_accelerometer_saturates_at_14_and_adc_clips_at_12_bits() -> None:
    lab = make_lab(plant=PlantParams(battery_droop=0.0, motor_tau_s=0.0),
                   imu=ImuParams(gyro_scale=(0.0005, 0.0005, 0.0005)))
    lab.send(ConfigMsg(0x07, 10))
    lab.place((0.0, 0.0, -1.0))
    lab.set_pilot(Sticks(roll=2047, pitch=-2048, thrust=4096))  # full climb: ~ -16.9 m/s^2
    msgs = [m for _, m in lab.advance_messages(0.2)][3:]
    assert all(m.acc is not None and m.acc.z == round(2048 - 14.0 / 0.0111) for m in msgs)
    # 2.25 rad/s at a 0.0005 rad/s-per-count scale is past the 12-bit range
    late = msgs[-5:]
    assert all(m.gyro is not None and (m.gyro.x, m.gyro.y) == (4095, 0) for m in late)


@pytest.mark.parametrize("hold", [True, False])
def test_pilot_holds_thrust_when_the_vehicle_falls_back_in_flight(hold: bool) -> None:
    lab = make_lab(pilot=PilotParams(hold_thrust=hold))
    lab.place((0.0, 0.0, -1.0))
    lab.send(CommandMsg(roll=200, thrust=2050, ctrl=0x0F))  # one command, then silence
    lab.advance(0.3)
    truth = lab.truth
    assert truth.ctrl_mask == 0 and lab.stats().handbacks == 1
    if hold:  # neutral rates, thrust held: it keeps flying
        assert truth.sticks == Sticks(thrust=2050)
        assert truth.velocity[2] < 0.5
    else:  # the configured pilot thrust (0): motors stop, it falls
        assert truth.sticks == Sticks()
        assert truth.velocity[2] > 1.0


def test_pilot_thrust_on_the_floor_is_not_held() -> None:
    lab = make_lab()
    lab.send(CommandMsg(thrust=1500, ctrl=0x0F))  # below hover: stays on the floor
    lab.advance(0.3)
    assert lab.truth.on_ground and lab.truth.sticks == Sticks()
