"""The virtual fleet: N virtual X-3Ds on N ptys, one Tracker stream carrying every object
(``gs sim-device --vehicles N | --fleet FILE``)."""

from __future__ import annotations

import json
import socket
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from groundstation.config import apply_overrides, dump_config, load_config
from groundstation.endpoints import free_ports
from groundstation.vicon.decoder import ObjectPose, ViconFrame, decode_datagram, encode_datagram
from sim_device.config import sim_section
from sim_device.fleet import merge_datagrams, vehicles_in_a_row
from sim_device.vicon import ViconDatagram

REPO = Path(__file__).resolve().parents[1]


def dgram(t: float, frame: int, *objects: ObjectPose) -> ViconDatagram:
    return ViconDatagram(t, encode_datagram(frame, list(objects)), frame, True)


def test_one_datagram_per_instant_carries_every_labs_items_as_they_were() -> None:
    a = ObjectPose("X3D-1", (1.0, 2.0, 3.0), (0.1, 0.2, 0.3))
    b_lost = ObjectPose("X3D-2", (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))  # its lab's "zero"
    groups = [[dgram(0.01, 7, a), dgram(0.02, 8, a)],
              [dgram(0.01, 7, b_lost)]]  # lab 2 paused after its first: missing from the 2nd
    merged = merge_datagrams(groups, 1024)
    assert [t for t, _ in merged] == [0.01, 0.02]
    frames = [decode_datagram(d) for _, d in merged]
    assert all(isinstance(f, ViconFrame) for f in frames)
    assert [f.frame for f in frames] == [7, 8]  # type: ignore[union-attr]
    assert [o.name for o in frames[0].objects] == ["X3D-1", "X3D-2"]  # type: ignore[union-attr]
    assert frames[0].objects[1] == b_lost  # type: ignore[union-attr]
    assert [o.name for o in frames[1].objects] == ["X3D-1"]  # type: ignore[union-attr]
    assert all(len(d) == 1024 for _, d in merged)
    many = merge_datagrams([[dgram(0.0, 1, ObjectPose(f"O{k}", (0.0, 0.0, 1.0), (0.0,) * 3))]
                            for k in range(20)], 1024)
    assert len(many[0][1]) == 5 + 75 * 20  # more than the block holds: sent unpadded


def test_vehicles_in_a_row_stand_apart_each_its_own_object_and_seed(tmp_path: Path) -> None:
    row = vehicles_in_a_row(load_config(REPO / "config" / "sim.yaml"), 3, tmp_path / "t.npz")
    assert [v.name for v in row] == ["v1", "v2", "v3"]
    assert [v.config.vicon.object_name for v in row] == ["X3D-1", "X3D-2", "X3D-3"]
    assert [sim_section(v.config).initial_position for v in row] == [
        [-1.0, 0.0, 0.0], [0.0, 0.0, 0.0], [1.0, 0.0, 0.0]]
    assert len({sim_section(v.config).seed for v in row}) == 3
    assert [v.truth_file.name for v in row] == ["t-v1.npz", "t-v2.npz", "t-v3.npz"]


@pytest.mark.virtual_vehicle
@pytest.mark.slow
def test_gs_sim_device_vehicles_announces_every_pty_and_sends_one_stream(tmp_path: Path
                                                                         ) -> None:
    import serial

    port = free_ports(1, socket.SOCK_DGRAM)[0]
    config = tmp_path / "sim.yaml"
    config.write_text(dump_config(apply_overrides(load_config(REPO / "config" / "sim.yaml"),
                                                  {"vicon.port": port})))
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as tracker:
        tracker.bind(("127.0.0.1", port))
        tracker.settimeout(10.0)
        child = subprocess.Popen(
            [sys.executable, "-m", "groundstation", "sim-device", "--json", "--vehicles", "2",
             "--config", str(config), "--truth-file", str(tmp_path / "truth.npz"),
             "--seconds", "3"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        try:
            assert child.stdout is not None
            info = json.loads(child.stdout.readline())
            frames = [decode_datagram(tracker.recv(4096)) for _ in range(20)]
            for vehicle in info["vehicles"]:
                with serial.Serial(vehicle["serial_port"], 57600, timeout=0.5):
                    pass
            child.communicate(timeout=60)
        finally:
            if child.poll() is None:
                child.kill()
                child.communicate()
    assert child.returncode == 0
    assert [v["vicon_object"] for v in info["vehicles"]] == ["X3D-1", "X3D-2"]
    assert info["vicon_target"] == ["127.0.0.1", port]
    assert all(isinstance(f, ViconFrame) and [o.name for o in f.objects] == ["X3D-1", "X3D-2"]
               for f in frames)
    numbers = [f.frame for f in frames]  # type: ignore[union-attr]
    assert numbers == list(range(numbers[0], numbers[0] + 20))  # Tracker's frame counter
    for vehicle in info["vehicles"]:
        truth = np.load(vehicle["truth_file"])
        assert len(truth["t"]) > 100 and float(truth["start_monotonic"]) > 0
    # on the floor where each stands: 1 m apart along north
    x = [float(np.load(v["truth_file"])["position"][-1][0]) for v in info["vehicles"]]
    assert x == pytest.approx([-0.5, 0.5], abs=1e-6)
