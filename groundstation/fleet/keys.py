"""The fleet's Zenoh key expressions, in one place.

Everything a fleet says is under its name (``fleet.name``), so two fleets on one network
never mix::

    <fleet>/vicon/<object>            relayed Vicon item (messages.RelayedPose, binary)
    <fleet>/relay/health              the relay's counters (JSON, 1 Hz)
    <fleet>/<vehicle>/state           the telemetry ``state`` payload (JSON)
    <fleet>/<vehicle>/health          the telemetry ``health`` payload (JSON)
    <fleet>/<vehicle>/reference       the reference tracked (JSON)
    <fleet>/<vehicle>/pose            the estimated pose for the peers (messages.PeerPose)
    <fleet>/<vehicle>/intent          where the vehicle is planned to be (messages.Intent)
    <fleet>/<vehicle>/cmd/<request>   queryable: status, go_to, takeoff, follow, hold,
                                      land, channels (JSON in, JSON reply)

Names are single key chunks (``config.FLEET_NAME``): no ``/`` or wildcard.
"""

from __future__ import annotations

from typing import Final

VICON: Final = "vicon"
RELAY: Final = "relay"
TOPICS: Final = ("state", "health", "reference", "pose", "intent")
"""Per-vehicle publications."""
REQUESTS: Final = ("status", "go_to", "takeoff", "follow", "hold", "land", "channels")
"""Per-vehicle queries: the run-time API's requests (groundstation/app/api.py)."""


def vicon_key(fleet: str, object_name: str) -> str:
    """Where the relay publishes ``object_name``'s items."""
    return f"{fleet}/{VICON}/{object_name}"


def relay_health_key(fleet: str) -> str:
    """Where the relay publishes its counters."""
    return f"{fleet}/{RELAY}/health"


def vehicle_key(fleet: str, vehicle: str, topic: str) -> str:
    """A vehicle's publication ``topic`` (one of :data:`TOPICS`)."""
    return f"{fleet}/{vehicle}/{topic}"


def all_vehicles(fleet: str, topic: str) -> str:
    """Every vehicle's ``topic`` (a subscription's key expression)."""
    return f"{fleet}/*/{topic}"


def request_key(fleet: str, vehicle: str, request: str) -> str:
    """A vehicle's queryable for ``request``; ``vehicle`` may be ``*`` (every vehicle)."""
    return f"{fleet}/{vehicle}/cmd/{request}"


def vehicle_of(key: str) -> str:
    """The vehicle chunk of a per-vehicle key (``lab/x3d-1/pose`` -> ``x3d-1``)."""
    return key.split("/")[1]
