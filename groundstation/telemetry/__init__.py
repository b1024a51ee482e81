"""Telemetry: a pyzmq PUB socket fed by the flight loop, its schema, a subscriber and
the ``gs monitor`` live view. The message schema is documented in
:mod:`groundstation.telemetry.schema`."""

from groundstation.telemetry.monitor import render, run_monitor
from groundstation.telemetry.publisher import TelemetryPublisher
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
    "TelemetryPublisher",
    "TelemetrySubscriber",
    "health_payload",
    "render",
    "run_monitor",
    "state_payload",
]
