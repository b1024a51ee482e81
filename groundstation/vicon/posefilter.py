"""Sans-IO per-datagram logic: datagram bytes + receive time -> Pose or nothing.

:class:`PoseFilter` turns each datagram into at most one
:class:`groundstation.types.Pose` of the configured object, in this order:

1. **Decode** (:mod:`.decoder`): a malformed datagram is counted and dropped.
2. **Lost tracking** ("no measurement", counted by kind): the object is missing;
   a value is NaN or infinite; all six values are exactly 0.0 (Vicon SDK,
   occluded object); or the **held identity** of the thesis's lab (Ch. 7.3.1,
   Algorithm 2): all three rotations exactly 0.0 with a *held* translation, exactly
   the previous item's of this object or the last one of a pose stream. A first
   pose with rotation exactly 0 is a pose (a level vehicle facing Vicon's x with
   noise-free angles reads so); if the same values come again, it was the start of
   a held run and is taken back (:meth:`.Streams.retract`).
3. **Absolute plausibility** (:mod:`.plausibility`, counted): raw values within
   the sighting range's radius and one turn, checked before any conversion; then a
   unit quaternion and the NED position inside the sighting range (the plausible
   volume grown by ``SIGHTING_MARGIN_M``). At start-up and after a gap as at any
   other time. A pose outside the plausible volume (flight volume + margin) but in
   the sighting range goes on: it may be the vehicle leaving the volume.
4. **Convert** (:mod:`.frames`) and stamp ``t = t_receive - latency_s`` (between
   the two halves of step 3).
5. **Streams** (:mod:`.streams`): the pose joins the stream of poses it agrees
   with (speed / rotation-rate gate for their spacing, with slack for receive-time
   jitter and noise) or starts one; frame numbers are kept per stream and advanced
   only by its poses. It counts once its stream holds ``reanchor_poses``
   consistent poses in a row: never one pose at start-up, after a gap longer than
   ``reanchor_after_s`` or for a new sender. One confirmed stream is followed; a
   confirmed stream fed at the same time (its poses alternating with the followed
   one's) is a **rival** (a second sender: counted, logged once per episode as
   ``vicon_rival_stream``, never passed on).
6. **Pass on** a pose of the followed stream inside the plausible volume; one
   outside it is a **sighting** (counted, kept for :meth:`PoseFilter.evidence`),
   never a pose to fuse.

Only datagrams that carry a usable pose of the followed object ever touch the frame
bookkeeping; other objects' items and pose-less datagrams are counted and ignored.
No arithmetic on a received number before it is known to be finite and bounded,
so no datagram can make numpy warn.

Datagrams that stop are visible in :class:`ViconHealth` (rate of the followed
stream, time since the last pose), and the rate leaving its band is logged by
:class:`RateMonitor`. :meth:`PoseFilter.evidence` is what the flight reads per
tick beyond the poses (rivals, sightings outside the volume);
:meth:`PoseFilter.diagnosis` says in one line why poses were refused.
Not thread-safe: the client serialises calls.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from types import MappingProxyType
from typing import TypedDict

import numpy.typing as npt
import structlog

from groundstation.errors import ConfigError
from groundstation.types import Pose
from groundstation.vicon.decoder import BadDatagram, DatagramDecoder, ObjectPose, ViconFrame
from groundstation.vicon.frames import (
    DEFAULT_BODY_TO_OBJECT,
    DEFAULT_WORLD_TO_NED,
    FrameConversion,
)
from groundstation.vicon.health import LOGGER_NAME, RateMonitor, ViconEvidence, ViconHealth
from groundstation.vicon.plausibility import (
    DEFAULT_VOLUME,
    OUTSIDE,
    POSITION,
    ROTATION,
    Box,
    Plausibility,
)
from groundstation.vicon.streams import FOLLOWED, RIVAL, Gate, Streams

MAX_RATE_FACTOR = 1.2
"""A stream faster than its expected rate times this is misconfigured (the rate band's top,
``max_rate_hz``, as the assembly sets it from ``vicon.expected_rate_hz``)."""

Matrix3 = tuple[tuple[float, float, float], tuple[float, float, float],
                tuple[float, float, float]]
"""A (3, 3) rotation as rows."""


class FilterOptions(TypedDict, total=False):
    """The optional :class:`PoseFilter` parameters, for callers that pass them through."""

    restart_silence_s: float
    restart_backjump_frames: int
    max_speed: float
    max_rotation_rate: float
    position_slack: float
    angle_slack: float
    reanchor_after_s: float
    reanchor_poses: int
    plausible_volume: Box
    rate_window_s: float
    min_rate_hz: float
    max_rate_hz: float
    warn_interval_s: float


@dataclass(frozen=True, slots=True)
class PoseFilterParams:
    """What the pose filter is built with (see :class:`PoseFilter` for each).

    object_name : the Tracker object; world_to_ned, body_to_object : rotations C_wn, C_bo
    latency_s : [s]; restart_silence_s : [s]; restart_backjump_frames : [frames]
    max_speed : [m/s]; max_rotation_rate : [rad/s]; reanchor_poses : [-]
    plausible_volume : NED [m]; min_rate_hz, max_rate_hz : the rate band [Hz]
    """

    object_name: str
    world_to_ned: Matrix3
    body_to_object: Matrix3
    latency_s: float
    restart_silence_s: float
    restart_backjump_frames: int
    max_speed: float
    max_rotation_rate: float
    reanchor_poses: int
    plausible_volume: Box
    min_rate_hz: float
    max_rate_hz: float

    def options(self) -> FilterOptions:
        """The optional arguments of :class:`PoseFilter` these parameters set."""
        return FilterOptions(
            restart_silence_s=self.restart_silence_s,
            restart_backjump_frames=self.restart_backjump_frames,
            max_speed=self.max_speed, max_rotation_rate=self.max_rotation_rate,
            reanchor_poses=self.reanchor_poses, plausible_volume=self.plausible_volume,
            min_rate_hz=self.min_rate_hz, max_rate_hz=self.max_rate_hz)


class PoseFilter:
    """Datagrams in, poses of one object out; counts everything it drops.

    Parameters (keyword-only, validated here once)
    ----------
    object_name : the Tracker object to follow (names are compared exactly)
    world_to_ned, body_to_object : (3, 3) rotations C_wn and C_bo (see :mod:`.frames`)
    latency_s : Vicon + network latency subtracted from the receive time [s]
    restart_silence_s : a silence longer than this makes any frame number acceptable [s]
    restart_backjump_frames : a backward jump larger than this is a Tracker restart
    max_speed : plausibility limit on the implied speed [m/s]
    max_rotation_rate : plausibility limit on the implied rotation rate [rad/s]
    position_slack : position jump always allowed [m]
    angle_slack : rotation always allowed [rad]
    reanchor_after_s : a link between two poses of a stream longer than this is a gap [s]
    reanchor_poses : consistent poses in a row before a stream's poses pass (>= 2)
    plausible_volume : where a pose may be passed on, NED [m] ((x_min, x_max),
        (y_min, y_max), (z_min, z_max)); default: the configuration's flight volume grown
        by its margin
    rate_window_s, min_rate_hz, max_rate_hz, warn_interval_s : see :class:`RateMonitor`
    logger : structlog logger for the rate and rival-stream warnings
    """

    def __init__(
        self,
        object_name: str,
        *,
        world_to_ned: npt.ArrayLike = DEFAULT_WORLD_TO_NED,
        body_to_object: npt.ArrayLike = DEFAULT_BODY_TO_OBJECT,
        latency_s: float = 0.005,
        restart_silence_s: float = 1.0,
        restart_backjump_frames: int = 1000,
        max_speed: float = 5.0,
        max_rotation_rate: float = 30.0,
        position_slack: float = 0.02,
        angle_slack: float = 0.05,
        reanchor_after_s: float = 0.5,
        reanchor_poses: int = 3,
        plausible_volume: Box = DEFAULT_VOLUME,
        rate_window_s: float = 1.0,
        min_rate_hz: float = 8.0,
        max_rate_hz: float = 120.0,
        warn_interval_s: float = 5.0,
        logger: structlog.typing.FilteringBoundLogger | None = None,
    ) -> None:
        nonnegative = {
            "latency_s": latency_s,
            "restart_silence_s": restart_silence_s,
            "restart_backjump_frames": restart_backjump_frames,
            "max_speed": max_speed,
            "max_rotation_rate": max_rotation_rate,
            "position_slack": position_slack,
            "angle_slack": angle_slack,
            "reanchor_after_s": reanchor_after_s,
        }
        problems: list[tuple[str, object, str]] = [
            (k, v, "finite and >= 0")
            for k, v in nonnegative.items()
            if not (math.isfinite(v) and v >= 0.0)
        ]
        if not object_name:
            problems.append(("object_name", object_name, "non-empty"))
        if not (isinstance(reanchor_poses, int) and reanchor_poses >= 2):
            problems.append(("reanchor_poses", reanchor_poses, "an integer >= 2: never one pose"))
        if problems:
            raise ConfigError("invalid Vicon parameters", problems)
        self.object_name = object_name
        self.frames = FrameConversion.create(world_to_ned, body_to_object)
        self.plausibility = Plausibility.create(plausible_volume)
        self.latency_s = latency_s
        self.restart_silence_s = restart_silence_s
        self.restart_backjump_frames = restart_backjump_frames
        self.max_speed = max_speed
        self.max_rotation_rate = max_rotation_rate
        self.position_slack = position_slack
        self.angle_slack = angle_slack
        self.reanchor_after_s = reanchor_after_s
        self.reanchor_poses = reanchor_poses
        self.decoder = DatagramDecoder()
        self._log = logger if logger is not None else structlog.get_logger(LOGGER_NAME)
        self.rate = RateMonitor(
            window_s=rate_window_s,
            min_rate_hz=min_rate_hz,
            max_rate_hz=max_rate_hz,
            warn_interval_s=warn_interval_s,
            logger=logger,
        )
        self.streams = Streams(
            Gate(max_speed, max_rotation_rate, position_slack, angle_slack),
            confirm=reanchor_poses, gap_s=reanchor_after_s, silence_s=restart_silence_s,
            backward_frames=restart_backjump_frames, max_rate_hz=max_rate_hz,
        )
        self.lost_missing = self.lost_zero = self.lost_held_identity = self.non_finite = 0
        self.implausible_position = self.implausible_rotation = self.poses = 0
        self.outside = 0
        self._rival_logged = 0  # the rival episode last logged
        self._previous: tuple[float, float, float] | None = None  # the last item's translation
        self._last: Pose | None = None  # the newest pose passed on
        self._last_t = -math.inf  # its receive time [s]
        self._sighting: Pose | None = None  # the newest sighting outside the volume
        self._sighting_t = -math.inf  # its receive time [s]

    @classmethod
    def from_params(cls, params: PoseFilterParams,
                    logger: structlog.typing.FilteringBoundLogger | None = None) -> PoseFilter:
        """A filter built with ``params``."""
        return cls(params.object_name, world_to_ned=params.world_to_ned,
                   body_to_object=params.body_to_object, latency_s=params.latency_s,
                   logger=logger, **params.options())

    def process(self, datagram: bytes | bytearray | memoryview, t_receive: float) -> Pose | None:
        """Process one datagram received at monotonic time ``t_receive`` [s].

        Returns the object's Pose (t = t_receive - latency_s, NED position [m],
        scalar-first quaternion with R(q) = eCb, Tracker frame number), or None
        if the datagram carries no acceptable measurement. Never raises on bad input.
        """
        result = self.decoder.decode(datagram)
        pose = None
        if not isinstance(result, BadDatagram):
            pose = self._measure(result, t_receive)
        self.rate.check(t_receive)
        return pose

    def rate_and_age(self, now: float) -> tuple[float, float]:
        """``(pose rate [Hz], time since the last accepted pose [s])`` at ``now``.

        The cheap per-tick subset of :meth:`health`; it also drives the rate-band warning.
        """
        return self.rate.check(now), self.rate.time_since_pose(now)

    def evidence(self, now: float) -> ViconEvidence:
        """What the stream says at monotonic time ``now`` [s] beyond the poses: the newest
        pose passed on, a newer sighting outside the volume, rival streams (see
        :class:`ViconEvidence`). Cheap (a few comparisons), for every loop tick."""
        last, sighting = self._last, self._sighting
        outside = None
        if (sighting is not None and self._sighting_t > self._last_t
                and now - self._sighting_t <= self.reanchor_after_s):
            outside = _xyz(sighting)
        return ViconEvidence(
            last_position=None if last is None else _xyz(last),
            last_age_s=now - self._last_t,
            outside=outside,
            rivals=self.streams.rivals(now - self.latency_s),
            rival_events=self.streams.rival_events,
        )

    def diagnosis(self) -> str:
        """One line: datagrams received, poses of the object passed on, and how many were
        refused for each reason (see :meth:`ViconHealth.diagnosis`)."""
        return self._snapshot(math.nan, math.nan, 0).diagnosis(self.object_name)

    def health(self, now: float) -> ViconHealth:
        """Snapshot of rates and counters at monotonic time ``now`` [s].

        Also updates the rate band, so calling this periodically is what warns when
        datagrams stop arriving altogether.
        """
        rate = self.rate.check(now)
        return self._snapshot(rate, self.rate.time_since_pose(now),
                              self.streams.rivals(now - self.latency_s))

    def _snapshot(self, rate: float, since: float, rivals: int) -> ViconHealth:
        """The counters with this rate [Hz], time since the last pose [s] and rivals."""
        streams = self.streams
        return ViconHealth(
            rate_hz=rate,
            rate_in_band=self.rate.in_band,
            time_since_pose_s=since,
            datagrams=self.decoder.datagrams,
            poses=self.poses,
            rejected=MappingProxyType(dict(self.decoder.rejected)),
            skipped_items=self.decoder.skipped_items,
            frames_dropped=streams.frames_dropped,
            duplicates=streams.duplicates,
            reordered=streams.reordered,
            restarts=streams.restarts,
            lost_missing=self.lost_missing,
            lost_zero=self.lost_zero,
            lost_held_identity=self.lost_held_identity,
            non_finite=self.non_finite,
            outliers=streams.outliers,
            reanchors=streams.reanchors,
            rate_warnings=self.rate.warnings,
            implausible_position=self.implausible_position,
            implausible_rotation=self.implausible_rotation,
            unconfirmed=streams.unconfirmed,
            outside=self.outside,
            rivals=rivals,
            rival_events=streams.rival_events,
            rival_poses=streams.rival_poses,
        )

    def _measure(self, frame: ViconFrame, t_receive: float) -> Pose | None:
        """Lost-tracking and plausibility checks, conversion and streams for one frame."""
        obj = frame.find(self.object_name)
        if obj is None:
            self.lost_missing += 1
            return None
        if self._is_lost(obj):
            return None
        reason = self.plausibility.raw(obj.translation, obj.rotation)
        if reason is None:
            position, quaternion = self.frames.to_ned(obj.translation, obj.rotation)
            reason = self.plausibility.converted(position, quaternion)
        if reason == POSITION:
            self.implausible_position += 1
            return None
        if reason == ROTATION:
            self.implausible_rotation += 1
            return None
        pose = Pose(t_receive - self.latency_s, position, quaternion, frame.frame)
        verdict = self.streams.offer(pose, obj.translation, obj.rotation == (0.0, 0.0, 0.0))
        if verdict == RIVAL:
            self._rival(pose)
        if verdict != FOLLOWED:
            return None
        if reason == OUTSIDE:  # the vehicle's own stream, beyond the volume: never fused
            self.outside += 1
            self._sighting, self._sighting_t = pose, t_receive
            return None
        self.poses += 1
        self.rate.record(t_receive)
        self._last, self._last_t = pose, t_receive
        return pose

    def _rival(self, pose: Pose) -> None:
        """Log a rival stream's pose once per episode (the first pose of an episode)."""
        streams = self.streams
        if streams.rival_events == self._rival_logged:
            return
        self._rival_logged = streams.rival_events
        followed = streams.followed
        offset = (math.nan if followed is None
                  else math.dist(pose.position.tolist(), followed.last.position.tolist()))
        self._log.warning(
            "vicon_rival_stream", object=self.object_name, episode=streams.rival_events,
            rival_position=_xyz(pose),
            followed_position=None if followed is None else _xyz(followed.last),
            offset_m=offset,
        )

    def _is_lost(self, obj: ObjectPose) -> bool:
        """True (and counted by kind) if the object's values encode lost tracking."""
        x, y, z = obj.translation
        rx, ry, rz = obj.rotation
        previous, self._previous = self._previous, obj.translation
        if not all(map(math.isfinite, (x, y, z, rx, ry, rz))):
            self.non_finite += 1
            self._previous = None
            return True
        if rx != 0.0 or ry != 0.0 or rz != 0.0:
            return False
        if x == 0.0 and y == 0.0 and z == 0.0:
            self.lost_zero += 1
            return True
        if obj.translation == previous or self.streams.held(obj.translation):
            self.lost_held_identity += 1
            if self.streams.retract(obj.translation):  # the run's first item, taken back
                self.lost_held_identity += 1
            return True
        return False


def _xyz(pose: Pose) -> tuple[float, float, float]:
    """A pose's NED position [m] as a tuple of floats."""
    x, y, z = pose.position.tolist()
    return (x, y, z)
