"""Vicon streams of any honest character, and the evidence beyond the poses.

Datagrams are packed here by hand with ``struct``, byte for byte as the spec
(``spec/vicon-udp.md``) lays them out and as other senders build them, never with the
project's encoder. Expected values are independent of the filter: NED positions are the
spec's conversion with the default rotations (x, -y, -z) / 1000, counts follow from the
sequence each test sends, rates from the number of poses in the 1 s window.

* a stream with noise-free angles (rotation exactly 0, position noisy) is accepted at
  1, 10 and 100 Hz within ``reanchor_poses`` poses;
* held-identity lost tracking (a held translation with rotation exactly 0) is refused
  at start-up and mid-stream, and a stream starting after it starts with its poses;
* a second sender of our object 0.5 m off is a rival: alarmed within a few poses, never
  passed on, and the rate stays the followed stream's;
* a vehicle walking out of the volume is a sighting outside it, not lost Vicon; a
  single absurd or jumping pose is neither;
* ``diagnosis()`` names each refusal with its count.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Sequence

import numpy as np
import pytest
from structlog.testing import capture_logs

from groundstation.types import Pose
from groundstation.vicon import PoseFilter, ViconEvidence

NAME = "X3D"
ZERO = (0.0, 0.0, 0.0)
HOVER_MM = (100.0, 200.0, 1000.0)  # Vicon (z up): NED (0.1, -0.2, -1.0) m
SIGMA_MM = math.sqrt(4.16e-7) * 1000.0  # Table 6.1, position x: 0.65 mm
ROT = (0.02, -0.01, 0.3)  # a real attitude, Euler XYZ [rad]

Item = tuple[str, Sequence[float], Sequence[float]]


def datagram(frame: int, *items: Item, pad_to: int = 1024) -> bytes:
    """One Tracker frame: uint32 frame, uint8 count, then per object item: uint8 id 0,
    uint16 size 72, char[24] name, 6 float64 (x, y, z [mm], rx, ry, rz [rad]); padded."""
    body = struct.pack("<IB", frame, len(items))
    for name, t, r in items:
        body += struct.pack("<BH24s6d", 0, 72, name.encode(), *t, *r)
    return body.ljust(pad_to, b"\0")


def ned(translation_mm: Sequence[float]) -> list[float]:
    """The spec's position conversion with C_wn = Rx(180 deg): (x, -y, -z) / 1000 [m]."""
    x, y, z = translation_mm
    return [x / 1000.0, -y / 1000.0, -z / 1000.0]


def noisy(rng: np.random.Generator, centre: Sequence[float] = HOVER_MM) -> tuple[float, ...]:
    return tuple(float(c) for c in np.asarray(centre) + rng.normal(0.0, SIGMA_MM, 3))


def send(f: PoseFilter, frame: int, t: float, *items: Item) -> Pose | None:
    return f.process(datagram(frame, *items), t)


# --- noise-free angles ------------------------------------------------------------------


@pytest.mark.parametrize("rate_hz", [1.0, 10.0, 100.0])
def test_noise_free_angles_are_accepted_within_reanchor_poses(rate_hz: float) -> None:
    """A simulator's sender: a level vehicle facing Vicon's x reports rotation exactly
    (0, 0, 0) while its position carries noise. It was taken for held-identity lost
    tracking at start-up, so no stream could ever start (preflight: Vicon at 0 Hz)."""
    rng = np.random.default_rng(1)
    f = PoseFilter(NAME)
    translations = [noisy(rng) for _ in range(20)]
    poses = [send(f, k + 1, k / rate_hz, (NAME, tr, ZERO)) for k, tr in enumerate(translations)]
    assert [p is not None for p in poses] == [False] * (f.reanchor_poses - 1) + [True] * (
        20 - f.reanchor_poses + 1)
    for pose, tr in zip(poses[2:], translations[2:], strict=True):
        assert pose is not None
        np.testing.assert_allclose(pose.position, ned(tr), rtol=0, atol=1e-12)
        np.testing.assert_array_equal(pose.quaternion, [1.0, 0.0, 0.0, 0.0])  # C_wn C_bo = I
    t_end = 19 / rate_hz
    h = f.health(t_end)
    assert (h.poses, h.unconfirmed, h.lost_held_identity, h.lost_zero) == (18, 2, 0, 0)
    evidence = f.evidence(t_end)
    assert evidence.last_position == pytest.approx(ned(translations[-1]), abs=1e-12)
    assert (evidence.last_age_s, evidence.outside, evidence.rivals) == (0.0, None, 0)


