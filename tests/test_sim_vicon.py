"""The virtual Vicon sender against spec/vicon-udp.md, Table 6.1 and Table B.1.

Expected bytes are packed by hand with struct at the spec's offsets; the Euler
angles come from scipy (``Rotation.from_matrix(...).as_euler("XYZ")``) applied to
the spec's frame relation ``R_ov = C_wn^T eCb C_bo^T`` with both default
rotations ``diag(1, -1, -1)`` (180 degrees about x).
"""

from __future__ import annotations

import math
import struct
from typing import Any

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from groundstation.config import load_config
from groundstation.vicon.decoder import ViconFrame, decode_datagram, encode_datagram
from groundstation.vicon.frames import FrameConversion, rotation_from_euler_deg
from sim_device import LabParams, ViconSimParams, VirtualLab
from sim_device.params import LossEncoding
from sim_device.vicon import foreign_stream

FLIP_X = np.diag([1.0, -1.0, -1.0])


def lab_with(**vicon: Any) -> VirtualLab:
    return VirtualLab(LabParams(vicon=ViconSimParams(**vicon)), seed=3)


def first_datagram(lab: VirtualLab) -> bytes:
    lab.advance(0.0051)  # the datagram sampled at t = 0 arrives after the 5 ms latency
    [dgram] = lab.vicon_datagrams()
    assert dgram.t == pytest.approx(0.005)
    return dgram.data


def test_datagram_matches_the_spec_byte_for_byte() -> None:
    lab = lab_with(noise=False, first_frame=41)
    q = Rotation.from_euler("ZYX", [30.0, 10.0, -5.0], degrees=True).as_quat(scalar_first=True)
    lab.place((0.5, -0.25, -1.5), quaternion=q)
    data = first_datagram(lab)
    r_ov = FLIP_X.T @ Rotation.from_quat(q, scalar_first=True).as_matrix() @ FLIP_X.T
    rx, ry, rz = Rotation.from_matrix(r_ov).as_euler("XYZ")
    got = struct.unpack_from("<6d", data, 5 + 27)  # first item at 5, x at item offset 27
    assert got[:3] == (500.0, 250.0, 1500.0)  # NED (0.5, -0.25, -1.5) m -> z-up mm
    assert got[3:] == pytest.approx((rx, ry, rz), abs=1e-12)
    expected = (
        struct.pack("<IB", 41, 1)  # frame number, one item
        + struct.pack("<BH", 0, 72)  # object item, 72 data bytes
        + b"X3D".ljust(24, b"\0")
        + struct.pack("<6d", 500.0, 250.0, 1500.0, *got[3:])
    ).ljust(1024, b"\0")  # padded to Tracker's data block size
    assert data == expected


def test_rate_latency_and_frame_numbers() -> None:
    lab = lab_with(rate_hz=10.0, latency=0.03, pad_to=None)
    lab.advance(1.0)
    dgrams = lab.vicon_datagrams()
    assert [d.t for d in dgrams] == pytest.approx([k * 0.1 + 0.03 for k in range(10)])
    assert [d.frame for d in dgrams] == list(range(1, 11))
    assert all(len(d.data) == 5 + 75 for d in dgrams)
    lab.set_vicon(rate_hz=1.0)
    lab.advance(3.0)
    assert len(lab.vicon_datagrams()) == 3


def _pose_bytes(data: bytes) -> bytes:
    return data[32:80]


@pytest.mark.parametrize("encoding", ["missing", "zero", "held-identity"])
def test_outage_in_each_loss_encoding(encoding: LossEncoding) -> None:
    lab = lab_with(loss_encoding=encoding, outages=((0.5, 0.3),))
    lab.advance(1.0)
    dgrams = lab.vicon_datagrams()
    lost = [d for d in dgrams if not d.tracked]
    assert [round(d.t - 0.005, 3) for d in lost] == pytest.approx(
        [0.5 + 0.01 * k for k in range(30)])
    last_tracked = next(d for d in reversed(dgrams) if d.t < 0.5)
    for d in lost:
        frame = decode_datagram(d.data)
        assert isinstance(frame, ViconFrame)
        if encoding == "missing":
            assert d.data[4] == 0 and frame.objects == ()
        elif encoding == "zero":
            assert _pose_bytes(d.data) == struct.pack("<6d", 0, 0, 0, 0, 0, 0)
        else:  # position held at its last value, rotation exactly zero
            assert _pose_bytes(d.data)[:24] == _pose_bytes(last_tracked.data)[:24]
            assert _pose_bytes(d.data)[24:] == struct.pack("<3d", 0, 0, 0)
    assert dgrams[-1].tracked


def test_outage_injected_at_run_time() -> None:
    lab = lab_with()
    lab.advance(0.3)
    lab.vicon_outage(0.2)
    lab.advance(0.5)
    lost = [d for d in lab.vicon_datagrams() if not d.tracked]
    assert len(lost) == 20
    assert lost[0].t == pytest.approx(0.305)


