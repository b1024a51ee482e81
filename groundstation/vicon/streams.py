"""Pose streams of the tracked object: consistency, confirmation, frame numbers.

Poses of one object name may come from more than one sender (issue 14: a hostile
or misconfigured one beside Tracker), and after a gap any single pose may be wrong.
:class:`Streams` therefore sorts the plausible poses (see :mod:`.plausibility`)
into **streams**, each a sequence of poses in which every pose agrees with the one
before it: ``|dp| <= max_speed * dt + position_slack`` and rotation angle
``<= max_rotation_rate * dt + angle_slack`` (spec: "a jump faster than the
configured limits is an outlier"). A pose joins the stream it agrees with (a link
that is not a gap first, then the longer run, then the closer one); a pose that
agrees with none starts a new stream (an *outlier* if other streams exist).

**Confirmation.** A pose is passed on only when its stream holds ``confirm``
consistent poses in a row, never one: at start-up, for a new stream, and after a
**gap**, a link longer than ``gap_s`` and than ``GAP_FACTOR`` times the stream's
previous link (so a 1 Hz stream has no gaps, while a 100 Hz one paused for 0.5 s
has) starts the run again. Two confirmed streams both pass: the filter cannot tell
which sender is real; the estimator, which has the IMU, decides.

**Frame numbers** are kept per stream and advanced only by its poses, so another
object's items, pose-less datagrams and other streams never touch them. Against
its stream's last frame, a datagram is the next frame, or a gap of ``d - 1``
dropped frames if the time since the last one explains it (``d - 1 <= max_rate_hz
* dt + GAP_SLACK_FRAMES``); a repeat (duplicate) or up to ``backward_frames`` back
(reordered) is dropped; anything else, or anything after ``silence_s`` without a
frame, is a **restart** (a Tracker restart, the uint32 wrap being a plain step,
or a garbage frame number): accepted if the pose agrees, and never counted as
dropped frames. ``confirm`` reordered datagrams in a row, each after the one
before, are a restart too (the stream went on below a garbage frame number).
Dropped frames are counted only in streams that have passed poses, so no foreign
stream inflates them; a restart counts one per datagram.

Pure Python floats on poses already inside the plausible volume: no overflow.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Final

from groundstation.types import Pose

GAP_FACTOR: Final = 3.0
"""A link is a gap only if also this many times the stream's previous link."""
GAP_SLACK_FRAMES: Final = 10
"""Frames a gap may exceed the time since the last frame at ``max_rate_hz`` (bursts)."""
MAX_STREAMS: Final = 4
"""Streams kept; a new one replaces the least recently fed, unconfirmed ones first."""
UINT32: Final = 1 << 32

NEXT, DUPLICATE, REORDERED, RESTART = "next", "duplicate", "reordered", "restart"


def frame_step(last: int, frame: int, dt: float, *, silence_s: float,
               backward_frames: int, max_rate_hz: float) -> tuple[str, int]:
    """Classify ``frame`` after ``last`` (uint32), ``dt`` [s] later: ``(kind, dropped)``.

    kind : NEXT (``dropped`` frames were missed), DUPLICATE, REORDERED or RESTART (see
    the module docstring; ``dropped`` is 0 unless NEXT).
    """
    d = (frame - last) % UINT32
    if d >= 1 and d - 1 <= max_rate_hz * max(dt, 0.0) + GAP_SLACK_FRAMES:
        return NEXT, d - 1
    if dt > silence_s:
        return RESTART, 0
    if d == 0:
        return DUPLICATE, 0
    if UINT32 - d <= backward_frames:
        return REORDERED, 0
    return RESTART, 0


@dataclass(slots=True)
class Stream:
    """One stream: its newest pose, raw translation [mm], run and frame state."""

    last: Pose
    translation: tuple[float, float, float]
    run: int = 1
    spacing: float = math.inf  # the previous link [s]
    fed: int = 0  # order of the last update (for replacement)
    confirmed: bool = False  # the run has reached ``confirm`` since the stream began
    behind: int = 0  # reordered datagrams in a row, each after the one before
    behind_frame: int = 0


@dataclass(frozen=True, slots=True)
class Gate:
    """The speed / rotation-rate gate between two poses ``dt`` apart."""

    max_speed: float
    max_rotation_rate: float
    position_slack: float
    angle_slack: float

    def score(self, a: Pose, b: Pose) -> float:
        """max(jump / allowed jump, angle / allowed angle) from ``a`` to ``b``; <= 1 agrees."""
        dt = max(b.t - a.t, 0.0)
        ax, ay, az = a.position.tolist()
        bx, by, bz = b.position.tolist()
        jump = math.sqrt((bx - ax) ** 2 + (by - ay) ** 2 + (bz - az) ** 2)
        p0, p1, p2, p3 = a.quaternion.tolist()
        q0, q1, q2, q3 = b.quaternion.tolist()
        cos_half = min(abs(p0 * q0 + p1 * q1 + p2 * q2 + p3 * q3), 1.0)
        angle = 2.0 * math.acos(cos_half)
        return max(_ratio(jump, self.max_speed * dt + self.position_slack),
                   _ratio(angle, self.max_rotation_rate * dt + self.angle_slack))


