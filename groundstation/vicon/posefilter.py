"""Sans-IO per-datagram logic: datagram bytes + receive time -> Pose or nothing.

:class:`PoseFilter` turns each datagram into at most one
:class:`groundstation.types.Pose` of the configured object, in this order:

1. **Decode** (:mod:`.decoder`): a malformed datagram is counted and dropped.
2. **Frame number.** A forward gap of n > 1 counts n - 1 dropped frames. A
   repeated frame number (duplicate) or an older one (reordered) is dropped,
   unless it follows a silence longer than ``restart_silence_s`` or jumps back
   by more than ``restart_backward_frames``: that is a Tracker restart, counted
   and accepted (so is the uint32 wrap-around).
3. **Lost tracking** ("no measurement", counted by kind): the object is missing;
   all six values are exactly 0.0 (Vicon SDK, occluded object); or all three
   rotations are exactly 0.0 while the translation equals the previous one
   reported for this object, or there is no previous one (the thesis's lab,
   Ch. 7.3.1, Algorithm 2). Non-finite values are also dropped and counted.
4. **Convert** (:mod:`.frames`) and stamp ``t = t_receive - latency_s``.
5. **Plausibility gate** against the last accepted pose, ``dt`` apart: reject
   (count an outlier) if ``|dp| > max_speed * dt + position_slack`` or the
   rotation angle ``> max_rotation_rate * dt + angle_slack``. The slack absorbs
   receive-time jitter (a backlog of datagrams read at nearly the same time) and
   noise. If the last accepted pose is older than ``reanchor_after_s`` the pose is
   accepted anyway and becomes the new anchor (so one bad anchor cannot lock
   the gate forever).

Datagrams that stop are visible in :class:`ViconHealth` (rate, time since the
last pose), and the rate leaving its band is logged by :class:`RateMonitor`.
Not thread-safe: the client serialises calls.
"""

from __future__ import annotations

import math
from types import MappingProxyType
from typing import TYPE_CHECKING, TypedDict

import numpy as np
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
from groundstation.vicon.health import RateMonitor, ViconHealth

if TYPE_CHECKING:  # config is only needed by from_config; no import cycle at run time
    from groundstation.config import ViconConfig

MAX_RATE_FACTOR = 1.2
"""from_config: warn above expected_rate_hz * 1.2 (a faster stream is misconfigured)."""


class FilterOptions(TypedDict, total=False):
    """The optional :class:`PoseFilter` parameters, for callers that pass them through."""

    restart_silence_s: float
    restart_backward_frames: int
    max_speed: float
    max_rotation_rate: float
    position_slack: float
    angle_slack: float
    reanchor_after_s: float
    rate_window_s: float
    min_rate_hz: float
    max_rate_hz: float
    warn_interval_s: float


def filter_options(config: ViconConfig) -> FilterOptions:
    """The :class:`FilterOptions` a ``vicon:`` configuration section asks for.

    max_rate_hz is not configured: it is ``MAX_RATE_FACTOR * expected_rate_hz``.
    """
    return FilterOptions(
        restart_silence_s=config.restart_silence_s,
        restart_backward_frames=config.restart_backjump_frames,
        max_speed=config.max_speed_m_s,
        max_rotation_rate=config.max_rotation_rate_rad_s,
        min_rate_hz=config.min_rate_hz,
        max_rate_hz=MAX_RATE_FACTOR * config.expected_rate_hz,
    )