def test_a_stream_starting_while_occluded_starts_with_its_poses() -> None:
    """Held identity first (the object occluded since before the first datagram: its
    translation held, rotation exactly 0), then real poses near the held position. The
    stream starts ``reanchor_poses`` poses after the real ones: the held item that came
    first is taken back, and never counts towards them."""
    rng = np.random.default_rng(2)
    f = PoseFilter(NAME)
    held = [send(f, k + 1, 0.01 * k, (NAME, HOVER_MM, ZERO)) for k in range(20)]
    assert all(p is None for p in held)
    real = [send(f, 21 + k, 0.2 + 0.01 * k, (NAME, noisy(rng), (0.001, 0.0, 0.002)))
            for k in range(10)]
    assert [p is not None for p in real] == [False, False] + [True] * 8
    h = f.health(0.3)
    assert (h.lost_held_identity, h.unconfirmed, h.outliers, h.poses) == (20, 2, 0, 8)
    assert f.diagnosis() == (
        "30 datagrams, 8 poses of 'X3D' passed; refused: 20 held-identity lost tracking, "
        "2 unconfirmed")


def test_only_held_identity_is_all_refused_as_such() -> None:
    f = PoseFilter(NAME)
    for k in range(412):
        assert send(f, k + 1, 0.01 * k, (NAME, HOVER_MM, ZERO)) is None
    assert f.diagnosis() == (
        "412 datagrams, 0 poses of 'X3D' passed; refused: 412 held-identity lost tracking")


@pytest.mark.parametrize("rotation", [ROT, ZERO], ids=["real-angles", "noise-free-angles"])
def test_held_identity_mid_stream_is_still_refused(rotation: tuple[float, float, float]
                                                   ) -> None:
    """The thesis's lab (Ch. 7.3.1, Algorithm 2): on lost tracking the translation is held
    at its last value and the rotation reads exactly 0. Refused for as long as it lasts,
    whatever the angles read before; the stream goes on when tracking is back."""
    rng = np.random.default_rng(3)
    f = PoseFilter(NAME)
    last: tuple[float, ...] = ()
    for k in range(10):
        last = noisy(rng)
        send(f, k + 1, 0.01 * k, (NAME, last, rotation))
    lost = [send(f, 11 + k, 0.1 + 0.01 * k, (NAME, last, ZERO)) for k in range(30)]
    assert all(p is None for p in lost)
    back = send(f, 41, 0.4, (NAME, noisy(rng), rotation))
    assert back is not None  # 0.31 s after the last pose: no gap, no re-confirmation
    h = f.health(0.4)
    assert (h.lost_held_identity, h.poses, h.unconfirmed) == (30, 8 + 1, 2)


# --- a rival stream -------------------------------------------------------------------


def circle(t: float) -> tuple[float, float, float]:
    """The vehicle's true Vicon translation at ``t`` [s]: a 0.2 m circle at 0.5 rad/s [mm]."""
    return (HOVER_MM[0] + 200.0 * math.cos(0.5 * t), HOVER_MM[1] + 200.0 * math.sin(0.5 * t),
            HOVER_MM[2])


