"""The virtual X-3D's radio: baud pacing, fault injection and determinism.

Expected rates come from the spec's frame arithmetic: a DATA frame is N + 11
bytes with N = 4 + the selected blocks (STATUS 4, GYRO 6, ACC 6, PRESSURE 4,
RC 10), a byte is 10 bits (8N1), and the UART sends one frame at a time, so a
sample every period T becomes one every ceil(frame_time / T) * T.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from groundstation.asctec.decoder import StreamDecoder
from groundstation.asctec.messages import CommandMsg, ConfigMsg, DataMsg
from sim_device import FaultParams, LabParams, LinkParams, VirtualLab

ALL_BLOCKS = 0x1F
ALL_BLOCKS_FRAME = 11 + 4 + 4 + 6 + 6 + 4 + 10  # 45 bytes (spec section 6)


def stream_start(baud: int = 57600) -> float:
    """Time of the first DATA tick: the 15-byte CONFIG's arrival (+20 ms delay), 2 ms grid."""
    return math.ceil((15 * 10 / baud + 0.020) / 0.002 - 1e-9) * 0.002


def streaming_lab(baud: int = 57600, mask: int = 0x07, period_ms: int = 10, seed: int = 4,
                  **faults: float) -> VirtualLab:
    lab = VirtualLab(LabParams(link=LinkParams(baud=baud), faults=FaultParams(**faults)),
                     seed=seed)
    lab.send(ConfigMsg(mask, period_ms))
    lab.advance(0.1)  # the stream is running
    return lab


@pytest.mark.parametrize("baud", [57600, 38400, 9600])
def test_baud_limits_the_data_rate(baud: int) -> None:
    lab = streaming_lab(baud=baud, mask=ALL_BLOCKS)
    frames = lab.advance(10.0)
    frame_time = ALL_BLOCKS_FRAME * 10 / baud  # 7.8 ms, 11.7 ms, 46.9 ms
    interval = math.ceil(frame_time / 0.010) * 0.010  # 10, 20, 50 ms
    assert len(frames) == pytest.approx(10.0 / interval, abs=1)
    gaps = np.diff([t for t, _ in frames])
    np.testing.assert_allclose(gaps, interval, atol=1e-9)
    # each frame arrives its transmission time after its sample tick (10 ms grid)
    offsets = (np.array([t for t, _ in frames]) - stream_start(baud) - frame_time) / 0.010
    np.testing.assert_allclose(offsets, np.round(offsets), atol=1e-6)
    assert all(len(f) == ALL_BLOCKS_FRAME for _, f in frames)


def test_fitting_selection_keeps_full_rate_at_low_baud() -> None:
    lab = streaming_lab(baud=9600, mask=0x06)  # GYRO + ACC: 27 bytes = 28 ms at 9600 baud
    frames = lab.advance(3.0)
    assert len(frames) == pytest.approx(3.0 / 0.030, abs=1)


@pytest.mark.slow
def test_dropped_frames_leave_counter_gaps() -> None:
    lab = streaming_lab(drop_rate=0.3)
    before = lab.stats()
    counters = [m.counter for _, m in lab.advance_messages(20.0)]
    stats = lab.stats()
    lost = int(np.sum(np.diff(counters) - 1))
    assert lost > 0
    sent_in_window = counters[-1] - counters[0] + 1
    assert lost / sent_in_window == pytest.approx(0.3, abs=0.03)  # 2000 frames: 3.5 sigma
    assert len(counters) + stats.data_dropped - before.data_dropped == (
        stats.data_sent - before.data_sent)


@pytest.mark.slow
def test_byte_corruption_rate_matches_rejected_frames() -> None:
    p = 2e-3
    lab = streaming_lab(corruption_rate=p)
    frames = lab.advance(30.0)
    bad = 0
    for _, data in frames:
        decoded = StreamDecoder().feed(data)
        if not (len(decoded) == 1 and isinstance(decoded[0], DataMsg)):
            bad += 1
    n = len(frames)
    expected = 1.0 - (1.0 - p) ** 31  # 31-byte frames (STATUS+GYRO+ACC)
    sigma = math.sqrt(n * expected * (1 - expected))
    assert abs(bad - n * expected) < 4 * sigma
    assert bad > 0


def test_corruption_also_hits_commands() -> None:
    lab = streaming_lab(corruption_rate=1.0)  # every byte flipped: nothing valid arrives
    for _ in range(20):
        lab.send(CommandMsg(thrust=1000, ctrl=0x0F))
        lab.advance(0.02)
    assert lab.stats().commands == 0
    assert lab.truth.ctrl_mask == 0


def test_stall_stops_the_stream_for_its_duration() -> None:
    lab = streaming_lab()
    frames = lab.advance(0.9)
    lab.stall_data(0.5)
    t = np.array([t for t, _ in frames + lab.advance(2.0)])
    gap = np.diff(t).max()
    assert gap == pytest.approx(0.51, abs=1e-6)  # the last sample before plus 50 missing ones
    assert lab.stats().samples_stalled == 50


def test_configured_stall() -> None:
    lab = streaming_lab(stall_at=1.0, stall_duration=0.3)
    t = np.array([t for t, _ in lab.advance(2.0)])
    assert t[0] < 1.0 < t[-1]
    assert np.diff(t).max() == pytest.approx(0.31, abs=1e-6)


def test_bursty_and_delayed_delivery() -> None:
    lab = streaming_lab(burst_delay_s=0.1)
    t = np.array([t for t, _ in lab.advance(2.0)])
    np.testing.assert_allclose(t / 0.1, np.round(t / 0.1), atol=1e-9)
    assert len(t) == pytest.approx(200, abs=10)
    lab.set_faults(burst_delay_s=0.0, data_delay=0.05)
    lab.advance(0.2)
    t = np.array([t for t, _ in lab.advance(1.0)])
    # sample on the 10 ms grid + 31-byte frame time + 50 ms
    offsets = (t - stream_start() - 31 * 10 / 57600 - 0.05) / 0.010
    np.testing.assert_allclose(offsets, np.round(offsets), atol=1e-6)


def _run(seed: int) -> tuple[list[bytes], list[bytes]]:
    lab = VirtualLab(LabParams(faults=FaultParams(corruption_rate=1e-3, drop_rate=0.05)),
                     seed=seed)
    lab.send(ConfigMsg(ALL_BLOCKS, 10))
    out = []
    for _ in range(100):
        lab.send(CommandMsg(roll=100, thrust=2300, ctrl=0x0F))
        out += [data for _, data in lab.advance(0.02)]
    return out, [d.data for d in lab.vicon_datagrams()]


def test_same_seed_same_bytes_other_seed_other_bytes() -> None:
    serial_a, vicon_a = _run(5)
    serial_b, vicon_b = _run(5)
    serial_c, vicon_c = _run(6)
    assert serial_a == serial_b and vicon_a == vicon_b
    assert serial_a != serial_c and vicon_a != vicon_c
