"""Run-time requests to a flying daemon: a pyzmq REP socket the loop polls (``gs channels``).

A lab user tuning one axis hands the others to the pilot while flying (thesis
Ch. 1.2: "only thrust automatic while tuning altitude"). ``gs channels thrust``
sends a request; the daemon answers within one tick.

Wire format, one JSON object per message (UTF-8):

* request ``{"request": "channels", "auto": ["thrust", ...]}`` puts exactly these
  channels under ground-station control (bumpless, see
  :mod:`groundstation.asctec.channels`); without ``"auto"`` it only reports;
* reply ``{"ok": true, "auto": [...], "state": "TRACK"}`` or
  ``{"ok": false, "error": "why"}``.

The loop calls :meth:`ControlServer.poll` once per tick after its COMMAND is
written: one non-blocking receive, at most one request answered, so a request
never delays a command. A malformed request gets an error reply and is counted;
it never raises into the loop.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from typing import Any

import structlog
import zmq

from groundstation.config import TelemetryConfig
from groundstation.errors import TelemetryError
from groundstation.telemetry._zmqowner import ZmqOwner

log = structlog.get_logger(__name__)

Request = dict[str, Any]
Reply = dict[str, Any]


class ControlServer(ZmqOwner):
    """The daemon's end: a bound REP socket answered from the flight loop.

    endpoint : where to bind, e.g. ``tcp://127.0.0.1:5557`` or ``tcp://127.0.0.1:*``
        (see :attr:`endpoint`); None makes a disabled server whose poll does nothing
    Raises TelemetryError if the socket cannot be bound.
    """

    def __init__(self, endpoint: str | None, *, context: zmq.Context[Any] | None = None) -> None:
        self.endpoint: str | None = None
        """The bound endpoint with the actual port (None when disabled)."""
        self.answered = 0
        """Requests answered (including error replies)."""
        self.bad_requests = 0
        """Requests that were not a JSON object or that the handler failed on."""
        self._open_context(context, needed=endpoint is not None)
        self._socket: zmq.Socket[Any] | None = None
        if endpoint is not None:
            self.endpoint = self._bind_socket(zmq.REP, endpoint, "control")

    @classmethod
    def from_config(cls, config: TelemetryConfig,
                    context: zmq.Context[Any] | None = None) -> ControlServer:
        """A server on ``telemetry.control_endpoint`` (disabled when it is null)."""
        return cls(config.control_endpoint, context=context)

    def poll(self, handler: Callable[[Request], Reply]) -> bool:
        """Answer at most one waiting request with ``handler(request)``; never blocks.

        Returns True if a request was answered.
        """
        if self._socket is None:
            return False
        try:
            raw = self._socket.recv(zmq.NOBLOCK)
        except zmq.Again:
            return False
        try:
            request = json.loads(raw)
            if not isinstance(request, dict):
                raise ValueError("the request must be a JSON object")
            reply = handler(request)
        except ValueError as exc:  # includes json.JSONDecodeError and UnicodeDecodeError
            self.bad_requests += 1
            reply = {"ok": False, "error": f"malformed request: {exc}"}
        except Exception as exc:  # a handler bug must not stop the flight
            self.bad_requests += 1
            log.exception("control request failed")
            reply = {"ok": False, "error": f"request failed: {exc}"}
        self._socket.send(json.dumps(reply).encode(), zmq.NOBLOCK)
        self.answered += 1
        return True


def send_request(endpoint: str, request: Request, timeout_s: float = 2.0) -> Reply:
    """Send one request to a daemon's control endpoint and return its reply.

    Raises TelemetryError if no reply arrives within ``timeout_s`` (no daemon
    flying, or the endpoint is wrong) or the reply is not a JSON object.
    """
    context = zmq.Context()
    sock = context.socket(zmq.REQ)
    try:
        sock.setsockopt(zmq.LINGER, 0)
        try:
            sock.connect(endpoint)
        except zmq.ZMQError as exc:
            raise TelemetryError(f"control: bad endpoint {endpoint!r}: {exc}") from exc
        sock.send(json.dumps(request).encode())
        if not sock.poll(int(timeout_s * 1000), zmq.POLLIN):
            raise TelemetryError(f"control: no reply from {endpoint} within {timeout_s:g} s "
                                 "(is a flight running, with telemetry.control_endpoint set?)")
        try:
            reply = json.loads(sock.recv())
        except ValueError as exc:
            raise TelemetryError(f"control: malformed reply from {endpoint}: {exc}") from exc
        if not isinstance(reply, dict):
            raise TelemetryError(f"control: malformed reply from {endpoint}: {reply!r}")
        return reply
    finally:
        sock.close(linger=0)
        context.term()