class PoseFilter:
    """Datagrams in, poses of one object out; counts everything it drops.

    Parameters (keyword-only, validated here once)
    ----------
    object_name : the Tracker object to follow (names are compared exactly)
    world_to_ned, body_to_object : (3, 3) rotations C_wn and C_bo (see :mod:`.frames`)
    latency_s : Vicon + network latency subtracted from the receive time [s]
    restart_silence_s : a silence longer than this makes any frame number acceptable [s]
    restart_backward_frames : a backward jump larger than this is a Tracker restart
    max_speed : plausibility limit on the implied speed [m/s]
    max_rotation_rate : plausibility limit on the implied rotation rate [rad/s]
    position_slack : position jump always allowed [m]
    angle_slack : rotation always allowed [rad]
    reanchor_after_s : accept any pose this long after the last accepted one [s]
    rate_window_s, min_rate_hz, max_rate_hz, warn_interval_s : see :class:`RateMonitor`
    logger : structlog logger for the rate warning
    """

    def __init__(
        self,
        object_name: str,
        *,
        world_to_ned: npt.ArrayLike = DEFAULT_WORLD_TO_NED,
        body_to_object: npt.ArrayLike = DEFAULT_BODY_TO_OBJECT,
        latency_s: float = 0.005,
        restart_silence_s: float = 1.0,
        restart_backward_frames: int = 1000,
        max_speed: float = 5.0,
        max_rotation_rate: float = 30.0,
        position_slack: float = 0.02,
        angle_slack: float = 0.05,
        reanchor_after_s: float = 0.5,
        rate_window_s: float = 1.0,
        min_rate_hz: float = 8.0,
        max_rate_hz: float = 120.0,
        warn_interval_s: float = 5.0,
        logger: structlog.typing.FilteringBoundLogger | None = None,
    ) -> None:
        nonnegative = {
            "latency_s": latency_s,
            "restart_silence_s": restart_silence_s,
            "restart_backward_frames": restart_backward_frames,
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
        if problems:
            raise ConfigError("invalid Vicon parameters", problems)
        self.object_name = object_name
        self.frames = FrameConversion.create(world_to_ned, body_to_object)
        self.latency_s = latency_s
        self.restart_silence_s = restart_silence_s
        self.restart_backward_frames = restart_backward_frames
        self.max_speed = max_speed
        self.max_rotation_rate = max_rotation_rate
        self.position_slack = position_slack
        self.angle_slack = angle_slack
        self.reanchor_after_s = reanchor_after_s
        self.decoder = DatagramDecoder()
        self.rate = RateMonitor(
            window_s=rate_window_s,
            min_rate_hz=min_rate_hz,
            max_rate_hz=max_rate_hz,
            warn_interval_s=warn_interval_s,
            logger=logger,
        )
        self._last_frame: int | None = None
        self._t_last_frame = -math.inf
        self._last_translation: tuple[float, float, float] | None = None
        self._anchor: Pose | None = None
        self.frames_dropped = self.duplicates = self.reordered = self.restarts = 0
        self.lost_missing = self.lost_zero = self.lost_held_identity = self.non_finite = 0
        self.outliers = self.reanchors = self.poses = 0

    @classmethod
    def from_config(
        cls, config: ViconConfig, logger: structlog.typing.FilteringBoundLogger | None = None
    ) -> PoseFilter:
        """Build from the ``vicon:`` configuration section (see :func:`filter_options`)."""
        return cls(
            config.object_name,
            world_to_ned=config.world_to_ned.as_matrix(),
            body_to_object=config.body_to_object.as_matrix(),
            latency_s=config.latency_s,
            logger=logger,
            **filter_options(config),
        )

    def process(self, datagram: bytes | bytearray | memoryview, t_receive: float) -> Pose | None:
        """Process one datagram received at monotonic time ``t_receive`` [s].

        Returns the object's Pose (t = t_receive - latency_s, NED position [m],
        scalar-first quaternion with R(q) = eCb, Tracker frame number), or None
        if the datagram carries no acceptable measurement. Never raises on bad input.
        """
        result = self.decoder.decode(datagram)
        pose = None
        if not isinstance(result, BadDatagram) and self._accept_frame(result.frame, t_receive):
            pose = self._measure(result, t_receive)
        self.rate.check(t_receive)
        return pose

    def rate_and_age(self, now: float) -> tuple[float, float]:
        """``(pose rate [Hz], time since the last accepted pose [s])`` at ``now``.

        The cheap per-tick subset of :meth:`health`; it also drives the rate-band warning.
        """
        return self.rate.check(now), self.rate.time_since_pose(now)

    def health(self, now: float) -> ViconHealth:
        """Snapshot of rates and counters at monotonic time ``now`` [s].

        Also updates the rate band, so calling this periodically is what warns when
        datagrams stop arriving altogether.
        """
        rate = self.rate.check(now)
        return ViconHealth(
            rate_hz=rate,
            rate_in_band=self.rate.in_band,
            time_since_pose_s=self.rate.time_since_pose(now),
            datagrams=self.decoder.datagrams,
            poses=self.poses,
            rejected=MappingProxyType(dict(self.decoder.rejected)),
            skipped_items=self.decoder.skipped_items,
            frames_dropped=self.frames_dropped,
            duplicates=self.duplicates,
            reordered=self.reordered,
            restarts=self.restarts,
            lost_missing=self.lost_missing,
            lost_zero=self.lost_zero,
            lost_held_identity=self.lost_held_identity,
            non_finite=self.non_finite,
            outliers=self.outliers,
            reanchors=self.reanchors,
            rate_warnings=self.rate.warnings,
        )

    def _accept_frame(self, frame: int, t: float) -> bool:
        """Frame-number bookkeeping; True if the datagram is new (or a restart)."""
        last = self._last_frame
        if last is not None and frame <= last:
            silent = t - self._t_last_frame > self.restart_silence_s
            if not silent and last - frame <= self.restart_backward_frames:
                if frame == last:
                    self.duplicates += 1
                else:
                    self.reordered += 1
                return False
            self.restarts += 1
        elif last is not None:
            self.frames_dropped += frame - last - 1
        self._last_frame = frame
        self._t_last_frame = t
        return True

    def _measure(self, frame: ViconFrame, t_receive: float) -> Pose | None:
        """Lost-tracking checks, conversion and plausibility gate for one frame."""
        obj = frame.find(self.object_name)
        if obj is None:
            self.lost_missing += 1
            return None
        if self._is_lost(obj):
            return None
        position, quaternion = self.frames.to_ned(obj.translation, obj.rotation)
        pose = Pose(t_receive - self.latency_s, position, quaternion, frame.frame)
        if not self._plausible(pose):
            self.outliers += 1
            return None
        self._anchor = pose
        self.poses += 1
        self.rate.record(t_receive)
        return pose

    def _is_lost(self, obj: ObjectPose) -> bool:
        """True (and counted by kind) if the object's values encode lost tracking."""
        x, y, z = obj.translation
        rx, ry, rz = obj.rotation
        if not all(map(math.isfinite, (x, y, z, rx, ry, rz))):
            self.non_finite += 1
            return True
        held = self._last_translation
        self._last_translation = obj.translation
        if rx != 0.0 or ry != 0.0 or rz != 0.0:
            return False
        if x == 0.0 and y == 0.0 and z == 0.0:
            self.lost_zero += 1
            return True
        if held is None or held == obj.translation:
            self.lost_held_identity += 1
            return True
        return False

    def _plausible(self, pose: Pose) -> bool:
        """Speed / rotation-rate gate against the last accepted pose (see module doc)."""
        anchor = self._anchor
        if anchor is None:
            return True
        dt = max(pose.t - anchor.t, 0.0)
        jump = float(np.linalg.norm(pose.position - anchor.position))
        cos_half = min(abs(float(np.dot(pose.quaternion, anchor.quaternion))), 1.0)
        angle = 2.0 * math.acos(cos_half)
        max_jump = self.max_speed * dt + self.position_slack
        max_angle = self.max_rotation_rate * dt + self.angle_slack
        if jump <= max_jump and angle <= max_angle:
            return True
        if dt > self.reanchor_after_s:
            self.reanchors += 1
            return True
        return False
