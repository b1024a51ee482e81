"""PoseFilter: frame-number bookkeeping, lost-tracking encodings, outlier gate, health.

Sans-IO: datagrams are built with encode_datagram (its bytes are checked against
the spec in test_vicon_decoder.py) and fed with simulated receive times.
Expected values come from the rules in spec/vicon-udp.md and the filter's
documented defaults.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import pytest
import structlog
from hypothesis import given, settings
from hypothesis import strategies as st
from structlog.testing import capture_logs

from groundstation.errors import ConfigError
from groundstation.types import Pose
from groundstation.vicon.decoder import ObjectPose, encode_datagram
from groundstation.vicon.plausibility import DEFAULT_VOLUME
from groundstation.vicon.posefilter import PoseFilter

NAME = "quad"
# A plausible tilted pose 1 m up: Vicon (mm, Euler XYZ rad); NED = (0.1, -0.2, -1.0).
TRANSLATION = (100.0, 200.0, 1000.0)
ROTATION = (0.05, -0.03, 0.4)


def obj(
    translation: Sequence[float] = TRANSLATION,
    rotation: Sequence[float] = ROTATION,
    name: str = NAME,
) -> ObjectPose:
    return ObjectPose(name, tuple(translation), tuple(rotation))  # type: ignore[arg-type]


def feed(f: PoseFilter, frame: int, t: float, *objects: ObjectPose) -> Pose | None:
    return f.process(encode_datagram(frame, objects or (obj(),)), t)


def moving(i: int, speed_mm_per_frame: float = 5.0) -> ObjectPose:
    """Frame i of a smooth 0.5 m/s motion at 100 Hz (5 mm per frame along Vicon x)."""
    return obj((TRANSLATION[0] + speed_mm_per_frame * i, TRANSLATION[1], TRANSLATION[2]))


def started(f: PoseFilter, n: int = 3) -> float:
    """Feed ``n`` poses of the smooth motion at 100 Hz (frames 1..n); the last is accepted.
    Returns its receive time [s]."""
    for i in range(1, n + 1):
        pose = feed(f, i, i * 0.01, moving(i))
    assert pose is not None
    return n * 0.01


def confirmed(f: PoseFilter, frame: int, t: float, *objects: ObjectPose) -> Pose | None:
    """Feed the same datagram content as frames ``frame - 2 .. frame`` at 100 Hz ending at
    ``t``: the default ``reanchor_poses`` (3) consistent poses; the result of the last."""
    assert feed(f, frame - 2, t - 0.02, *objects) is None
    assert feed(f, frame - 1, t - 0.01, *objects) is None
    return feed(f, frame, t, *objects)


def test_a_pose_is_converted_and_stamped() -> None:
    f = PoseFilter(NAME, latency_s=0.004)
    pose = confirmed(f, 17, 10.0)
    assert pose is not None
    assert pose.t == pytest.approx(10.0 - 0.004)  # receive time minus configured latency
    assert pose.frame == 17
    np.testing.assert_allclose(pose.position, [0.1, -0.2, -1.0])  # default C_wn = diag(1,-1,-1)
    assert pose.quaternion[0] > 0
    assert f.health(10.0).poses == 1


def test_other_objects_are_ignored() -> None:
    f = PoseFilter(NAME)
    pose = confirmed(f, 3, 0.0, obj((9.0, 9.0, 9.0), name="wand"), obj(), obj(name="quad2"))
    assert pose is not None
    np.testing.assert_allclose(pose.position, [0.1, -0.2, -1.0])


# --- frame numbers ------------------------------------------------------------


def test_gaps_duplicates_and_reordering() -> None:
    f = PoseFilter(NAME)
    t = 0.0
    accepted = []
    # frames 1, 2 (not yet confirmed), 5 (gap of 2), 5 (duplicate), 4 (late), 6, 10 (gap of 3)
    for frame in (1, 2, 5, 5, 4, 6, 10):
        t += 0.01
        accepted.append(feed(f, frame, t, moving(frame)) is not None)
    assert accepted == [False, False, True, False, False, True, True]
    h = f.health(t)
    assert (h.frames_dropped, h.duplicates, h.reordered, h.restarts) == (5, 1, 1, 0)
    assert (h.poses, h.unconfirmed) == (3, 2)


def test_restart_after_large_backward_jump() -> None:
    f = PoseFilter(NAME, restart_backjump_frames=1000)
    assert confirmed(f, 50_000, 0.00) is not None
    assert feed(f, 49_000, 0.01) is None  # jump of exactly 1000: still "old"
    assert feed(f, 48_999, 0.02) is not None  # 1001 back: a Tracker restart
    assert feed(f, 49_000, 0.03) is not None  # and counting continues from there
    h = f.health(0.03)
    assert (h.restarts, h.reordered, h.frames_dropped) == (1, 1, 0)


def test_restart_after_silence_and_uint32_wrap() -> None:
    f = PoseFilter(NAME, restart_silence_s=1.0)
    assert confirmed(f, 500, 0.0) is not None
    assert feed(f, 400, 0.9) is None  # 0.9 s silence: just reordered
    assert feed(f, 400, 2.0) is None  # 2 s since the last frame: a restart, but after a gap
    assert feed(f, 401, 2.01) is None  # the stream is believed again after three poses
    assert feed(f, 402, 2.02) is not None
    assert feed(f, 2**31, 2.03) is not None  # neither ahead nor behind: a restart
    h = f.health(2.03)
    assert (h.restarts, h.reordered, h.frames_dropped) == (2, 1, 0)
    wrap = PoseFilter(NAME)
    assert confirmed(wrap, 2**32 - 1, 0.0) is not None
    assert feed(wrap, 0, 0.01) is not None  # uint32 wrap-around: the next frame
    assert feed(wrap, 2, 0.02) is not None
    h = wrap.health(0.02)
    assert (h.restarts, h.frames_dropped) == (0, 1)


def test_a_jump_no_elapsed_time_explains_is_a_restart_not_dropped_frames() -> None:
    f = PoseFilter(NAME)  # max_rate_hz 120: 10 ms explain 1.2 frames (+ 10 for bursts)
    assert confirmed(f, 100, 0.0) is not None
    assert feed(f, 112, 0.01) is not None  # 11 dropped: a burst after a stall
    assert feed(f, 1_000_000, 0.02) is not None  # no time for 999,887 frames: a restart
    assert feed(f, 1_000_240, 2.02) is None  # 2 s: 239 frames may have been lost, but after
    assert feed(f, 1_000_241, 2.03) is None  # a gap three poses in a row are needed
    assert feed(f, 1_000_242, 2.04) is not None
    h = f.health(2.04)
    assert (h.frames_dropped, h.restarts) == (11 + 239, 1)


# --- lost tracking --------------------------------------------------------------


def test_object_missing_is_no_measurement() -> None:
    f = PoseFilter(NAME)
    assert feed(f, 1, 0.0, obj(name="wand")) is None
    assert f.process(encode_datagram(2, []), 0.01) is None
    assert f.health(0.01).lost_missing == 2


def test_all_zero_pose_is_no_measurement() -> None:
    f = PoseFilter(NAME)
    assert confirmed(f, 3, 0.00) is not None
    assert feed(f, 4, 0.01, obj((0.0, 0.0, 0.0), (0.0, 0.0, 0.0))) is None
    assert feed(f, 5, 0.02, obj((-0.0, 0.0, 0.0), (0.0, -0.0, 0.0))) is None
    h = f.health(0.02)
    assert (h.lost_zero, h.lost_held_identity, h.poses) == (2, 0, 1)


def test_held_position_with_identity_rotation_is_no_measurement() -> None:
    # Thesis Ch. 7.3.1: position kept at its last value, orientation reset.
    f = PoseFilter(NAME)
    assert confirmed(f, 3, 0.00) is not None
    assert feed(f, 4, 0.01, obj(TRANSLATION, (0.0, 0.0, 0.0))) is None
    assert feed(f, 5, 0.02, obj(TRANSLATION, (0.0, 0.0, 0.0))) is None
    assert feed(f, 6, 0.03) is not None  # tracking back
    h = f.health(0.03)
    assert (h.lost_held_identity, h.lost_zero, h.poses) == (2, 0, 2)


def test_identity_rotation_without_history_is_held_back_then_taken_back() -> None:
    # A first item with rotation exactly 0 may be a level vehicle facing Vicon's x (held
    # back like any first pose); the same values again make both held-identity lost
    # tracking, the first one taken back from the unconfirmed.
    f = PoseFilter(NAME)
    assert feed(f, 1, 0.0, obj(TRANSLATION, (0.0, 0.0, 0.0))) is None
    h = f.health(0.0)
    assert (h.lost_held_identity, h.unconfirmed) == (0, 1)
    assert feed(f, 2, 0.01, obj(TRANSLATION, (0.0, 0.0, 0.0))) is None
    h = f.health(0.01)
    assert (h.lost_held_identity, h.unconfirmed) == (2, 0)


def test_identity_rotation_with_a_new_position_is_a_measurement() -> None:
    # Only *held* position + identity is the lost encoding; a moving level vehicle
    # facing Vicon +x really reads rotations (0, 0, 0).
    f = PoseFilter(NAME)
    assert confirmed(f, 3, 0.00, obj(TRANSLATION, (0.01, 0.0, 0.0))) is not None
    pose = feed(f, 4, 0.01, obj((101.0, 200.0, 1000.0), (0.0, 0.0, 0.0)))
    assert pose is not None
    np.testing.assert_array_equal(pose.quaternion, [1.0, 0.0, 0.0, 0.0])


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_non_finite_values_are_no_measurement(bad: float) -> None:
    f = PoseFilter(NAME)
    assert feed(f, 1, 0.0, obj((bad, 0.0, 1000.0))) is None
    assert feed(f, 2, 0.01, obj(TRANSLATION, (0.1, bad, 0.0))) is None
    assert f.health(0.01).non_finite == 2


def test_malformed_datagram_is_counted() -> None:
    f = PoseFilter(NAME)
    assert f.process(b"\x01\x00", 0.0) is None
    assert f.process(encode_datagram(1, [obj()], pad_to=None)[:-8], 0.01) is None
    h = f.health(0.01)
    assert h.rejected == {"short_header": 1, "item_header_truncated": 0, "item_data_truncated": 1}
    assert h.rejected_datagrams == 2
    assert h.datagrams == 2


# --- plausibility gate ----------------------------------------------------------


def test_position_gate_boundary() -> None:
    # limit: |dp| <= max_speed * dt + slack = 5 m/s * 0.01 s + 0 = 50 mm
    f = PoseFilter(NAME, latency_s=0.0, position_slack=0.0, max_speed=5.0)
    assert confirmed(f, 3, 0.00, obj((0.0, 0.0, 1000.0))) is not None
    assert feed(f, 4, 0.01, obj((51.0, 0.0, 1000.0))) is None
    assert feed(f, 5, 0.02, obj((0.0, 0.0, 1000.0 - 99.0))) is not None  # 99 mm in 20 ms
    assert f.health(0.02).outliers == 1


def test_rotation_gate_boundary() -> None:
    # limit: angle <= 30 rad/s * 0.01 s + 0 = 0.3 rad (rotation about one axis: angle = |rz|)
    f = PoseFilter(NAME, latency_s=0.0, angle_slack=0.0)
    assert confirmed(f, 3, 0.00, obj(TRANSLATION, (0.0, 0.0, 0.1))) is not None
    assert feed(f, 4, 0.01, obj(TRANSLATION, (0.0, 0.0, 0.41))) is None  # 0.31 rad
    assert feed(f, 5, 0.02, obj(TRANSLATION, (0.0, 0.0, 0.69))) is not None  # 0.59 rad in 20 ms
    # 0.69 -> -pi + 0.1 is 2 pi - 3.73 = 2.55 rad the short way round: rejected.
    assert feed(f, 6, 0.03, obj(TRANSLATION, (0.0, 0.0, -math.pi + 0.1))) is None
    assert f.health(0.03).outliers == 2


def test_rotation_gate_uses_the_short_way_round() -> None:
    f = PoseFilter(NAME, latency_s=0.0, angle_slack=0.0)
    assert confirmed(f, 3, 0.00, obj(TRANSLATION, (0.0, 0.0, math.pi - 0.1))) is not None
    assert feed(f, 4, 0.01, obj(TRANSLATION, (0.0, 0.0, -math.pi + 0.1))) is not None  # 0.2 rad


def test_outlier_does_not_move_the_anchor() -> None:
    f = PoseFilter(NAME)
    for i in range(5):
        assert (feed(f, i, i * 0.01, moving(i)) is not None) == (i >= 2)
    assert feed(f, 5, 0.05, obj((1100.0, 0.0, 1000.0))) is None  # 1 m jump in 10 ms
    assert feed(f, 6, 0.06, moving(6)) is not None
    assert f.health(0.06).outliers == 1


def test_a_consistent_new_stream_is_taken_after_reanchor_poses() -> None:
    # The first stream is wrong (a reflection elsewhere); the real vehicle is 2 m away and
    # far beyond the speed limit. Its poses agree with each other: once three have, they
    # pass (the estimator sorts two senders out), and from then on every one does.
    f = PoseFilter(NAME, reanchor_after_s=0.5, max_speed=1.0)
    assert confirmed(f, 3, 0.0) is not None
    far = obj((TRANSLATION[0] - 2000.0, TRANSLATION[1], TRANSLATION[2]))
    results = [feed(f, 3 + i, i * 0.01, far) for i in range(1, 100)]
    assert [r is not None for r in results] == [False, False] + [True] * 97
    h = f.health(1.0)
    assert (h.reanchors, h.outliers, h.unconfirmed) == (1, 1, 1 + 2)


def test_gate_after_lost_tracking_allows_motion_in_proportion_to_time() -> None:
    f = PoseFilter(NAME, reanchor_after_s=10.0, position_slack=0.0)
    assert confirmed(f, 2, 0.0, obj((0.0, 0.0, 1000.0))) is not None
    for i in range(1, 40):  # 0.39 s without the object
        assert feed(f, 2 + i, i * 0.01, obj(name="other")) is None
    # 1.5 m after 0.4 s is 3.75 m/s: plausible.
    assert feed(f, 42, 0.40, obj((1500.0, 0.0, 1000.0))) is not None
    assert f.health(0.4).outliers == 0


# --- health ------------------------------------------------------------------


def test_rate_and_time_since_pose() -> None:
    f = PoseFilter(NAME)
    for i in range(200):  # 100 Hz for 2 s
        feed(f, i, i * 0.01, moving(i))
    h = f.health(1.995)
    assert h.rate_hz == pytest.approx(100.0)  # 100 poses in (0.995, 1.995]
    assert h.time_since_pose_s == pytest.approx(0.005)
    assert h.rate_in_band
    later = f.health(3.0)
    assert later.rate_hz == 0.0
    assert later.time_since_pose_s == pytest.approx(1.01)


def test_no_pose_yet() -> None:
    f = PoseFilter(NAME)
    h = f.health(5.0)
    assert h.time_since_pose_s == math.inf
    assert h.rate_hz == 0.0
    assert h.poses == 0


def test_rate_warning_is_rate_limited_and_recovers() -> None:
    with capture_logs() as logs:
        f = PoseFilter(NAME, min_rate_hz=8.0, max_rate_hz=120.0, warn_interval_s=5.0)
        for i in range(20):  # 1 Hz for 20 s
            feed(f, i, float(i), moving(i, 0.0))
        low = f.health(19.5)
        warnings = [e for e in logs if e["event"] == "vicon_rate_out_of_band"]
        # One warning per 5 s while out of band (t = 1, 6, 11, 16), not one per datagram;
        # the first before any pose passed (three are needed), the later ones at 1 Hz.
        assert len(warnings) == 4
        assert warnings[0]["log_level"] == "warning"
        assert warnings[-1]["rate_hz"] == pytest.approx(1.0)
        assert low.rate_warnings == 4
        assert not low.rate_in_band
        for i in range(20, 220):  # back to 100 Hz
            feed(f, i, 19.0 + (i - 19) * 0.01, moving(i, 0.0))
        assert f.health(21.0).rate_in_band
        assert [e["event"] for e in logs].count("vicon_rate_recovered") == 1


def test_rate_warning_when_datagrams_stop_and_not_during_first_window() -> None:
    with capture_logs() as logs:
        f = PoseFilter(NAME, warn_interval_s=5.0)
        f.health(100.0)
        f.health(100.9)  # within the first rate window: no verdict yet
        assert logs == []
        f.health(101.0)  # a full second without any datagram
        assert [e["event"] for e in logs] == ["vicon_rate_out_of_band"]


def test_custom_logger_receives_the_warning() -> None:
    with capture_logs() as logs:
        log = structlog.get_logger("test").bind(vehicle="x3d")
        f = PoseFilter(NAME, logger=log)
        f.health(0.0)
        f.health(2.0)
    assert logs[0]["vehicle"] == "x3d"


@pytest.mark.parametrize(
    "kwargs",
    [
        {"max_speed": -1.0},
        {"latency_s": math.nan},
        {"reanchor_after_s": -0.1},
        {"min_rate_hz": 10.0, "max_rate_hz": 5.0},
        {"rate_window_s": 0.0},
        {"world_to_ned": np.diag([1.0, 1.0, -1.0])},
    ],
)
def test_invalid_parameters_are_refused_at_construction(kwargs: dict[str, object]) -> None:
    with pytest.raises(ConfigError):
        PoseFilter(NAME, **kwargs)  # type: ignore[arg-type]


def test_empty_name_is_refused() -> None:
    with pytest.raises(ConfigError, match="invalid Vicon parameters"):
        PoseFilter("")


def test_from_lab_config() -> None:
    # config/lab.yaml: Rx(180 deg) for both rotations, 8 Hz minimum, 100 Hz expected.
    from groundstation.config import load_config
    from groundstation.flight.assembly import vicon_params

    lab = load_config("config/lab.yaml")
    cfg = lab.vicon
    f = PoseFilter.from_params(vicon_params(cfg, lab.safety).filter)
    assert f.object_name == cfg.object_name
    np.testing.assert_allclose(f.frames.world_to_ned, np.diag([1.0, -1.0, -1.0]), atol=1e-15)
    np.testing.assert_allclose(f.frames.body_to_object, np.diag([1.0, -1.0, -1.0]), atol=1e-15)
    assert (f.latency_s, f.max_speed, f.max_rotation_rate) == (
        cfg.latency_s,
        cfg.max_speed_m_s,
        cfg.max_rotation_rate_rad_s,
    )
    assert f.restart_backjump_frames == cfg.restart_backjump_frames
    assert f.rate.min_rate_hz == 8.0
    assert f.rate.max_rate_hz == pytest.approx(1.2 * 100.0)  # MAX_RATE_FACTOR * expected rate
    # safety.volume_x/y/z (Table B.1) grown by vicon.plausibility_margin_m (0.5 m)
    assert f.plausibility.volume == ((-2.0, 2.0), (-2.0, 2.0), (-2.5, 0.55))
    assert f.reanchor_poses == cfg.reanchor_poses == 3
    pose = confirmed(f, 3, 1.0, obj(name=cfg.object_name))
    assert pose is not None
    np.testing.assert_allclose(pose.position, [0.1, -0.2, -1.0], atol=1e-15)


def test_default_volume_is_the_configured_one() -> None:
    from groundstation.config import SafetyConfig, ViconConfig
    from groundstation.flight.assembly import plausible_volume

    assert plausible_volume(ViconConfig(), SafetyConfig()) == DEFAULT_VOLUME
    assert PoseFilter(NAME).plausibility.volume == DEFAULT_VOLUME
    with pytest.raises(ConfigError):
        PoseFilter(NAME, plausible_volume=((0.0, 0.0), (-1.0, 1.0), (-1.0, 1.0)))
    with pytest.raises(ConfigError, match="invalid Vicon parameters"):
        PoseFilter(NAME, reanchor_poses=1)  # never one pose


def test_rate_and_age_is_the_health_subset() -> None:
    """The per-tick accessor agrees with the full health snapshot."""
    filt = PoseFilter("X3D")
    for k in range(30):
        pose = ObjectPose("X3D", (1.0 + k, 2.0, 1000.0), (0.01 * k, 0.02, 0.03))
        filt.process(encode_datagram(k + 1, [pose]), 0.01 * k)
    now = 0.4
    rate, age = filt.rate_and_age(now)
    health = filt.health(now)
    assert (rate, age) == (health.rate_hz, health.time_since_pose_s)
    assert rate == pytest.approx(28.0) and age == pytest.approx(0.11)  # 2 to confirm


# --- hostile input ---------------------------------------------------------


ABSURD = [
    obj((1e300, 200.0, 1000.0)),  # the hostile tester's x = 1e300 mm
    obj((100.0, -1e308, 1000.0)),
    obj((100.0, 200.0, 5e-324 + 1e30)),
    obj((100_000.0, 200.0, 1000.0)),  # finite but 100 m away
    # 11 m below the floor: beyond the sighting range (volume z <= 0.05 m + 0.5 m margin
    # + 10 m); 0.6 m below is a sighting outside the volume (test_vicon_evidence.py)
    obj((100.0, 200.0, -11_000.0)),
    obj(TRANSLATION, (1e300, 0.0, 0.0)),  # an angle no Euler decomposition gives
    obj(TRANSLATION, (0.1, -7.0, 0.2)),  # more than a turn
]


@pytest.mark.filterwarnings("error::RuntimeWarning")
@pytest.mark.parametrize("bad", ABSURD, ids=lambda o: f"{o.translation}-{o.rotation}")
def test_implausible_values_are_refused_after_a_gap_and_at_start_up(bad: ObjectPose) -> None:
    """A Vicon gap of 1.5 s, then 99 datagrams of an absurd pose of the tracked
    object. None is accepted (the old gate re-anchored on any pose after 0.5 s), none warns,
    and the real stream is taken again once it returns."""
    f = PoseFilter(NAME)
    assert feed(f, 1, 0.0, bad) is None  # at start-up, too
    t = started(f) + 1.5
    for k in range(99):
        assert feed(f, 200 + k, t + k * 0.015, bad) is None
    t += 1.5
    back = [feed(f, 400 + k, t + k * 0.01, moving(4 + k)) for k in range(3)]
    assert back == [None, None, back[-1]] and back[-1] is not None
    h = f.health(t)
    assert h.implausible_position + h.implausible_rotation == 100
    assert h.reanchors == 1 and h.poses == 2


def test_a_single_pose_after_a_gap_is_never_taken() -> None:
    """After a gap, one pose (even one within the speed limit) is not enough;
    ``reanchor_poses`` (3) consecutive consistent ones are."""
    f = PoseFilter(NAME, reanchor_poses=3)
    t = started(f) + 1.5
    jumped = obj((TRANSLATION[0] + 1000.0, TRANSLATION[1], TRANSLATION[2]))  # 1 m away
    assert feed(f, 200, t, jumped) is None
    assert feed(f, 201, t + 0.01, moving(201, 0.0)) is None  # back: disagrees with the jump
    assert feed(f, 202, t + 0.02, moving(202, 0.0)) is None  # two agree
    assert feed(f, 203, t + 0.03, moving(203, 0.0)) is not None  # three agree
    assert feed(f, 204, t + 0.04, moving(204, 0.0)) is not None
    assert f.health(t).reanchors == 1


def test_scattered_poses_never_anchor() -> None:
    """Poses of which no two in a row agree (each 0.3 m from the last within 10 ms, round
    the volume) are never taken, at start-up or after a gap."""
    f = PoseFilter(NAME)
    for k in range(200):
        x = -1500.0 + 300.0 * (k % 10)
        assert feed(f, k + 1, k * 0.01, obj((x, 0.0, 1000.0))) is None
    assert f.health(2.0).poses == 0


def test_a_second_consistent_stream_is_a_rival_and_never_blinds() -> None:
    """A second sender of the tracked object's name beside the real one: the stream that
    was there first stays followed, every pose of it passes; the other's poses, once
    ``reanchor_poses`` of them agree, are a rival's: counted, never passed on."""
    f = PoseFilter(NAME)
    t = started(f)
    other = obj((TRANSLATION[0] + 300.0, TRANSLATION[1], TRANSLATION[2]))  # 30 cm away
    real, foreign = [], []
    for k in range(20):
        real.append(feed(f, 10 + k, t + 0.01 * (k + 1), moving(10 + k, 0.0)))
        foreign.append(feed(f, 5000 + k, t + 0.01 * (k + 1) + 0.005, other))
    assert all(p is not None for p in real)
    assert all(p is None for p in foreign)
    h = f.health(t + 0.2)
    assert (h.duplicates, h.reordered, h.frames_dropped) == (0, 0, 6)  # 3 .. 10: six lost
    assert (h.rivals, h.rival_events, h.rival_poses, h.outliers, h.unconfirmed) == (
        1, 1, 18, 1, 2 + 1)  # 2 at start-up, the rival's second pose


