"""The vehicle's serial protocols (``docs/protocol.md``), byte for byte: the X-3D's and the
AscTec AutoPilot LL's, and the links that speak them.

Modules, bottom up:

* :mod:`~groundstation.asctec.crc`: CRC16 (profiles asctec/kermit/mcrf4xx).
* :mod:`~groundstation.asctec.blocks`: DATA sensor blocks and mask arithmetic.
* :mod:`~groundstation.asctec.messages`: CONFIG, COMMAND, DATA and the registry.
* :mod:`~groundstation.asctec.decoder`: sans-IO stream decoder, frame encoder.
* :mod:`~groundstation.asctec.ll`: the LL dialect's packets and poll schedule (sans-IO).
* :mod:`~groundstation.asctec.channels`: per-channel handover, bumpless transfer.
* :mod:`~groundstation.asctec.keepalive`: COMMAND keep-alive policy (sans-IO).
* :mod:`~groundstation.asctec.stats`: DATA stream health, link statistics record.
* :mod:`~groundstation.asctec.params`: the link's plain parameter records.
* :mod:`~groundstation.asctec.link` and :mod:`~groundstation.asctec.ll_link`: the two
  pyserial links (X-3D, LL), the only modules here that do I/O.
* :mod:`~groundstation.asctec.dialect`: one :class:`VehicleLink` whichever the dialect;
  :func:`open_link` opens the configured one.

What a user calls: :func:`open_link` with a :class:`LinkParams` (the assembly makes one
from the ``serial`` section), then the :class:`VehicleLink` it returns; the codecs
(:class:`StreamDecoder`, :func:`encode_frame`, the messages) for bytes at hand.
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
from groundstation.asctec.dialect import DIALECTS, VehicleLink, open_link, wire_time_s
from groundstation.asctec.link import ReceivedData, SerialLink
from groundstation.asctec.ll_link import LlLink
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
from groundstation.asctec.params import LinkParams, LlParams
from groundstation.asctec.stats import LinkStats
from groundstation.types import CHANNELS, Channel

__all__ = [
    "CHANNELS",
    "DIALECTS",
    "MESSAGE_TYPES",
    "SENSOR_BLOCKS",
    "AxisCounts",
    "Channel",
    "ChannelHandover",
    "CommandMsg",
    "ConfigMsg",
    "DataMsg",
    "LinkParams",
    "LinkStats",
    "LlLink",
    "LlParams",
    "Message",
    "RcBlock",
    "ReceivedData",
    "RejectReason",
    "RejectedFrame",
    "SensorBlock",
    "SerialLink",
    "StatusBlock",
    "StreamDecoder",
    "VehicleLink",
    "channel_mask",
    "data_payload_size",
    "encode_frame",
    "mask_channels",
    "open_link",
    "sensor_mask",
    "wire_time_s",
]
