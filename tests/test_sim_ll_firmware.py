"""The virtual vehicle in the AscTec LL dialect: polls, answers, commands, fallback.

Expected values come from ``asctec-ll-protocol.md`` (packet sizes 16/28/33/16/92 bytes,
11 bytes of framing, the 5-byte acknowledgement, flightMode 0x20/0x40, mask bits), the
link arithmetic (10 bits a byte at 57600 baud, the 20 ms transport delay, the lab's 2 ms
step) and the configuration (``serial.ll.fallback_ms``, ``serial.ll.rc_channels``, the
vehicle's zero and scale), read back with the project's host-side codec
(:mod:`groundstation.asctec.ll`). Everything runs on the lab's simulated clock except the
last test, which starts ``gs sim-device --protocol asctec-ll`` and polls its pty.
"""

from __future__ import annotations

import math
import socket
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import serial
from typer.testing import CliRunner

from groundstation.asctec.decoder import Ack, encode_frame
from groundstation.asctec.ll import (
    ControllerOutput,
    ImuCalcData,
    ImuRawData,
    LlDecoder,
    LlMessage,
    LlStatus,
    PollMask,
    RcData,
    encode_command,
    encode_poll,
)
from groundstation.asctec.messages import CommandMsg, ConfigMsg, DataMsg
from groundstation.cli import app
from groundstation.config import (
    GroundStationConfig,
    apply_overrides,
    dump_config,
    load_config,
    validate_config,
)
from groundstation.errors import ConfigError
from groundstation.types import Sticks
from sim_device import ImuParams, LabParams, LinkParams, SimDeviceProcess, VirtualLab
from sim_device.firmware import Firmware
from sim_device.ll_firmware import LlFirmware

BAUD = 57600
BYTE = 10 / BAUD  # one byte on the wire [s]
DT = 0.002  # the lab's plant step [s]
DELAY = 0.020  # default command transport delay [s]
OVERHEAD = 11  # >*> + length + descriptor + CRC16 + <#<
POLL_SIZE = 6  # >*>p + uint16
COMMAND_SIZE = 17  # >*>di + 12
ACK = b">a\x00a<"
FRAME = {"ll_status": 16 + OVERHEAD, "imu_rawdata": 28 + OVERHEAD, "rc_data": 33 + OVERHEAD,
         "controller_output": 16 + OVERHEAD, "imu_calcdata": 92 + OVERHEAD}


def ll_config(sim: dict[str, Any] | None = None, **serial_ll: Any) -> GroundStationConfig:
    """A configuration in the LL dialect; IMU zero 0 as on an LL vehicle."""
    return validate_config({
        "serial": {"protocol": "asctec-ll", "ll": serial_ll},
        "vehicle": {"gyro_zero": [0.0, 0.0, 0.0], "acc_zero": [0.0, 0.0, 0.0]},
        "sim": sim or {},
    })


def arrival_step(t_write: float, size: int) -> float:
    """First 2 ms step boundary at or after ``size`` request bytes written at ``t_write``
    reach the vehicle [s]."""
    return math.ceil((t_write + size * BYTE + DELAY) / DT - 1e-9) * DT


@pytest.mark.slow
def test_poll_is_answered_by_exactly_the_requested_packets_at_the_baud() -> None:
    lab = VirtualLab(ll_config())
    assert isinstance(lab.firmware, LlFirmware) and lab.firmware.next_sample_ns is None
    assert lab.advance(0.5) == []  # nothing unpolled
    lab.poll(0x000B)
    got = lab.advance_packets(0.2)
    assert [type(p) for _, p in got] == [LlStatus, ImuRawData, RcData]
    t = [ti for ti, _ in got]
    start = arrival_step(0.5, POLL_SIZE)
    np.testing.assert_allclose(t, start + BYTE * np.cumsum([27, 39, 44]), atol=1e-9)
    assert t[1] - t[0] == pytest.approx(6.77e-3, abs=0.005e-3)  # 39-byte IMU_RAWDATA
    assert lab.advance(0.5) == []  # one answer per poll
    assert lab.stats().polls == 1 and lab.stats().data_sent == 3
    lab.advance_to(60.5)
    lab.poll(PollMask.LL_STATUS)
    (status,) = (p for _, p in lab.advance_packets(0.1))
    assert isinstance(status, LlStatus) and status.up_time == 60


