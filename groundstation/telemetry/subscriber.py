"""A telemetry subscriber: connects a SUB socket and returns decoded messages.

``TelemetrySubscriber("tcp://127.0.0.1:5556").receive(1.0)`` gives ``(topic, payload)``
or None on timeout. Malformed messages are counted in
:attr:`TelemetrySubscriber.bad_messages` and skipped. ZeroMQ subscribers join late
(the "slow joiner"): messages published before the connection is made are not
seen, which is fine for a live view.
"""

from __future__ import annotations

import math
import time
from collections.abc import Iterable
from typing import Any

import zmq

from groundstation.errors import TelemetryError
from groundstation.telemetry._zmqowner import ZmqOwner
from groundstation.telemetry.schema import decode


class TelemetrySubscriber(ZmqOwner):
    """Receives telemetry from a :class:`~groundstation.telemetry.publisher.TelemetryPublisher`.

    endpoint : the publisher's endpoint, e.g. ``tcp://127.0.0.1:5556``
    topics : topic prefixes to subscribe to (default: every topic)
    rcvhwm : messages queued before zmq drops the oldest arrivals
    context : a zmq.Context to share (not terminated by :meth:`close`)
    Raises TelemetryError if the endpoint is invalid.
    """

    def __init__(
        self, endpoint: str, topics: Iterable[str] = ("",), *, rcvhwm: int = 100,
        context: zmq.Context[Any] | None = None,
    ) -> None:
        self._open_context(context)
        self.bad_messages = 0
        """Messages that could not be decoded (skipped)."""
        assert self._context is not None  # a subscriber always needs a context
        sock = self._context.socket(zmq.SUB)
        try:
            sock.setsockopt(zmq.LINGER, 0)
            sock.setsockopt(zmq.RCVHWM, rcvhwm)
            for topic in topics:
                sock.setsockopt(zmq.SUBSCRIBE, topic.encode("ascii"))
            sock.connect(endpoint)
        except zmq.ZMQError as exc:
            sock.close(linger=0)
            self._close_context()
            raise TelemetryError(f"telemetry: cannot connect {endpoint!r}: {exc}") from exc
        self._socket: zmq.Socket[Any] | None = sock
        self.endpoint = endpoint

    def receive(self, timeout: float | None = None) -> tuple[str, dict[str, Any]] | None:
        """The next ``(topic, payload)``, or None if none arrives within ``timeout`` [s]
        (None waits forever). Raises TelemetryError if the subscriber is closed."""
        if self._socket is None:
            raise TelemetryError("telemetry subscriber is closed")
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            wait_ms = None if deadline is None else max(0, math.ceil(
                (deadline - time.monotonic()) * 1e3))
            if not self._socket.poll(wait_ms, zmq.POLLIN):
                return None
            frames = self._socket.recv_multipart(zmq.NOBLOCK)
            try:
                return decode(frames)
            except (ValueError, UnicodeError):
                self.bad_messages += 1

    def close(self) -> None:
        """Close the socket and, if the subscriber owns it, terminate the context (idempotent)."""
        self._close_socket()