def test_a_forged_second_sender_is_a_rival_alarm_and_never_passed_on() -> None:
    """Tracker streams the vehicle at 100 Hz. From 1 s a forger sends our object 0.5 m off
    (following the vehicle, with noise and its own frame counter) between Tracker's frames
    for 2 s, stops for 1 s, and comes back for 0.5 s: two episodes."""
    rng = np.random.default_rng(4)
    real: list[tuple[Pose | None, tuple[float, ...]]] = []
    forged: list[Pose | None] = []
    raised_after: int | None = None
    attacks = [(1.0, 3.0), (4.0, 4.5)]
    seen: dict[str, ViconEvidence] = {}
    with capture_logs() as logs:
        f = PoseFilter(NAME)
        for k in range(520):  # 5.2 s at 100 Hz
            t = 0.01 * k
            tr = noisy(rng, circle(t))
            real.append((send(f, 1000 + k, t, (NAME, tr, ROT)), tr))
            if any(a <= t < b for a, b in attacks):
                off = noisy(rng, np.add(circle(t), (500.0, 0.0, 0.0)))
                forged.append(send(f, 70_000 + k, t + 0.005, (NAME, off, ROT)))
                if raised_after is None and f.evidence(t + 0.005).rivals:
                    raised_after = len(forged)
            if k == 250:  # 1.5 s into the first attack, between two frames
                seen["during"] = f.evidence(t + 0.0075)
                rate_during = f.health(t + 0.0075).rate_hz
            if k == 360:  # 0.6 s after the first attack
                seen["after"] = f.evidence(t)
        seen["end"] = f.evidence(5.19)  # 0.7 s after the second
    assert raised_after == f.reanchor_poses  # the alarm as soon as the rival is confirmed
    assert (seen["during"].rivals, seen["during"].rival_events) == (1, 1)
    assert (seen["after"].rivals, seen["after"].rival_events) == (0, 1)
    assert (seen["end"].rivals, seen["end"].rival_events) == (0, 2)
    assert rate_during == pytest.approx(100.0)  # the followed stream's, not 200 Hz
    assert all(p is None for p in forged)
    for pose, tr in real[2:]:  # every real pose passed, each the vehicle's own
        assert pose is not None
        np.testing.assert_allclose(pose.position, ned(tr), rtol=0, atol=1e-12)
    warnings = [e for e in logs if e["event"] == "vicon_rival_stream"]
    assert [(w["log_level"], w["episode"]) for w in warnings] == [("warning", 1),
                                                                  ("warning", 2)]
    assert warnings[0]["offset_m"] == pytest.approx(0.5, abs=0.01)
    h = f.health(5.19)
    assert (h.rival_events, h.rival_poses) == (2, (200 - 2) + (50 - 2))
    # the first forged pose agreed with no stream; a second later, the forged stream's
    # gate had grown enough to take the next attack's first pose (a gap: run 1 again)
    assert h.outliers == 1
    assert "246 from a rival stream" in f.diagnosis()


def test_one_sender_moving_on_to_a_new_stream_is_no_rival() -> None:
    """Tracker's stream stops and, 1 ms later, poses 30 cm off begin (one sender at a
    time: a jump, or a forger during a pause). The new stream is followed once confirmed;
    the old one, whose gate widens while it waits (5 m/s x 60 ms covers 30 cm), must not
    take the new poses back and pose as a rival of them: no alarm."""
    rng = np.random.default_rng(8)
    f = PoseFilter(NAME)
    for k in range(100):
        send(f, k + 1, 0.01 * k, (NAME, noisy(rng), ROT))
    moved = (HOVER_MM[0] + 300.0, HOVER_MM[1], HOVER_MM[2])
    taken = []
    for k in range(100):
        t = 1.0 + 0.001 + 0.01 * k
        taken.append(send(f, 5000 + k, t, (NAME, noisy(rng, moved), ROT)) is not None)
        assert f.evidence(t).rivals == 0
    assert taken == [False, False] + [True] * 98
    h = f.health(2.0)
    assert (h.rival_events, h.rival_poses, h.outliers) == (0, 0, 1)


def test_stray_poses_of_one_sender_are_no_rival() -> None:
    """Tracker's stream at 100 Hz; now and then one pose lands 1 m off at one spot (a
    reflection; the attitude snaps of a hard touchdown in the virtual lab were 0.27 s
    apart): three of them make a consistent, confirmed stream (no gap: each link under
    three times the one before). Its poses alternate with the vehicle's, but a stray
    pose makes two alternations, and two strays within 0.5 s are not a second sender:
    no alarm, never passed on."""
    rng = np.random.default_rng(10)
    f = PoseFilter(NAME)
    stray_at = {70: 0.705, 160: 1.605, 187: 1.875}
    far = (HOVER_MM[0] + 1000.0, HOVER_MM[1], HOVER_MM[2])
    strays, real = [], []
    for k in range(300):
        real.append(send(f, k + 1, 0.01 * k, (NAME, noisy(rng), ROT)))
        if k in stray_at:
            strays.append(send(f, k + 1, stray_at[k], (NAME, noisy(rng, far), ROT)))
    assert all(p is not None for p in real[2:]) and all(p is None for p in strays)
    h = f.health(3.0)
    assert (h.rival_events, h.rival_poses, h.outliers, h.unconfirmed) == (0, 0, 1, 2 + 2)