def test_every_known_bit_in_ascending_order_gps_ignored() -> None:
    lab = VirtualLab(ll_config())
    lab.poll(0x029F)  # all five packets, GPS_DATA and GPS_DATA_ADVANCED
    frames = lab.advance(0.2)
    assert [len(f) for _, f in frames] == [FRAME[n] for n in (  # bits 0x01 ... 0x10
        "ll_status", "imu_rawdata", "imu_calcdata", "rc_data", "controller_output")]
    decoded = [p for _, f in frames for p in LlDecoder().feed(f)]
    assert [type(p) for p in decoded] == [LlStatus, ImuRawData, ImuCalcData, RcData,
                                          ControllerOutput]
    assert decoded[2] == ImuCalcData(bytes(92))
    fw = lab.firmware
    assert isinstance(fw, LlFirmware) and fw.poll_bits_ignored == 2
    lab.poll(PollMask.GPS_DATA)
    assert lab.advance(0.2) == []
    assert fw.poll_bits_ignored == 3 and fw.polls == 2


def test_imu_counts_at_rest_read_minus_g_with_the_configured_scaling() -> None:
    config = ll_config({"acc_bias": [0.0, 0.0, 0.0], "gyro_bias": [0.0, 0.0, 0.0],
                        "scale_error": 0.0})
    lab = VirtualLab(config)
    got: list[tuple[float, LlMessage | Ack]] = []
    for _ in range(200):
        lab.poll(PollMask.IMU_RAWDATA)
        got += lab.advance_packets(0.02)
    got += lab.advance_packets(0.05)
    raw = [p for _, p in got if isinstance(p, ImuRawData)]
    assert len(raw) == len(got) == 200
    acc = np.array([p.acc for p in raw], dtype=float)
    gyro = np.array([p.gyro for p in raw], dtype=float)
    assert np.all(acc[:, 2] < -800)  # int16 counts: below a 12-bit ADC's range
    veh = config.vehicle
    acc_si = np.array(veh.acc_scale) * (acc - np.array(veh.acc_zero))
    gyro_si = np.array(veh.gyro_scale) * (gyro - np.array(veh.gyro_zero))
    np.testing.assert_allclose(acc_si.mean(axis=0), [0.0, 0.0, -veh.gravity], atol=0.02)
    np.testing.assert_allclose(gyro_si.mean(axis=0), [0.0, 0.0, 0.0], atol=0.005)


def test_status_rc_and_controller_output_report_pilot_and_commands() -> None:
    lab = VirtualLab(ll_config(rc_channels=(2, 3, 0, 1)))  # pitch, roll, thrust, yaw
    lab.set_pilot(Sticks(roll=-300, pitch=100, yaw=50, thrust=1500))
    lab.poll(PollMask.LL_STATUS | PollMask.RC_DATA | PollMask.CONTROLLER_OUTPUT)
    status, rc, out = (p for _, p in lab.advance_packets(0.1))
    assert isinstance(status, LlStatus) and isinstance(rc, RcData)
    assert (status.battery_mv_1, status.battery_mv_2, status.cpu_load) == (11800, 11800, 1000)
    assert (status.flying, status.motors_on, status.flight_mode) == (0, 1, 0x20)
    assert rc.channels_out == (1500, 2098, 2148, 1748, 4095, 2048, 2048, 2048)
    assert rc.channels_in == rc.channels_out and rc.lock == 1
    assert out == ControllerOutput(nick=100, roll=-300, yaw=50, thrust=1500)
    lab.send(CommandMsg(pitch=-200, thrust=2500, ctrl=0x09))
    lab.advance(0.05)
    lab.poll(PollMask.LL_STATUS | PollMask.CONTROLLER_OUTPUT)
    status, out = (p for _, p in lab.advance_packets(0.1))
    assert isinstance(status, LlStatus) and status.flight_mode == 0x60
    assert out == ControllerOutput(nick=-200, roll=-300, yaw=50, thrust=2500)
    lab.set_pilot(serial_enable=False, rc_link=False)
    lab.poll(PollMask.LL_STATUS | PollMask.RC_DATA)
    status, rc = (p for _, p in lab.advance_packets(0.1))
    assert isinstance(status, LlStatus) and isinstance(rc, RcData)
    assert status.flight_mode == 0 and rc.channels_out[4] == 0 and rc.lock == 0


def test_a_command_is_acknowledged_and_applied_per_channel() -> None:
    lab = VirtualLab(ll_config())
    lab.set_pilot(Sticks(roll=-300, pitch=40, yaw=7, thrust=900))
    lab.write(encode_command(CommandMsg(pitch=222, roll=111, yaw=-333, thrust=1500, ctrl=0x05)))
    frames = lab.advance(0.05)
    assert [f for _, f in frames] == [ACK]
    assert frames[0][0] == pytest.approx(arrival_step(0.0, COMMAND_SIZE) + 5 * BYTE, abs=1e-9)
    assert lab.firmware.applied == Sticks(roll=-300, pitch=222, yaw=-333, thrust=900)
    assert lab.firmware.applied_mask == 0x05
    lab.send(CommandMsg(pitch=222, roll=111, yaw=-333, thrust=1500, ctrl=0x0F))  # LL wrapping
    assert [p for _, p in lab.advance_packets(0.05)] == [Ack(0)]
    assert lab.truth.sticks == Sticks(roll=111, pitch=222, yaw=-333, thrust=1500)
    assert lab.stats().commands == 2 and lab.stats().configs == 0


