"""Telemetry: a pyzmq PUB socket fed by the flight loop, its schema, a subscriber, the
``gs monitor`` and ``gs foxglove`` live views, and the request socket clients talk to.

The message schema is documented in :mod:`groundstation.telemetry.schema`; the request
socket (``telemetry.control_endpoint``: ``gs channels``, ``gs goto``, the Python client)
in :mod:`groundstation.telemetry.requests`, its CURVE authentication in
:mod:`groundstation.telemetry.curve`.
"""

from groundstation.telemetry.monitor import render, run_monitor
from groundstation.telemetry.publisher import PublisherParams, TelemetryPublisher
from groundstation.telemetry.requests import (
    Reply,
    Request,
    RequestServer,
    RequestServerParams,
    send_request,
)
from groundstation.telemetry.schema import (
    SCHEMA_VERSION,
    TOPIC_HEALTH,
    TOPIC_STATE,
    health_payload,
    state_payload,
)
from groundstation.telemetry.subscriber import TelemetrySubscriber

__all__ = [
    "SCHEMA_VERSION",
    "TOPIC_HEALTH",
    "TOPIC_STATE",
    "PublisherParams",
    "Reply",
    "Request",
    "RequestServer",
    "RequestServerParams",
    "TelemetryPublisher",
    "TelemetrySubscriber",
    "health_payload",
    "render",
    "run_monitor",
    "send_request",
    "state_payload",
]