def test_a_mis_fit_of_a_few_frames_is_no_rival() -> None:
    """One sender, a mis-fit for five frames (the attitude flipped by pi about z): the
    consistent mis-fit takes over as a new stream would after the real one missed its
    poses (the estimator's gate is the judge of those), and the real stream takes over
    again when it returns; two alternations, never a rival."""
    rng = np.random.default_rng(11)
    f = PoseFilter(NAME)
    flipped = (ROT[0], ROT[1], ROT[2] - math.pi)
    passed = []
    for k in range(200):
        rotation = flipped if 100 <= k < 105 else ROT
        passed.append(send(f, k + 1, 0.01 * k, (NAME, noisy(rng), rotation)) is not None)
        assert f.evidence(0.01 * k).rivals == 0
    #  the mis-fit: outlier, unconfirmed, then followed; back: held back once, then followed
    assert passed[100:108] == [False, False, True, True, True, False, True, True]
    h = f.health(2.0)
    assert (h.rival_events, h.rival_poses, h.outliers, h.unconfirmed) == (0, 0, 1, 2 + 1 + 1)


# --- leaving the volume -----------------------------------------------------------------


def test_walking_out_of_the_volume_is_a_sighting_not_lost_vicon() -> None:
    """The vehicle walks at 0.5 m/s along NED x from 1 m to 3 m and back in: beyond the
    plausible volume (x <= 1.5 m + 0.5 m margin) its stream goes on as sightings, never as
    poses; back inside, poses pass at once."""
    rng = np.random.default_rng(5)
    f = PoseFilter(NAME)
    out, back = [], []
    for k in range(400):  # 4 s at 100 Hz, out
        tr = noisy(rng, (1000.0 + 5.0 * k, HOVER_MM[1], HOVER_MM[2]))
        out.append((send(f, k + 1, 0.01 * k, (NAME, tr, ROT)), tr))
    t_out = 3.99
    inside = [ned(tr)[0] <= 2.0 for _, tr in out]
    assert [p is not None for p, _ in out] == [False, False, *inside[2:]]
    evidence = f.evidence(t_out)
    last_in = [tr for p, tr in out if p is not None][-1]
    assert evidence.last_position == pytest.approx(ned(last_in), abs=1e-12)
    assert evidence.outside == pytest.approx(ned(out[-1][1]), abs=1e-12)
    assert evidence.last_age_s == pytest.approx(t_out - 0.01 * (inside.index(False) - 1))
    h = f.health(t_out)
    assert h.outside == inside.count(False)
    assert (h.lost_missing, h.lost_zero, h.lost_held_identity, h.implausible_position,
            h.outliers, h.rivals) == (0, 0, 0, 0, 0, 0)
    assert f.evidence(t_out + 0.6).outside is None  # no sighting for longer than 0.5 s
    for k in range(400, 800):  # and back in
        tr = noisy(rng, (3000.0 - 5.0 * (k - 400), HOVER_MM[1], HOVER_MM[2]))
        back.append((send(f, k + 1, 0.01 * k, (NAME, tr, ROT)), tr))
    assert all((p is not None) == (ned(tr)[0] <= 2.0) for p, tr in back)
    assert f.evidence(7.99).outside is None  # the newest pose is newer than any sighting


