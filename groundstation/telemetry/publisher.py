"""The telemetry publisher: a pyzmq PUB socket the flight loop feeds every tick.

The loop calls :meth:`TelemetryPublisher.maybe_publish` on every tick; it costs
one comparison until a message is due (``rate_hz``), and only then calls the
loop's snapshot function, encodes and sends. Sending never blocks: ``NOBLOCK``,
a small send high-water mark and ``XPUB_NODROP`` so that a full queue (a slow
or stuck subscriber) shows up as ``zmq.Again``, which is counted in
:attr:`TelemetryPublisher.dropped` and the message dropped. Any other error
while publishing (including one raised by the snapshot function) is counted in
:attr:`TelemetryPublisher.errors` and logged once: telemetry never stops a flight.
Message layout: :mod:`groundstation.telemetry.schema`.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import structlog
import zmq

from groundstation.telemetry._zmqowner import ZmqOwner
from groundstation.telemetry.schema import SCHEMA_VERSION, TOPIC_HEALTH, encode

log = structlog.get_logger(__name__)

Snapshot = Mapping[str, Mapping[str, Any]]
"""What a snapshot function returns: topic -> payload body (see schema.py)."""


@dataclass(frozen=True, slots=True)
class PublisherParams:
    """The telemetry publisher: the ZeroMQ ``endpoint`` it binds (None: no telemetry) and
    the ``rate_hz`` [Hz] it publishes snapshots at."""

    endpoint: str | None
    rate_hz: float


class TelemetryPublisher(ZmqOwner):
    """Publishes rate-limited telemetry snapshots on a PUB socket.

    endpoint : where to bind, e.g. ``tcp://127.0.0.1:5556``, ``tcp://*:5556``, or
        ``tcp://127.0.0.1:*`` for a free port (see :attr:`endpoint`); None makes a
        disabled publisher that does nothing
    rate_hz : snapshots per second, > 0
    sndhwm : messages queued per subscriber before dropping (small: stale
        telemetry is worthless, memory is not)
    context : a zmq.Context to share (not terminated by :meth:`close`); by default
        the publisher owns one
    Raises TelemetryError if the socket cannot be bound.
    """

    def __init__(
        self, endpoint: str | None, rate_hz: float = 20.0, *, sndhwm: int = 16,
        context: zmq.Context[Any] | None = None,
    ) -> None:
        if not rate_hz > 0 or sndhwm < 1:
            raise ValueError("rate_hz must be > 0 and sndhwm >= 1")
        self._period = 1.0 / rate_hz
        self._next_due = -float("inf")
        self._seq = 0
        self.sent = 0
        """Messages handed to zmq."""
        self.dropped = 0
        """Messages dropped because a subscriber's queue was full."""
        self.errors = 0
        """Snapshots or sends that failed for another reason."""
        self.endpoint: str | None = None
        """The bound endpoint with the actual port (None when disabled or closed)."""
        self._open_context(context, needed=endpoint is not None)
        self._socket: zmq.Socket[Any] | None = None
        if endpoint is not None:
            self.endpoint = self._bind_socket(
                zmq.PUB, endpoint, "telemetry", {zmq.SNDHWM: sndhwm, zmq.XPUB_NODROP: 1})

    @classmethod
    def from_params(
        cls, params: PublisherParams, context: zmq.Context[Any] | None = None
    ) -> TelemetryPublisher:
        """A publisher as ``params`` describe it (disabled without an endpoint)."""
        return cls(params.endpoint, params.rate_hz, context=context)

    @property
    def enabled(self) -> bool:
        """True while there is a bound socket."""
        return self._socket is not None

    def maybe_publish(self, t: float, snapshot_fn: Callable[[], Snapshot]) -> bool:
        """Publish a snapshot if one is due at monotonic time ``t`` [s]; True if it was.

        Call every tick. ``snapshot_fn`` is called only when due and returns
        ``{topic: body}``; every body gets the envelope and is sent as one message.
        Due times advance by the period without catching up after a pause (no bursts).
        """
        if t < self._next_due or self._socket is None:
            return False
        self._next_due += self._period
        if self._next_due <= t:  # first call, or late by a period or more: restart at t
            self._next_due = t + self._period
        try:
            snapshot = snapshot_fn()
        except Exception:  # a bug in a snapshot must not stop the loop; logged below
            self._error("telemetry snapshot failed")
            return False
        for topic, body in snapshot.items():
            self.publish(topic, body, t)
        return True

    def publish(self, topic: str, body: Mapping[str, Any], t: float) -> bool:
        """Send one message now with the envelope added; True if zmq accepted it.

        A ``health`` body gets the publisher's own counters as its ``telemetry`` section.
        """
        if self._socket is None:
            return False
        self._seq += 1
        payload: dict[str, Any] = {"schema": SCHEMA_VERSION, "topic": topic, "seq": self._seq,
                                   "t": t, "time_unix": time.time(), **body}
        if topic == TOPIC_HEALTH:
            payload["telemetry"] = {"sent": self.sent, "dropped": self.dropped,
                                    "errors": self.errors}
        try:
            self._socket.send_multipart(encode(topic, payload), flags=zmq.NOBLOCK)
        except zmq.Again:
            self.dropped += 1
            return False
        except (zmq.ZMQError, ValueError, TypeError, UnicodeError):
            self._error("telemetry send failed", topic=topic)
            return False
        self.sent += 1
        return True

    def _error(self, event: str, **fields: Any) -> None:
        self.errors += 1
        if self.errors == 1:
            log.warning(event, exc_info=True, **fields)

    def close(self, linger_s: float = 0.0) -> None:
        """Close the socket and, if the publisher owns it, terminate the context.

        Idempotent. Messages not yet sent are discarded, at once by default, or after
        they had up to ``linger_s`` [s] to go out (the flight's final messages).
        """
        if self._socket is not None and linger_s > 0:
            self._socket.close(linger=round(1000 * linger_s))
            self._socket = None
        self._close_socket()
        self.endpoint = None
