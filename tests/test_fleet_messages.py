"""The fleet's binary messages: round trips over their whole ranges, and every wrong
length, version or value refused as a ProtocolError (bad bytes are data)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from groundstation.errors import ProtocolError
from groundstation.fleet.messages import (
    BOOT_ID,
    MAX_INTENT_POINTS,
    VERSION,
    Intent,
    PeerPose,
    RelayedPose,
)

finite = st.floats(allow_nan=False, allow_infinity=False)
any_float = st.floats(allow_nan=True, allow_infinity=True)
triple = st.tuples(any_float, any_float, any_float)


@given(st.integers(0, 2**32 - 1), st.integers(-2**63, 2**63 - 1),
       st.integers(-2**63, 2**63 - 1), st.binary(min_size=16, max_size=16), triple, triple)
def test_relayed_pose_round_trips(frame: int, t_rx: int, t_pub: int, boot: bytes,
                                  translation: tuple[float, float, float],
                                  rotation: tuple[float, float, float]) -> None:
    message = RelayedPose(frame, t_rx, t_pub, boot, translation, rotation)
    back = RelayedPose.unpack(message.pack())
    assert back.frame == frame and back.boot == boot
    assert (back.t_receive_ns, back.t_publish_ns) == (t_rx, t_pub)
    for a, b in zip((*back.translation, *back.rotation), (*translation, *rotation),
                    strict=True):
        assert a == b or (math.isnan(a) and math.isnan(b))


@given(st.integers(0, 255), st.integers(0, 2**32 - 1), triple,
       st.tuples(any_float, any_float, any_float, any_float), triple)
def test_peer_pose_round_trips(state: int, seq: int, p: tuple[float, float, float],
                               q: tuple[float, float, float, float],
                               v: tuple[float, float, float]) -> None:
    back = PeerPose.unpack(PeerPose(state, seq, p, q, v).pack())
    assert (back.state, back.seq) == (state, seq)
    assert back.known == all(math.isfinite(x) for x in p)
    assert np.array_equal(np.array(back.position), np.array(p), equal_nan=True)


@given(st.integers(0, 2**32 - 1), st.floats(0.0, 10.0),
       st.lists(st.tuples(finite, finite, finite), max_size=50))
def test_intent_round_trips(seq: int, step: float,
                            points: list[tuple[float, float, float]]) -> None:
    message = Intent(seq, step, np.array(points, dtype=float).reshape(-1, 3))
    back = Intent.unpack(message.pack())
    assert back.seq == seq and back.step_m == step
    assert np.array_equal(back.points, message.points)


def test_wrong_bytes_are_refused() -> None:
    good = RelayedPose(1, 2, 3, BOOT_ID, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0)).pack()
    for bad in (b"", good[:-1], good + b"\0", bytes([VERSION + 1]) + good[1:]):
        with pytest.raises(ProtocolError):
            RelayedPose.unpack(bad)
    pose = PeerPose(2, 1, (0.0, 0.0, -1.0), (1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0)).pack()
    with pytest.raises(ProtocolError):
        PeerPose.unpack(pose[:-8])
    intent = Intent(1, 0.1, np.zeros((3, 3))).pack()
    for bad in (intent[:-1], intent[:10], bytes([9]) + intent[1:],
                Intent(1, 0.1, np.array([[math.nan, 0.0, 0.0]])).pack(),
                Intent(1, math.inf, np.zeros((1, 3))).pack()):
        with pytest.raises(ProtocolError):
            Intent.unpack(bad)
    with pytest.raises(ProtocolError):
        Intent(1, 0.0, np.zeros((MAX_INTENT_POINTS + 1, 3))).pack()
    assert len(good) == RelayedPose.STRUCT.size == 88 and len(pose) == 88
