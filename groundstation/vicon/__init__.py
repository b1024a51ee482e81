"""Vicon Tracker UDP object stream: sans-IO decoder, frame conversion, filter, receiver.

Data flow::

    UDP datagram -> decoder.decode_datagram -> ObjectPose (mm, Euler XYZ)
        -> PoseFilter (lost tracking, plausibility, frames.vicon_to_ned, pose streams with
           their frame numbers, outlier gate and rivals, health)
        -> groundstation.types.Pose (NED m, q scalar first)
           + ViconEvidence per tick (rival streams, sightings outside the volume)

Only :class:`ViconReceiver` touches a socket; everything else is pure and testable
with bytes. The byte layout is ``docs/vicon-udp.md``; the frame
conventions are in :mod:`groundstation.vicon.frames`.
"""

from groundstation.vicon.decoder import (
    BadDatagram,
    DatagramDecoder,
    ObjectPose,
    ViconFrame,
    decode_datagram,
    encode_datagram,
)
from groundstation.vicon.frames import (
    DEFAULT_BODY_TO_OBJECT,
    DEFAULT_WORLD_TO_NED,
    FrameConversion,
    ned_to_vicon,
    vicon_to_ned,
)
from groundstation.vicon.health import RateMonitor, ViconEvidence, ViconHealth
from groundstation.vicon.posefilter import FilterOptions, PoseFilter, PoseFilterParams
from groundstation.vicon.receiver import DEFAULT_PORT, ViconParams, ViconReceiver

__all__ = [
    "DEFAULT_BODY_TO_OBJECT",
    "DEFAULT_PORT",
    "DEFAULT_WORLD_TO_NED",
    "BadDatagram",
    "DatagramDecoder",
    "FilterOptions",
    "FrameConversion",
    "ObjectPose",
    "PoseFilter",
    "PoseFilterParams",
    "RateMonitor",
    "ViconEvidence",
    "ViconFrame",
    "ViconHealth",
    "ViconParams",
    "ViconReceiver",
    "decode_datagram",
    "encode_datagram",
    "ned_to_vicon",
    "vicon_to_ned",
]
