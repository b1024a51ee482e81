"""Pose streams of the tracked object: consistency, confirmation, following, frame numbers.

Poses of one object name may come from more than one sender (a hostile
or misconfigured one beside Tracker), and after a gap any single pose may be wrong.
:class:`Streams` therefore sorts the sighted poses (see :mod:`.plausibility`)
into **streams**, each a sequence of poses in which every pose agrees with the one
before it: ``|dp| <= max_speed * dt + position_slack`` and rotation angle
``<= max_rotation_rate * dt + angle_slack`` (spec: "a jump faster than the
configured limits is an outlier"). A pose joins the stream it agrees with: a link
that is not a gap first, then the followed stream, then a confirmed one, then the one
fed last (not the longest run: a stream whose sender has moved on would otherwise
take that sender's poses back as soon as its gate, widening while it waits, allows,
and one sender would feed two streams in turn). A pose that agrees with none starts
a new stream (an *outlier* if other streams exist).

**Confirmation.** A stream's pose counts only once the stream holds ``confirm``
consistent poses in a row, never one: at start-up, for a new stream, and after a
**gap**, a link longer than ``gap_s`` and than ``GAP_FACTOR`` times the stream's
previous link (so a 1 Hz stream has no gaps, while a 100 Hz one paused for 0.5 s
has) starts the run again.

**Following.** One confirmed stream is the **followed** one: the vehicle as far as
Vicon can tell, the only stream whose poses are passed on. The first confirmed stream
is followed. Another stream's poses **alternate** with the followed one's when the
pose before was of the other stream: one sender sends one pose per frame, so it
moves from stream to stream in blocks (a jump, a stray pose, a mis-fit of a few
frames: one or two alternations), while two senders at once alternate all the time.
A confirmed stream whose poses alternated ``RIVAL_ALTERNATIONS`` times with the
followed one's, each within ``gap_s`` of the one before, is a **rival**: a second
sender of our object. Its poses are never passed on (counted in ``rival_poses``);
each episode of rival poses, separated by more than ``gap_s`` without one, counts in
``rival_events``. Any other confirmed stream takes over when the followed one has
stopped: silent for longer than ``gap_s``, re-confirming after a gap of its own, or
silent for ``MISSED_FACTOR`` times its usual link (it missed a pose: its sender moved
on to the other stream); until then its poses are held back (``unconfirmed``).
Nothing here can tell which sender is real: the incumbent is kept, and the flight
decides what a rival means.

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
Dropped frames are counted only in the followed stream, so no foreign stream inflates
them; a restart counts one per datagram.

Pure Python floats on poses already inside the sighting range: no overflow.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Final

from groundstation.types import Pose

GAP_FACTOR: Final = 3.0
"""A link is a gap only if also this many times the stream's previous link."""
MISSED_FACTOR: Final = 1.5
"""A followed stream silent for this many times its usual link has missed a pose."""
PERIOD_WEIGHT: Final = 0.1
"""Weight of the newest link in a stream's usual link (an exponential average, so one
burst of two datagrams back to back does not make a late pose look missed)."""
RIVAL_ALTERNATIONS: Final = 5
"""Alternations with the followed stream that make a confirmed stream a rival. A second
sender alternates at every pose, so it has five by its third (confirming) pose; one
sender moving to another stream and back makes two, and its stray poses (a snap at a
hard touchdown, a reflection) make two each, so it would take three strays, each within
``gap_s`` of the one before."""
GAP_SLACK_FRAMES: Final = 10
"""Frames a gap may exceed the time since the last frame at ``max_rate_hz`` (bursts)."""
MAX_STREAMS: Final = 4
"""Streams kept; a new one replaces the least recently fed, unconfirmed ones first."""
UINT32: Final = 1 << 32

NEXT, DUPLICATE, REORDERED, RESTART = "next", "duplicate", "reordered", "restart"

