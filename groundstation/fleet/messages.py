"""The fleet's binary messages: frozen, slotted records with a class-level ``struct``.

Each has ``pack() -> bytes`` and ``unpack(data) -> record``; ``unpack`` raises
:class:`~groundstation.errors.ProtocolError` for bytes that are not one (wrong length or
version), never anything else, so a receiver counts them and goes on. All little-endian.

* :class:`RelayedPose`: one Vicon object item as ``gs vicon-relay`` received it.
* :class:`PeerPose`: a vehicle's estimated pose for its peers' separation checks.
* :class:`Intent`: where a vehicle is planned to be (its motion's path, sampled).
"""

from __future__ import annotations

import math
import struct
import uuid
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

import numpy as np

from groundstation.errors import ProtocolError
from groundstation.types import FloatArray

VERSION = 1
"""Version byte every message starts with."""


def _boot_id() -> bytes:
    """16 bytes naming this machine's boot: two processes that read the same value share
    one ``CLOCK_MONOTONIC`` (Linux's ``/proc/sys/kernel/random/boot_id``); elsewhere a
    random value per process, so no other process takes its stamps for its own clock."""
    try:
        return uuid.UUID(Path("/proc/sys/kernel/random/boot_id").read_text().strip()).bytes
    except (OSError, ValueError):
        return uuid.uuid4().bytes


BOOT_ID = _boot_id()
"""This process's :func:`_boot_id`."""


def _version(data: bytes, what: str, size: int) -> None:
    if len(data) != size:
        raise ProtocolError(f"{what}: {len(data)} bytes, expected {size}")
    if data[0] != VERSION:
        raise ProtocolError(f"{what}: version {data[0]}, expected {VERSION}")


@dataclass(frozen=True, slots=True)
class RelayedPose:
    """One object item of Tracker's stream, as the relay received it (Vicon's own units).

    frame : Tracker's frame number (uint32)
    t_receive_ns : the relay's ``time.monotonic_ns()`` when the datagram arrived [ns]
    t_publish_ns : the relay's ``time.monotonic_ns()`` when this was published [ns]
    boot : the relay's :data:`BOOT_ID` (equal to the receiver's: the stamps are on its
        own monotonic clock)
    translation : (x, y, z) in Vicon's world frame [mm]
    rotation : (rx, ry, rz) Euler angles, intrinsic X then Y then Z [rad] (docs/vicon-udp.md)
    """

    STRUCT: ClassVar[struct.Struct] = struct.Struct("<BxxxIqq16s3d3d")

    frame: int
    t_receive_ns: int
    t_publish_ns: int
    boot: bytes
    translation: tuple[float, float, float]
    rotation: tuple[float, float, float]

    def pack(self) -> bytes:
        """The wire bytes (88)."""
        return self.STRUCT.pack(VERSION, self.frame, self.t_receive_ns, self.t_publish_ns,
                                self.boot, *self.translation, *self.rotation)

    @classmethod
    def unpack(cls, data: bytes) -> RelayedPose:
        """From the wire; ProtocolError for anything else."""
        _version(data, "relayed pose", cls.STRUCT.size)
        _, frame, t_rx, t_pub, boot, x, y, z, rx, ry, rz = cls.STRUCT.unpack(data)
        return cls(frame, t_rx, t_pub, boot, (x, y, z), (rx, ry, rz))


@dataclass(frozen=True, slots=True)
class PeerPose:
    """A vehicle's estimate for its peers, published at ``fleet.pose_rate_hz``.

    state : the supervisor's state (its integer, ``flight.supervisor.State``)
    seq : a counter from the sender (gaps: messages lost)
    position : NED [m]; quaternion : scalar first, body FRD -> NED; velocity : NED [m/s]
    (all NaN before the estimator runs)
    """

    STRUCT: ClassVar[struct.Struct] = struct.Struct("<BBxxI3d4d3d")

    state: int
    seq: int
    position: tuple[float, float, float]
    quaternion: tuple[float, float, float, float]
    velocity: tuple[float, float, float]

    def pack(self) -> bytes:
        """The wire bytes (88)."""
        return self.STRUCT.pack(VERSION, self.state, self.seq, *self.position,
                                *self.quaternion, *self.velocity)

    @classmethod
    def unpack(cls, data: bytes) -> PeerPose:
        """From the wire; ProtocolError for anything else."""
        _version(data, "peer pose", cls.STRUCT.size)
        _, state, seq, *v = cls.STRUCT.unpack(data)
        return cls(state, seq, (v[0], v[1], v[2]), (v[3], v[4], v[5], v[6]),
                   (v[7], v[8], v[9]))

    @property
    def known(self) -> bool:
        """The sender had an estimate (its position is finite)."""
        return all(math.isfinite(v) for v in self.position)


MAX_INTENT_POINTS = 4096
"""Most points an :class:`Intent` carries (96 KiB)."""


@dataclass(frozen=True, slots=True)
class Intent:
    """Where a vehicle is planned to be: points of its motion's path, NED [m].

    seq : the sender's plan counter; step_m : the largest distance between consecutive
    points of the path [m] (a point of the path is within ``step_m / 2`` of a sample);
    points : (N, 3) NED [m], N <= :data:`MAX_INTENT_POINTS`
    """

    HEADER: ClassVar[struct.Struct] = struct.Struct("<BxxxIId")

    seq: int
    step_m: float
    points: FloatArray

    def pack(self) -> bytes:
        """The wire bytes: the header, then N x 3 float64."""
        pts = np.ascontiguousarray(self.points, dtype="<f8").reshape(-1, 3)
        if len(pts) > MAX_INTENT_POINTS:
            raise ProtocolError(f"intent of {len(pts)} points, at most {MAX_INTENT_POINTS}")
        return self.HEADER.pack(VERSION, self.seq, len(pts), self.step_m) + pts.tobytes()

    @classmethod
    def unpack(cls, data: bytes) -> Intent:
        """From the wire; ProtocolError for anything else (also a point that is not
        finite)."""
        size = cls.HEADER.size
        if len(data) < size or data[0] != VERSION:
            raise ProtocolError("intent: short or of another version")
        _, seq, n, step = cls.HEADER.unpack_from(data)
        if n > MAX_INTENT_POINTS or len(data) != size + 24 * n:
            raise ProtocolError(f"intent: {len(data)} bytes for {n} points")
        points = np.frombuffer(data, dtype="<f8", offset=size).reshape(n, 3).astype(float)
        if not (math.isfinite(step) and step >= 0.0 and np.isfinite(points).all()):
            raise ProtocolError("intent: a value that is not finite")
        return cls(seq, step, points)