def test_commands_with_enough_thrust_make_the_plant_climb() -> None:
    lab = VirtualLab(ll_config())
    for _ in range(100):  # 2 s at 50 Hz
        lab.send(CommandMsg(thrust=2600, ctrl=0x0F))
        lab.advance(0.02)
    assert lab.truth.position[2] < -0.3  # NED: up is negative z
    assert lab.truth.velocity[2] < -0.2
    fw = lab.firmware  # the last command is still on its way
    assert isinstance(fw, LlFirmware) and fw.acks_sent == fw.commands == 99


@pytest.mark.parametrize("fallback_ms", [100.0, 200.0])
def test_fallback_hands_every_channel_back_after_fallback_ms(fallback_ms: float) -> None:
    config = ll_config() if fallback_ms == 100.0 else ll_config(fallback_ms=fallback_ms)
    assert config.serial.ll.fallback_ms == fallback_ms
    lab = VirtualLab(config)
    assert lab.params.link.watchdog == pytest.approx(fallback_ms / 1000)
    lab.set_pilot(Sticks(thrust=300))
    lab.send(CommandMsg(pitch=500, thrust=1200, ctrl=0x0F))
    on = arrival_step(0.0, COMMAND_SIZE)
    fallback = fallback_ms / 1000
    lab.advance_to(on + 0.8 * fallback)
    assert lab.firmware.applied_mask == 0x0F
    assert lab.firmware.applied == Sticks(pitch=500, thrust=1200)
    lab.advance_to(on + 1.2 * fallback)
    assert lab.firmware.applied_mask == 0
    assert lab.firmware.applied == Sticks(thrust=300)  # on the floor: the pilot's own stick
    assert lab.stats().handbacks == 1
    lab.poll(PollMask.LL_STATUS)
    (status,) = (p for _, p in lab.advance_packets(0.1))
    assert isinstance(status, LlStatus) and status.flight_mode == 0x20


def test_a_stalled_vehicle_answers_no_polls() -> None:
    lab = VirtualLab(ll_config())
    lab.stall_data(0.5, start=0.0)
    for _ in range(10):
        lab.poll(0x000B)
        lab.advance(0.04)
    lab.send(CommandMsg(thrust=1000, ctrl=0x08))  # the command path still works
    assert [p for _, p in lab.advance_packets(0.05)] == [Ack(0)]
    assert lab.stats().samples_stalled == 10
    lab.advance_to(0.6)
    lab.poll(PollMask.IMU_RAWDATA)
    assert [type(p) for _, p in lab.advance_packets(0.1)] == [ImuRawData]


def test_polling_beyond_the_baud_loses_answers_not_time() -> None:
    lab = VirtualLab(ll_config())
    latest: list[float] = []
    for k in range(100):  # 240 bytes every 10 ms: 4x what 57600 baud carries
        lab.poll(0x001F)
        latest += [t - k * 0.01 for t, _ in lab.advance_packets(0.01)]
    stats = lab.stats()
    assert stats.samples_busy > 200
    # the transmit buffer (512 bytes, 89 ms) bounds the delay behind the poll
    assert max(latest) < DELAY + POLL_SIZE * BYTE + 512 * BYTE + 2 * DT


def test_corrupted_requests_are_counted_never_crash() -> None:
    lab = VirtualLab(ll_config())
    good = encode_command(CommandMsg(thrust=1000, ctrl=0x0F))
    bad_sum = good[:-1] + bytes([good[-1] ^ 0x01])
    rng = np.random.default_rng(5)
    lab.write(b">*>zz" + bad_sum + b">*>p" + bytes(rng.integers(0, 256, 2000, dtype=np.uint8)))
    lab.write(b">*>me")
    lab.advance(0.5)
    lab.poll(PollMask.IMU_RAWDATA)
    got = lab.advance_packets(0.2)
    assert ImuRawData in [type(p) for _, p in got]
    rejected = lab.stats().uplink_rejected
    assert rejected["bad_request"] >= 1 and rejected["command_checksum"] == 1
    fw = lab.firmware
    assert isinstance(fw, LlFirmware) and fw.emergencies == 1
    assert lab.firmware.applied_mask == 0 and lab.stats().commands == 0