HELD_BACK: Final = "held back"
"""Verdict of :meth:`Streams.offer`: not (yet) believed: unconfirmed, outlier, duplicate
or reordered (counted by kind)."""
FOLLOWED: Final = "followed"
"""Verdict: a confirmed pose of the followed stream (pass it on)."""
RIVAL: Final = "rival"
"""Verdict: a confirmed pose of a rival stream (counted; never pass it on)."""


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
    """One stream: its newest pose, raw translation [mm], run and frame state.

    identity : the newest pose's raw rotation was exactly (0, 0, 0)
    poses : poses joined since the stream began (1: only the one that started it)
    outlier : the first pose was counted as an outlier (else as unconfirmed)
    period : the usual link, an exponential average (PERIOD_WEIGHT) [s]
    alternations, alternated : alternations with the followed stream's poses, each
        within ``gap_s`` of the one before, and the pose time of the last [s]
    rival : the newest confirmed pose was a rival's
    """

    last: Pose
    translation: tuple[float, float, float]
    identity: bool = False
    run: int = 1
    spacing: float = math.inf  # the previous link [s]
    period: float = math.inf
    fed: int = 0  # order of the last update (for replacement)
    confirmed: bool = False  # the run has reached ``confirm`` since the stream began
    behind: int = 0  # reordered datagrams in a row, each after the one before
    behind_frame: int = 0
    poses: int = 1
    outlier: bool = False
    alternations: int = 0
    alternated: float = -math.inf
    rival: bool = False


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
    gap_s : a longer link (and GAP_FACTOR x the previous one) restarts the run; also how
        long a stream counts as fed, for following and rivals [s]
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
        self.followed: Stream | None = None
        self._previous: Stream | None = None  # the stream of the previous pose sorted in
        self._last_rival_t = -math.inf
        self.frames_dropped = self.duplicates = self.reordered = self.restarts = 0
        self.outliers = self.unconfirmed = self.reanchors = 0
        self.rival_poses = self.rival_events = 0

    def held(self, translation: tuple[float, float, float]) -> bool:
        """True if a stream's last raw translation [mm] is exactly ``translation`` (with
        rotations exactly 0: the held-identity lost-tracking encoding)."""
        return any(s.translation == translation for s in self._streams)

    def retract(self, translation: tuple[float, float, float]) -> bool:
        """Take back a stream started by one pose with rotation exactly 0 and this raw
        ``translation`` [mm], now that the same values came again: that pose was the first
        of a held-identity run, not a measurement. True if one was (its count is undone:
        the caller counts it as lost tracking)."""
        for s in self._streams:
            if s.poses == 1 and s.identity and s.translation == translation:
                if s.outlier:
                    self.outliers -= 1
                else:
                    self.unconfirmed -= 1
                self._streams.remove(s)
                return True
        return False

    def offer(self, pose: Pose, translation: tuple[float, float, float],
              identity: bool = False) -> str:
        """Sort in one sighted pose (raw ``translation`` [mm]; ``identity``: its raw
        rotation is exactly 0); the verdict: :data:`FOLLOWED`, :data:`RIVAL` or
        :data:`HELD_BACK`."""
        stream, gap = self._join(pose)
        if stream is None:
            outlier = bool(self._streams)
            if outlier:
                self.outliers += 1
            else:
                self.unconfirmed += 1
            self._alternate(self._start(pose, translation, identity, outlier), pose.t)
            return HELD_BACK
        dropped = self._frame(stream, pose.frame, pose.t - stream.last.t)
        if dropped is None:
            return HELD_BACK
        self._alternate(stream, pose.t)
        stream.run = 1 if gap else stream.run + 1
        stream.spacing = pose.t - stream.last.t
        stream.period = (stream.spacing if math.isinf(stream.period) else
                         stream.period + PERIOD_WEIGHT * (stream.spacing - stream.period))
        stream.last, stream.translation, stream.identity = pose, translation, identity
        stream.poses += 1
        self._fed += 1
        stream.fed = self._fed
        passed = stream.run >= self.confirm
        if passed and not stream.confirmed:
            self.reanchors += self._confirmed_once
            self._confirmed_once = stream.confirmed = True
        elif passed and stream.run == self.confirm:  # confirmed again after a gap
            self.reanchors += 1
        verdict = self._follow(stream, pose.t) if passed else HELD_BACK
        if stream is self.followed:  # the vehicle's drops are real, even across a gap
            self.frames_dropped += dropped
        if verdict == HELD_BACK:
            self.unconfirmed += 1
        return verdict

    def rivals(self, now: float) -> int:
        """Rival streams (confirmed, alternating with the followed one) fed within ``gap_s``
        before ``now`` (pose time [s]) while the followed one was too; 0 with one sender."""
        f = self.followed
        if f is None or now - f.last.t > self.gap_s:
            return 0
        return sum(1 for s in self._streams
                   if s is not f and s.rival and s.run >= self.confirm
                   and now - s.last.t <= self.gap_s)

    def _follow(self, stream: Stream, t: float) -> str:
        """Whether the confirmed ``stream`` (fed at ``t`` [s]) is followed, a rival, or held
        back until the followed one stops (see the module docstring)."""
        f = self.followed
        rival = stream.alternations >= RIVAL_ALTERNATIONS
        stream.rival = False
        if (f is None or f is stream or t - f.last.t > self.gap_s or f.run < self.confirm
                or (not rival and t - f.last.t > MISSED_FACTOR * f.period)):
            if f is not stream:  # alternations count against the followed stream
                self.followed, stream.alternations = stream, 0
            return FOLLOWED
        if not rival:
            return HELD_BACK
        stream.rival = True
        self.rival_poses += 1
        if t - self._last_rival_t > self.gap_s:
            self.rival_events += 1
        self._last_rival_t = t
        return RIVAL

    def _alternate(self, stream: Stream, t: float) -> None:
        """Count an alternation if a pose of ``stream`` (at ``t`` [s]) follows one of the
        followed stream, or the reverse; on the stream that is not the followed one."""
        previous, self._previous = self._previous, stream
        f = self.followed
        if previous is None or previous is stream or f is None:
            return
        other = stream if previous is f else previous if stream is f else None
        if other is None:
            return
        if t - other.alternated > self.gap_s:
            other.alternations = 0
        other.alternations += 1
        other.alternated = t

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
        best: tuple[bool, bool, bool, int] | None = None
        chosen: Stream | None = None
        for s in self._streams:
            score = self.gate.score(s.last, pose)
            if not score <= 1.0:
                continue
            dt = pose.t - s.last.t
            gap = dt > self.gap_s and dt > GAP_FACTOR * s.spacing
            key = (gap, s is not self.followed, s.run < self.confirm, -s.fed)
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

    def _start(self, pose: Pose, translation: tuple[float, float, float], identity: bool,
               outlier: bool) -> Stream:
        if len(self._streams) >= MAX_STREAMS:
            unconfirmed = [s for s in self._streams if not s.confirmed]
            pool = unconfirmed or self._streams
            gone = min(pool, key=lambda s: s.fed)
            self._streams.remove(gone)
            if gone is self.followed:
                self.followed = None
        self._fed += 1
        stream = Stream(pose, translation, identity, fed=self._fed, outlier=outlier)
        self._streams.append(stream)
        return stream