def test_foreign_items_and_poseless_datagrams_never_touch_the_frame_numbers() -> None:
    """Another object's items, datagrams without a usable pose of ours and absurd
    poses of ours, all 500 frames ahead, beside the real stream: the real stream is never
    taken for duplicates or reordered datagrams (the old bookkeeping dropped it for 5 s)."""
    f = PoseFilter(NAME)
    t = started(f)
    foreign = [
        (obj(name="wand"),),
        (),
        (obj((0.0, 0.0, 0.0), (0.0, 0.0, 0.0)),),  # lost tracking (all zero)
        (obj((math.nan, 0.0, 1000.0)),),
        (obj((1e300, 0.0, 1000.0)),),
    ]
    accepted = []
    for k in range(4, 104):
        accepted.append(feed(f, k, t + 0.01 * k, moving(k)) is not None)
        f.process(encode_datagram(k + 500, foreign[k % len(foreign)]), t + 0.01 * k + 0.005)
    assert all(accepted)
    h = f.health(t + 1.1)
    assert (h.frames_dropped, h.duplicates, h.reordered, h.restarts) == (0, 0, 0, 0)
    assert h.lost_missing == 40 and h.lost_zero == 20 and h.non_finite == 20


def test_garbage_frame_numbers_neither_inflate_counters_nor_blind() -> None:
    """The tracked object's (plausible) pose with garbage frame numbers: near
    2**32, and 500 ahead. A jump that no elapsed time explains is a restart (or garbage),
    never billions of dropped frames, and the real stream goes on within a few frames."""
    f = PoseFilter(NAME)
    t = started(f)
    taken = []
    for k in range(4, 204):
        taken.append(feed(f, k, t + 0.01 * k, moving(k)) is not None)
        if k in (50, 51, 120):
            garbage = 2**32 - 7 if k != 120 else k + 500
            feed(f, garbage, t + 0.01 * k + 0.005, moving(k))
    h = f.health(t + 2.1)
    assert h.frames_dropped < 10  # was 2**32 - 7 - 50 - 1
    assert taken.count(False) <= 2 * (f.reanchor_poses - 1)  # never blinded for long
    assert h.restarts <= 6


@pytest.mark.slow
@pytest.mark.filterwarnings("error::RuntimeWarning")
@settings(max_examples=300, deadline=None)
@given(
    frame=st.integers(0, 2**32 - 1),
    values=st.lists(st.floats(allow_nan=True, allow_infinity=True, width=64), min_size=6,
                    max_size=6),
    name=st.sampled_from([NAME, "wand"]),
)
def test_no_datagram_raises_warns_or_leaves_the_volume(frame: int, values: list[float],
                                                       name: str) -> None:
    """Property: any datagram after a healthy start neither raises nor warns; what it
    yields is a pose inside the plausible volume with a unit quaternion, or nothing."""
    f = PoseFilter(NAME)
    t = started(f)
    x, y, z, rx, ry, rz = values
    item = ObjectPose(name, (x, y, z), (rx, ry, rz))
    for k in range(3):
        pose = f.process(encode_datagram(frame, [item]), t + 0.01 * k)
        if pose is not None:
            assert np.all(np.abs(pose.position[:2]) <= 2.0)
            assert -2.5 <= pose.position[2] <= 0.55
            assert abs(float(np.dot(pose.quaternion, pose.quaternion)) - 1.0) < 1e-9
    assert f.health(t).frames_dropped < 1000