def test_corruption_on_the_link_is_survived() -> None:
    lab = VirtualLab(ll_config({"faults": {"corruption_rate": 0.01}}))
    n = 0
    for _ in range(200):
        lab.poll(0x000B)
        lab.send(CommandMsg(thrust=800, ctrl=0x08))
        n += len(lab.advance_packets(0.03))
    assert 0.5 * 800 < n < 800  # answers and acks, some lost to bit flips
    assert lab.stats().bits_flipped > 0 and lab.stats().uplink_rejected


def test_an_x3d_config_frame_is_ignored() -> None:
    lab = VirtualLab(ll_config())
    lab.write(encode_frame(ConfigMsg(0x17, 10)))
    lab.write(encode_frame(CommandMsg(thrust=1000, ctrl=0x0F)))  # X-3D framing: not LL's
    assert lab.advance(1.0) == []
    assert lab.stats().configs == 0 and lab.stats().commands == 0
    assert lab.stats().uplink_rejected.get("bad_request", 0) >= 2
    with pytest.raises(RuntimeError, match="use advance_packets"):
        lab.advance_messages(0.1)


def test_x3d_default_still_streams_data() -> None:
    config = validate_config({"sim": {}})
    assert LabParams.from_config(config).link == LinkParams()
    lab = VirtualLab(config)
    assert type(lab.firmware) is Firmware and lab.protocol == "x3d"
    lab.poll(PollMask.IMU_RAWDATA)  # not a frame of this dialect
    lab.send(ConfigMsg(0x07, 10))
    msgs = lab.advance_messages(0.5)
    assert len(msgs) == pytest.approx(47, abs=2)
    assert all(isinstance(m, DataMsg) and m.mask == 0x07 for _, m in msgs)
    with pytest.raises(RuntimeError, match="use advance_messages"):
        lab.advance_packets(0.1)


def test_from_config_maps_the_ll_link() -> None:
    p = LabParams.from_config(ll_config(fallback_ms=250.0, rc_channels=(3, 2, 1, 0)))
    assert (p.link.protocol, p.link.watchdog, p.link.rc_channels) == (
        "asctec-ll", 0.25, (3, 2, 1, 0))
    assert p.imu.count_range == (-32768, 32767) and p.imu.acc_zero == (0.0, 0.0, 0.0)
    x3d = LabParams.from_config(validate_config({"serial": {"ll": {"fallback_ms": 250.0}},
                                                 "sim": {}}))
    assert (x3d.link.protocol, x3d.link.watchdog, x3d.imu.count_range) == ("x3d", 0.1,
                                                                          (0, 4095))


@pytest.mark.parametrize("build", [
    lambda: LinkParams(protocol="x3d-ll"),  # type: ignore[arg-type]  # bad on purpose
    lambda: LinkParams(rc_channels=(0, 1, 2, 4)),  # the serial-enable switch's channel
    lambda: LinkParams(rc_channels=(0, 1, 1, 3)),
    lambda: LinkParams(tx_buffer=64),  # smaller than IMU_CALCDATA's frame
    lambda: LabParams(imu=ImuParams(count_range=(-32768, 32767))),  # not 12-bit X-3D counts
    lambda: ImuParams(count_range=(10, 10)),
])
def test_bad_ll_parameters_raise_config_error(build: Callable[[], object]) -> None:
    with pytest.raises(ConfigError):
        build()


def test_bad_protocol_option_exits_2(repo: Path) -> None:
    result = CliRunner().invoke(app, ["sim-device", "--config", str(repo / "config" / "sim.yaml"),
                                      "--protocol", "mavlink"])
    assert result.exit_code == 2


@pytest.mark.virtual_vehicle
def test_gs_sim_device_protocol_asctec_ll_answers_polls_on_its_pty(repo: Path,
                                                                   tmp_path: Path) -> None:
    udp = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        udp.bind(("127.0.0.1", 0))
        config = apply_overrides(load_config(repo / "config" / "sim.yaml"),
                                 {"vicon.port": udp.getsockname()[1]})
        config_file = tmp_path / "sim.yaml"
        config_file.write_text(dump_config(config), encoding="utf-8")
        with SimDeviceProcess(config_file, tmp_path / "truth.npz", protocol="asctec-ll",
                              duration=9.0, timeout=8.0) as dev, \
                serial.serial_for_url(dev.pty_path, baudrate=BAUD, timeout=1) as port:
            decoder = LlDecoder()
            got: list[object] = []
            port.write(encode_poll(PollMask.IMU_RAWDATA)
                       + encode_command(CommandMsg(thrust=0, ctrl=0x08)))
            deadline = time.monotonic() + 5.0
            while time.monotonic() < deadline and len(got) < 2:
                got += decoder.feed(port.read(max(1, port.in_waiting)))
            assert [type(p) for p in got] == [ImuRawData, Ack]
        assert dev.wire is not None and len(dev.wire.command_in) >= 1
        assert len(dev.wire.data_out) >= 1
    finally:
        udp.close()
