"""X-3D serial protocol (``docs/protocol.md``), byte for byte.

Modules, bottom up:

* :mod:`~groundstation.asctec.crc`: CRC16 (profiles asctec/kermit/mcrf4xx).
* :mod:`~groundstation.asctec.blocks`: DATA sensor blocks and mask arithmetic.
* :mod:`~groundstation.asctec.messages`: CONFIG, COMMAND, DATA and the registry.
* :mod:`~groundstation.asctec.decoder`: sans-IO stream decoder, frame encoder.
* :mod:`~groundstation.asctec.channels`: per-channel handover, bumpless transfer.
* :mod:`~groundstation.asctec.keepalive`: COMMAND keep-alive policy (sans-IO).
* :mod:`~groundstation.asctec.stats`: DATA stream health, link statistics record.
* :mod:`~groundstation.asctec.link`: the pyserial link (the only I/O here).
"""

from groundstation.asctec.blocks import (
    SENSOR_BLOCKS,
    AxisCounts,
    RcBlock,
    SensorBlock,
    StatusBlock,
    data_payload_size,
    sensor_mask,
)
from groundstation.asctec.channels import ChannelHandover
from groundstation.asctec.decoder import RejectedFrame, StreamDecoder, encode_frame
from groundstation.asctec.link import ReceivedData, SerialLink
from groundstation.asctec.messages import (
    MESSAGE_TYPES,
    CommandMsg,
    ConfigMsg,
    DataMsg,
    Message,
    RejectReason,
    channel_mask,
    mask_channels,
)
from groundstation.asctec.stats import LinkStats
from groundstation.types import CHANNELS, Channel

__all__ = [
    "CHANNELS",
    "MESSAGE_TYPES",
    "SENSOR_BLOCKS",
    "AxisCounts",
    "Channel",
    "ChannelHandover",
    "CommandMsg",
    "ConfigMsg",
    "DataMsg",
    "LinkStats",
    "Message",
    "RcBlock",
    "ReceivedData",
    "RejectReason",
    "RejectedFrame",
    "SensorBlock",
    "SerialLink",
    "StatusBlock",
    "StreamDecoder",
    "channel_mask",
    "data_payload_size",
    "encode_frame",
    "mask_channels",
    "sensor_mask",
]