@pytest.mark.parametrize(("far_mm", "counter"), [
    ((30_000.0, 200.0, 1000.0), "implausible_position"),  # 30 m: beyond the sighting range
    ((3000.0, 200.0, 1000.0), "outliers"),  # 3 m: in range, but a 2.9 m jump in 10 ms
])
def test_a_single_far_pose_is_no_sighting(far_mm: tuple[float, float, float],
                                          counter: str) -> None:
    rng = np.random.default_rng(6)
    f = PoseFilter(NAME)
    for k in range(10):
        send(f, k + 1, 0.01 * k, (NAME, noisy(rng), ROT))
    assert send(f, 11, 0.1, (NAME, far_mm, ROT)) is None
    evidence = f.evidence(0.1)
    assert evidence.outside is None and evidence.rivals == 0
    h = f.health(0.1)
    assert getattr(h, counter) == 1 and h.outside == 0
    assert send(f, 12, 0.11, (NAME, noisy(rng), ROT)) is not None  # not blinded


def test_a_consistent_absurd_stream_is_never_a_sighting() -> None:
    f = PoseFilter(NAME)
    for k in range(50):  # 100 m away, consistent, 1 s
        assert send(f, k + 1, 0.02 * k, (NAME, (100_000.0 + k, 200.0, 1000.0), ROT)) is None
    assert f.evidence(1.0).outside is None
    assert f.health(1.0).implausible_position == 50


def test_a_stream_below_the_floor_is_a_sighting() -> None:
    """0.6 m below the floor (NED z = +0.6 m, the plausible volume ends at +0.55 m) is
    inside the sighting range: a consistent stream there is a sighting once confirmed,
    at the spec's conversion of what was sent; never a pose."""
    f = PoseFilter(NAME)
    below = (100.0, 200.0, -600.0)
    assert all(send(f, k + 1, 0.01 * k, (NAME, below, ROT)) is None for k in range(5))
    assert f.evidence(0.04).outside == pytest.approx(ned(below), abs=1e-12)
    h = f.health(0.04)
    assert (h.outside, h.unconfirmed, h.implausible_position, h.poses) == (3, 2, 0, 0)


# --- diagnosis ------------------------------------------------------------------------


def test_diagnosis_names_every_refusal_with_its_count() -> None:
    rng = np.random.default_rng(7)
    f = PoseFilter(NAME)
    t = 0.0
    frame = 0

    def nxt(*items: Item) -> Pose | None:
        nonlocal t, frame
        t += 0.01
        frame += 1
        return send(f, frame, t, *items)

    assert f.process(b"\x01\x00", t) is None  # malformed: shorter than the header
    assert f.process(datagram(0, (NAME, HOVER_MM, ROT), pad_to=0)[:-8], t) is None  # truncated
    for _ in range(3):
        nxt(("wand", (0.0, 0.0, 0.0), ROT))  # without the object
    nxt()  # no item at all: without the object too
    nxt((NAME, (math.nan, 0.0, 1000.0), ROT))  # non-finite
    nxt((NAME, ZERO, ZERO))  # all zero
    last: tuple[float, ...] = ()
    for _ in range(10):  # 2 unconfirmed, 8 poses
        last = noisy(rng)
        nxt((NAME, last, ROT))
    assert send(f, frame, t + 0.005, (NAME, noisy(rng), ROT)) is None  # frame repeated
    nxt((NAME, last, ZERO))  # held identity
    nxt((NAME, last, ZERO))
    nxt((NAME, (50_000.0, 0.0, 1000.0), ROT))  # beyond the sighting range
    nxt((NAME, HOVER_MM, (0.1, 7.0, 0.0)))  # more than a turn: not a rotation
    nxt((NAME, (1100.0, 200.0, 1000.0), ROT))  # 1 m jump: inconsistent
    for _ in range(5):
        assert nxt((NAME, noisy(rng), ROT)) is not None
    h = f.health(t)
    assert h.datagrams == 2 + 4 + 1 + 1 + 10 + 1 + 2 + 1 + 1 + 1 + 5
    assert f.diagnosis() == (
        "29 datagrams, 13 poses of 'X3D' passed; refused: 2 malformed, 4 without the "
        "object, 1 non-finite, 1 all-zero lost tracking, 2 held-identity lost tracking, "
        "1 beyond the sighting range, 1 not a rotation, 1 inconsistent, 2 unconfirmed, "
        "1 duplicated")
    assert h.poses + sum(n for n, _ in h.refusals()) == h.datagrams
