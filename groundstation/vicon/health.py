"""Health of the Vicon input: measured pose rate, counters, rate-band warnings, evidence.

The Vicon rate is measured, never assumed: the lab must fly anywhere from 10 to
100 Hz and degrade, with a warning, down to 1 Hz (``docs/vicon-udp.md``).
:class:`RateMonitor` counts accepted poses in a sliding window and logs a
structlog warning when the rate leaves the configured band, at most once per
``warn_interval_s``. Sans-IO: every method takes the current monotonic time.
:class:`ViconHealth` is the counters' snapshot (telemetry, ``gs monitor``, the
preflight's :meth:`ViconHealth.diagnosis`); :class:`ViconEvidence` what the flight
reads every tick beyond the poses.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass

import structlog

from groundstation.errors import ConfigError

LOGGER_NAME = "groundstation.vicon"


@dataclass(frozen=True, slots=True)
class ViconHealth:
    """A snapshot of the Vicon input's health (all counters since construction).

    rate_hz : accepted poses per second over the last rate window [Hz]
    rate_in_band : rate_hz within [min_rate_hz, max_rate_hz] (True during the
        first window, before the rate can be measured)
    time_since_pose_s : now minus the receive time of the last accepted pose [s]
        (inf if none yet)
    datagrams : datagrams processed
    poses : poses accepted and returned
    rejected : per-reason count of datagrams rejected whole by the decoder
    skipped_items : items skipped (unknown id, or object size != 72)
    frames_dropped : frames missing from forward gaps in a passed stream's frame numbers
        (only gaps the elapsed time explains: never more than Tracker could have sent)
    duplicates : datagrams repeating their stream's last frame number (dropped)
    reordered : datagrams older than their stream's last frame (dropped)
    restarts : frame-number restarts passed (long silence, a jump no elapsed time
        explains: a Tracker restart or a garbage frame number)
    lost_missing : datagrams without the configured object (other objects only, or none)
    lost_zero : object reported with all six values exactly 0
    lost_held_identity : position held, rotations exactly (0, 0, 0)
    non_finite : object values NaN or infinite
    outliers : poses that agreed with no stream (speed / rotation-rate gate)
    reanchors : streams confirmed after the first: after a gap, or a new sender
    rate_warnings : rate-band warnings logged
    implausible_position : poses beyond the sighting range (absurd values; see
        :mod:`.plausibility`)
    implausible_rotation : Euler angles beyond a turn, or not converting to a rotation
    unconfirmed : poses held back because their stream had fewer than
        ``reanchor_poses`` consistent poses in a row (start-up, after a gap, new sender),
        or was confirmed but neither followed nor a rival (yet)
    outside : confirmed poses of the followed stream outside the plausible volume
        (sightings of the vehicle beyond it; never passed on)
    rivals : confirmed streams of the object fed at the same time as the followed one
        (their poses alternating with its poses, see :mod:`.streams`), now (0: one sender)
    rival_events : rival-stream episodes so far
    rival_poses : confirmed poses of rival streams (never passed on)
    """

    rate_hz: float
    rate_in_band: bool
    time_since_pose_s: float
    datagrams: int
    poses: int
    rejected: Mapping[str, int]
    skipped_items: int
    frames_dropped: int
    duplicates: int
    reordered: int
    restarts: int
    lost_missing: int
    lost_zero: int
    lost_held_identity: int
    non_finite: int
    outliers: int
    reanchors: int
    rate_warnings: int
    implausible_position: int
    implausible_rotation: int
    unconfirmed: int
    outside: int
    rivals: int
    rival_events: int
    rival_poses: int

    @property
    def rejected_datagrams(self) -> int:
        """Total datagrams rejected whole by the decoder."""
        return sum(self.rejected.values())

    def refusals(self) -> list[tuple[int, str]]:
        """``(count, reason)`` for every way a datagram gave no pose, in pipeline order,
        non-zero counts only; with :attr:`poses` they add up to :attr:`datagrams`."""
        reasons = [
            (self.rejected_datagrams, "malformed"),
            (self.lost_missing, "without the object"),
            (self.non_finite, "non-finite"),
            (self.lost_zero, "all-zero lost tracking"),
            (self.lost_held_identity, "held-identity lost tracking"),
            (self.implausible_position, "beyond the sighting range"),
            (self.implausible_rotation, "not a rotation"),
            (self.outliers, "inconsistent"),
            (self.unconfirmed, "unconfirmed"),
            (self.duplicates, "duplicated"),
            (self.reordered, "reordered"),
            (self.rival_poses, "from a rival stream"),
            (self.outside, "outside the volume"),
        ]
        return [(n, reason) for n, reason in reasons if n]

    def diagnosis(self, object_name: str) -> str:
        """One line for a person: ``412 datagrams, 0 poses of 'X3D' passed; refused: 411
        held-identity lost tracking, 1 unconfirmed``."""
        head = f"{self.datagrams} datagrams, {self.poses} poses of {object_name!r} passed"
        refused = ", ".join(f"{n} {reason}" for n, reason in self.refusals())
        return head + ("; refused: " + refused if refused else "; none refused")


@dataclass(frozen=True, slots=True)
class ViconEvidence:
    """What the pose stream says at time ``now`` [s], beyond the poses themselves.

    last_position : NED [m] of the newest pose passed on (None if none yet)
    last_age_s : now minus the receive time of that pose [s] (inf if none)
    outside : NED [m] of the newest confirmed sighting beyond the plausible volume, if it
        is newer than the newest pose passed on and at most ``reanchor_after_s`` old;
        else None
    rivals : confirmed streams of our object other than the followed one that were fed
        within the last ``reanchor_after_s`` at the same time as it (their poses
        alternating with its poses, see :mod:`.streams`; 0: one sender)
    rival_events : rival-stream episodes so far
    """

    last_position: tuple[float, float, float] | None
    last_age_s: float
    outside: tuple[float, float, float] | None
    rivals: int
    rival_events: int


class RateMonitor:
    """Sliding-window rate of accepted poses with a rate-limited out-of-band warning.

    window_s : sliding window length [s]; the rate is (poses in window) / window_s
    min_rate_hz, max_rate_hz : the band outside which a warning is logged [Hz]
    warn_interval_s : minimum time between two warnings [s]
    logger : structlog logger (default ``structlog.get_logger("groundstation.vicon")``)
    """

    def __init__(
        self,
        *,
        window_s: float = 1.0,
        min_rate_hz: float = 8.0,
        max_rate_hz: float = 120.0,
        warn_interval_s: float = 5.0,
        logger: structlog.typing.FilteringBoundLogger | None = None,
    ) -> None:
        if not window_s > 0.0 or not warn_interval_s >= 0.0:
            raise ConfigError(
                "rate window must be > 0 and warn interval >= 0",
                [("rate_window_s", window_s, "> 0"), ("warn_interval_s", warn_interval_s, ">= 0")],
            )
        if not 0.0 <= min_rate_hz <= max_rate_hz:
            raise ConfigError(
                f"rate band [{min_rate_hz}, {max_rate_hz}] Hz is empty or negative",
                [("min_rate_hz", min_rate_hz, "0 <= min <= max"), ("max_rate_hz", max_rate_hz, "")],
            )
        self.window_s = window_s
        self.min_rate_hz = min_rate_hz
        self.max_rate_hz = max_rate_hz
        self.warn_interval_s = warn_interval_s
        self._log = logger if logger is not None else structlog.get_logger(LOGGER_NAME)
        self._times: deque[float] = deque()
        self._t_first: float | None = None
        self._t_last_pose = -math.inf
        self._t_last_warning = -math.inf
        self.in_band = True
        self.warnings = 0

    def record(self, t: float) -> None:
        """Record one accepted pose received at monotonic time ``t`` [s]."""
        if self._t_first is None:
            self._t_first = t
        self._times.append(t)
        self._t_last_pose = t

    def rate(self, now: float) -> float:
        """Accepted poses per second over the window ending at ``now`` [Hz]."""
        times = self._times
        start = now - self.window_s
        while times and times[0] <= start:
            times.popleft()
        return len(times) / self.window_s

    def time_since_pose(self, now: float) -> float:
        """``now`` minus the last recorded pose time [s] (inf if none)."""
        return now - self._t_last_pose

    def check(self, now: float) -> float:
        """Update the band state at ``now``, warn if out of band; return the rate [Hz].

        No verdict before one full window has passed since the first call.
        """
        if self._t_first is None:
            self._t_first = now
        rate = self.rate(now)
        if now - self._t_first < self.window_s:
            return rate
        if self.min_rate_hz <= rate <= self.max_rate_hz:
            if not self.in_band:
                self._log.info("vicon_rate_recovered", rate_hz=rate)
            self.in_band = True
            return rate
        self.in_band = False
        if now - self._t_last_warning >= self.warn_interval_s:
            self._t_last_warning = now
            self.warnings += 1
            self._log.warning(
                "vicon_rate_out_of_band",
                rate_hz=rate,
                min_rate_hz=self.min_rate_hz,
                max_rate_hz=self.max_rate_hz,
                time_since_pose_s=self.time_since_pose(now),
            )
        return rate