def test_pause_sends_nothing_while_the_frame_number_counts_on() -> None:
    lab = lab_with()
    lab.advance(0.3)
    lab.pause_vicon(0.2)  # Tracker or the network stalls from 0.3 s to 0.5 s
    lab.advance(0.5)
    dgrams = lab.vicon_datagrams()
    assert not [d for d in dgrams if 0.305 <= d.t < 0.505]
    after = next(d for d in dgrams if d.t >= 0.505)
    assert after.frame == 1 + 50 and after.tracked  # 20 frames were never sent
    assert lab.vicon.paused == 20 and lab.stats().vicon_sent == 80 - 20


def test_foreign_datagrams_are_delivered_in_time_order() -> None:
    lab = lab_with(pad_to=None)
    stream = foreign_stream(0.0123, 0.05, 100.0,
                            lambda k, t: encode_datagram(7000 + k, [], pad_to=None))
    assert [round(t, 4) for t, _ in stream] == [0.0123, 0.0223, 0.0323, 0.0423, 0.0523]
    lab.inject_vicon([*stream, (0.0, b"\x01")])  # any bytes, even a short one
    lab.advance(0.06)
    dgrams = lab.vicon_datagrams()
    assert [d.t for d in dgrams] == sorted(d.t for d in dgrams)
    foreign = [d for d in dgrams if d.frame >= 7000 or d.frame == -1]
    assert [d.frame for d in foreign] == [-1, 7000, 7001, 7002, 7003, 7004]
    assert not any(d.tracked for d in foreign)
    assert foreign[1].data == stream[0][1] and foreign[1].t == pytest.approx(0.0123)
    assert len(dgrams) - len(foreign) == 6  # Tracker's own, 5 ms latency, 100 Hz


@pytest.mark.parametrize(
    ("position", "tilt_deg", "tracked"),
    [
        ((1.4, -1.4, -1.9), 0.0, True),
        ((1.6, 0.0, -1.0), 0.0, False),  # Table B.1: x within +/-1.5 m
        ((0.0, -1.6, -1.0), 0.0, False),
        ((0.0, 0.0, -2.1), 0.0, False),  # higher than 2 m
        ((0.0, 0.0, -1.0), 55.0, True),
        ((0.0, 0.0, -1.0), 65.0, False),  # beyond the 60 degree tilt limit
    ],
)
def test_tracked_volume_and_tilt_limit(position: tuple[float, float, float], tilt_deg: float,
                                       tracked: bool) -> None:
    lab = lab_with()
    q = Rotation.from_euler("X", tilt_deg, degrees=True).as_quat(scalar_first=True)
    lab.place(position, quaternion=q)
    lab.advance(0.0051)
    assert lab.vicon_datagrams()[0].tracked is tracked


def test_noise_has_table_6_1_variances() -> None:
    lab = lab_with()
    lab.place((0.2, 0.1, 0.0), yaw=0.3)  # resting on the floor
    lab.advance(20.0)
    conv = FrameConversion.create()
    positions, quats = [], []
    for d in lab.vicon_datagrams():
        frame = decode_datagram(d.data)
        assert isinstance(frame, ViconFrame)
        obj = frame.objects[0]
        p, q = conv.to_ned(obj.translation, obj.rotation)
        positions.append(p)
        quats.append(q)
    positions_arr, quats_arr = np.array(positions), np.array(quats)
    assert len(positions_arr) == 2000
    np.testing.assert_allclose(positions_arr.mean(axis=0), [0.2, 0.1, 0.0], atol=1e-4)
    np.testing.assert_allclose(positions_arr.var(axis=0), [4.16e-7, 3.28e-9, 2.91e-7],
                               rtol=0.15)
    # q1..q3 keep their Table 6.1 noise; normalisation removes q0's to first order
    np.testing.assert_allclose(quats_arr[:, 1:].var(axis=0), [5.17e-6, 9.74e-6, 3.62e-6],
                               rtol=0.15)


def test_sender_and_ground_station_agree_on_frames_from_sim_yaml(repo: object) -> None:
    """The configured rotations (sim.yaml) round-trip through the ground station's reader."""
    config = load_config(f"{repo}/config/sim.yaml")
    params = LabParams.from_config(config)
    lab = VirtualLab(LabParams(vicon=ViconSimParams(
        noise=False, world_to_ned=params.vicon.world_to_ned,
        body_to_object=params.vicon.body_to_object)))
    q = Rotation.from_euler("ZYX", [-120.0, 20.0, 15.0], degrees=True).as_quat(scalar_first=True)
    lab.place((0.3, 0.4, -0.9), quaternion=q)
    frame = decode_datagram(first_datagram(lab))
    assert isinstance(frame, ViconFrame)
    obj = frame.find(config.vicon.object_name)
    assert obj is not None
    conv = FrameConversion.create(rotation_from_euler_deg(config.vicon.world_to_ned.euler_xyz_deg),
                                  rotation_from_euler_deg(config.vicon.body_to_object.euler_xyz_deg))
    p, q_back = conv.to_ned(obj.translation, obj.rotation)
    np.testing.assert_allclose(p, [0.3, 0.4, -0.9], atol=1e-12)
    np.testing.assert_allclose(q_back, q * math.copysign(1.0, q[0]), atol=1e-12)