def _ratio(value: float, limit: float) -> float:
    if limit > 0.0:
        return value / limit
    return 0.0 if value == 0.0 else math.inf


class Streams:
    """The streams of one object (see the module docstring); counters for health.

    gate : the consistency gate; confirm : poses in a row before a stream passes (>= 2)
    gap_s : a longer link (and GAP_FACTOR x the previous one) restarts the run [s]
    silence_s, backward_frames, max_rate_hz : frame-number rules (:func:`frame_step`)
    """

    def __init__(self, gate: Gate, *, confirm: int, gap_s: float, silence_s: float,
                 backward_frames: int, max_rate_hz: float) -> None:
        self.gate = gate
        self.confirm = confirm
        self.gap_s = gap_s
        self.silence_s = silence_s
        self.backward_frames = backward_frames
        self.max_rate_hz = max_rate_hz
        self._streams: list[Stream] = []
        self._fed = 0
        self._confirmed_once = False
        self.frames_dropped = self.duplicates = self.reordered = self.restarts = 0
        self.outliers = self.unconfirmed = self.reanchors = 0

    def held(self, translation: tuple[float, float, float]) -> bool:
        """True if no stream exists or one's last raw translation [mm] is ``translation``
        (with rotations exactly 0: the held-identity lost-tracking encoding)."""
        return not self._streams or any(s.translation == translation for s in self._streams)

    def offer(self, pose: Pose, translation: tuple[float, float, float]) -> bool:
        """Sort in one plausible pose (raw ``translation`` [mm]); True if it is passed on."""
        stream, gap = self._join(pose)
        if stream is None:
            if self._streams:
                self.outliers += 1
            else:
                self.unconfirmed += 1
            self._start(pose, translation)
            return False
        dropped = self._frame(stream, pose.frame, pose.t - stream.last.t)
        if dropped is None:
            return False
        stream.run = 1 if gap else stream.run + 1
        stream.spacing = pose.t - stream.last.t
        stream.last, stream.translation = pose, translation
        self._fed += 1
        stream.fed = self._fed
        passed = stream.run >= self.confirm
        if passed and not stream.confirmed:
            self.reanchors += self._confirmed_once
            self._confirmed_once = stream.confirmed = True
        elif passed and stream.run == self.confirm:  # confirmed again after a gap
            self.reanchors += 1
        if stream.confirmed:  # our own stream: its drops are real, even across a gap
            self.frames_dropped += dropped
        if not passed:
            self.unconfirmed += 1
        return passed

    def _frame(self, stream: Stream, frame: int, dt: float) -> int | None:
        """Frame-number bookkeeping of a pose joining ``stream``, ``dt`` [s] after its last:
        the frames dropped before it, or None if it is a duplicate or reordered (counted)."""
        kind, dropped = frame_step(stream.last.frame, frame, dt, silence_s=self.silence_s,
                                   backward_frames=self.backward_frames,
                                   max_rate_hz=self.max_rate_hz)
        if kind == DUPLICATE:
            self.duplicates += 1
            return None
        if kind == REORDERED and not self._behind(stream, frame):
            self.reordered += 1
            return None
        if kind != NEXT:
            self.restarts += 1
        stream.behind = 0
        return dropped

    def _join(self, pose: Pose) -> tuple[Stream | None, bool]:
        """The stream ``pose`` agrees with and whether the link is a gap (None if none)."""
        best: tuple[bool, int, float] | None = None
        chosen: Stream | None = None
        for s in self._streams:
            score = self.gate.score(s.last, pose)
            if not score <= 1.0:
                continue
            dt = pose.t - s.last.t
            gap = dt > self.gap_s and dt > GAP_FACTOR * s.spacing
            key = (gap, -s.run, score)
            if best is None or key < best:
                best, chosen = key, s
        return chosen, bool(best is not None and best[0])

    def _behind(self, stream: Stream, frame: int) -> bool:
        """Count a reordered datagram; True once ``confirm`` in a row each followed the one
        before (the stream went on below a garbage frame number: a restart)."""
        step = (frame - stream.behind_frame) % UINT32
        after = 1 <= step <= self.backward_frames
        stream.behind = stream.behind + 1 if stream.behind and after else 1
        stream.behind_frame = frame
        return stream.behind >= self.confirm

    def _start(self, pose: Pose, translation: tuple[float, float, float]) -> None:
        if len(self._streams) >= MAX_STREAMS:
            unconfirmed = [s for s in self._streams if not s.confirmed]
            pool = unconfirmed or self._streams
            self._streams.remove(min(pool, key=lambda s: s.fed))
        self._fed += 1
        self._streams.append(Stream(pose, translation, fed=self._fed))
