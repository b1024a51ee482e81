"""The virtual lab in real time: a real pty with a plain pyserial client, real UDP on 127.0.0.1.

Nothing here asserts wall-clock timing; waits are generous upper bounds. Expected
content comes from the spec (frames, flags, ctrl mask) and the truth-file format of
sim_device.truth.
"""

from __future__ import annotations

import signal
import socket
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
import serial

from groundstation.asctec.decoder import StreamDecoder, encode_frame
from groundstation.asctec.messages import CommandMsg, ConfigMsg, DataMsg
from groundstation.config import GroundStationConfig, apply_overrides, load_config
from groundstation.vicon.decoder import ViconFrame, decode_datagram
from sim_device import LabParams, SimDeviceThread, VirtualLab
from sim_device.realtime import STALL_S, exchange


def _config(repo: Path, port: int, truth: Path) -> GroundStationConfig:
    return apply_overrides(load_config(repo / "config" / "sim.yaml"),
                           {"vicon.port": port, "sim.truth_file": str(truth)})


def _read_until(port: serial.Serial, decoder: StreamDecoder,
                want: Callable[[list[DataMsg]], bool], timeout: float = 5.0) -> list[DataMsg]:
    """Read DATA until ``want(msgs)`` is true (or fail after ``timeout`` seconds)."""
    msgs: list[DataMsg] = []
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        msgs += [m for m in decoder.feed(port.read(256)) if isinstance(m, DataMsg)]
        if want(msgs):
            return msgs
    pytest.fail(f"condition not met within {timeout} s; got {len(msgs)} DATA messages")


@pytest.mark.virtual_vehicle
def test_pty_round_trip_with_pyserial_and_udp(repo: Path, tmp_path: Path) -> None:
    udp = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        udp.bind(("127.0.0.1", 0))
        udp.settimeout(5.0)
        truth = tmp_path / "truth.npz"
        with SimDeviceThread(_config(repo, udp.getsockname()[1], truth)) as dev:
            assert dev.info.truth_file == truth
            with serial.Serial(dev.info.pty_path, 57600, timeout=0.02) as port:
                decoder = StreamDecoder()
                port.write(encode_frame(ConfigMsg(0x17, 10)))  # STATUS, GYRO, ACC, RC
                msgs = _read_until(port, decoder, lambda m: len(m) >= 10)
                assert all(m.mask == 0x17 for m in msgs)
                assert np.all(np.diff([m.counter for m in msgs]) == 1)
                assert msgs[-1].status is not None and msgs[-1].status.ctrl_mask == 0

                def commanded(ms: list[DataMsg]) -> bool:
                    port.write(encode_frame(CommandMsg(thrust=2200, ctrl=0x0B)))
                    return any(m.status is not None and m.status.ctrl_mask == 0x0B
                               and m.status.serial_active for m in ms)

                _read_until(port, decoder, commanded)
                # no more commands: the watchdog gives every channel back to the pilot
                _read_until(port, decoder, lambda ms: ms[-1:] != [] and ms[-1].status
                            is not None and ms[-1].status.ctrl_mask == 0)
            frame = decode_datagram(udp.recv(2048))
            assert isinstance(frame, ViconFrame) and frame.find("X3D") is not None
        assert dev.result is not None and dev.result.stats.commands > 0
    finally:
        udp.close()
    log = np.load(truth)
    assert np.all(np.diff(log["t"]) > 0)
    assert log["position"].shape == (len(log["t"]), 3)
    assert 0x0B in set(log["ctrl_mask"].tolist())
    assert log["sticks"][log["ctrl_mask"] == 0x0B, 3].min() == 2200


_CHILD = """
import sys
from groundstation.config import apply_overrides, load_config
from sim_device import run_sim_device
cfg = apply_overrides(load_config(sys.argv[1]), {"vicon.port": int(sys.argv[2])})
run_sim_device(cfg, truth_file=sys.argv[3], announce=lambda line: print(line, flush=True))
"""


@pytest.mark.virtual_vehicle
@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGINT])
def test_signal_stops_the_run_and_writes_truth(repo: Path, tmp_path: Path, signum: int) -> None:
    truth = tmp_path / "truth.npz"
    child = subprocess.Popen(
        [sys.executable, "-c", _CHILD, str(repo / "config" / "sim.yaml"), "51987", str(truth)],
        stdout=subprocess.PIPE, text=True)
    try:
        assert child.stdout is not None
        first = child.stdout.readline()
        assert first.startswith("virtual X-3D on /dev/pts/")
        assert "udp://127.0.0.1:51987" in first
        time.sleep(0.3)
        child.send_signal(signum)
        rest = child.communicate(timeout=20)[0]
    finally:
        if child.poll() is None:
            child.kill()
            child.communicate()
    assert child.returncode == 0
    assert "ground truth" in rest and str(truth) in rest
    assert len(np.load(truth)["t"]) > 0


def test_a_stall_of_the_simulator_is_not_a_command_gap_of_the_ground_station() -> None:
    """The real-time loop's step (:func:`sim_device.realtime.exchange`) on the virtual X-3D's
    own firmware: COMMANDs every 20 ms, then the lab's process wakes 150 ms late with the
    seven COMMANDs the ground station wrote meanwhile waiting in the pty. They go in spread
    over the stall, so the 100 ms watchdog (spec) does not hand back to the pilot; a ground
    station that wrote nothing in the same stall is handed back; and an ordinary wake-up
    (one plant step late) writes its bytes after the advance, as before: a COMMAND then
    needs its full transport time to apply."""
    command = encode_frame(CommandMsg(thrust=1000, ctrl=0x0F))
    for meanwhile, handbacks in ((command * 7, 0), (b"", 1)):
        lab = VirtualLab(LabParams(), seed=1)
        t = 0.0
        for _ in range(20):  # 0.4 s of COMMANDs at 50 Hz, on time
            t += 0.02
            exchange(lab, t, command)
        assert lab.firmware.applied_mask == 0x0F
        t += 0.15  # the stall: well over the watchdog's 100 ms
        assert t - lab.t > STALL_S
        exchange(lab, t, meanwhile)
        assert lab.stats().handbacks == handbacks, len(meanwhile)
        exchange(lab, t + 0.05, b"")  # the last one's transport time
        assert lab.stats().commands == 20 + len(meanwhile) // len(command)  # all, once
    lab = VirtualLab(LabParams(), seed=1)
    exchange(lab, 0.002, command)  # written at 2 ms: on the wire 4 ms, delayed 20 ms
    exchange(lab, 0.0259, b"")
    assert lab.firmware.applied_mask == 0
    exchange(lab, 0.0261, b"")
    assert lab.firmware.applied_mask == 0x0F
