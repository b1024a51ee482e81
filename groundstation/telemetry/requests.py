"""Run-time requests to a flying daemon: a pyzmq REP socket the loop polls (``gs channels``).

A lab user tuning one axis hands the others to the pilot while flying (thesis
Ch. 1.2: "only thrust automatic while tuning altitude"). ``gs channels thrust``
sends a request; the daemon answers within one tick.

Wire format, one JSON object per message (UTF-8, one frame, at most
:data:`MAX_PARSED_BYTES`):

* request ``{"request": "channels", "auto": ["thrust", ...]}`` puts exactly these
  channels under ground-station control (bumpless, see
  :mod:`groundstation.asctec.channels`); without ``"auto"`` it only reports;
* reply ``{"ok": true, "auto": [...], "state": "TRACK"}`` or
  ``{"ok": false, "error": "why", "kind": kind}``. Every error reply has a ``kind``:
  ``request`` for one that is not one frame of UTF-8 JSON holding an object (and the
  handler's refusals of malformed requests), ``internal`` when the handler failed (a
  fault of ours, logged), or the handler's own (:mod:`groundstation.app.api`: state,
  volume, infeasible, busy).

Nothing a client sends may crash, stall or wedge the flight loop:

* The daemon answers requests in a thread of its own (:meth:`RequestServer.serve`);
  a request that needs the flight is handed to the loop, which runs it between two
  ticks (:mod:`groundstation.app.api`), so no client ever delays a tick.
  :meth:`RequestServer.poll` handles at most one request and never blocks; a
  multipart message is drained :data:`FRAMES_PER_POLL` frames a poll.
* Every path through a poll is inside one error boundary: a request that is not
  one frame of UTF-8 JSON holding an object gets an error reply and is counted, a
  handler that raises is answered with an error, and a socket that fails is closed
  and bound again (retried every :data:`REOPEN_RETRY_S`). Every request received
  gets its reply, so the REP socket never waits for a send that never comes.
* A message over :data:`MAX_REQUEST_BYTES` never reaches us: libzmq drops its
  sender (``ZMQ_MAXMSGSIZE``) before reading it; one over :data:`MAX_PARSED_BYTES`
  is answered with an error without being parsed.
* The socket binds to loopback unless CURVE authenticates the clients
  (:mod:`groundstation.telemetry.curve`); any other bind is refused.

:meth:`RequestServer.stats` gives the counters the daemon publishes in telemetry.
"""

from __future__ import annotations

import json
import threading
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import structlog
import zmq

from groundstation.endpoints import local_endpoint
from groundstation.errors import TelemetryError
from groundstation.telemetry._zmqowner import ZmqOwner
from groundstation.telemetry.curve import (
    ClientKeyCheck,
    CurveClient,
    CurveServer,
    load_server_keys,
)

log = structlog.get_logger(__name__)

Request = dict[str, Any]
Reply = dict[str, Any]

MAX_REQUEST_BYTES = 64 * 1024
"""Largest message libzmq delivers [bytes] (``ZMQ_MAXMSGSIZE``): it drops a sender of a
larger one without reading it."""

MAX_PARSED_BYTES = 4096
"""Largest request parsed [bytes]; a larger one is answered with an error unparsed. A
request is under 100 bytes; 64 KiB of JSON numbers took 3 ms to parse, 4 KiB 0.2 ms."""

FRAMES_PER_POLL = 64
"""Frames of a multipart message discarded per poll: a flood of frames is drained over
several ticks instead of stalling one."""

RECEIVE_QUEUE = 16
"""Requests queued per client (``ZMQ_RCVHWM``): bounds what a client can make us hold."""

SERVE_WAIT_S = 0.05
"""Longest wait of :meth:`RequestServer.serve` for a request before it checks whether to
stop [s]."""

REOPEN_RETRY_S = 0.05
"""Wait between attempts to bind a failed socket's endpoint again [s]."""

_ERROR_CHARS = 200  # an error reply never echoes a large request back


@dataclass
class RequestStats:
    """The request socket's counters."""

    answered: int = 0
    """Replies sent, error replies included."""
    malformed: int = 0
    """Requests that were not one frame of at most :data:`MAX_PARSED_BYTES` of UTF-8 JSON
    holding an object."""
    failed: int = 0
    """Requests the handler raised on (answered with an error)."""
    frames_discarded: int = 0
    """Extra frames of multipart requests thrown away."""
    refused: int = 0
    """CURVE handshakes refused for a client key that is not authorised."""
    socket_errors: int = 0
    """Times the socket itself failed (it is then closed and bound again)."""
    reopened: int = 0
    """Times a failed socket was bound again."""


@dataclass(frozen=True, slots=True)
class RequestServerParams:
    """The request socket: the ZeroMQ ``endpoint`` it binds (None: no requests), and the
    CURVE ``server_key`` (a ``.key_secret`` file) and ``client_keys`` (a directory of
    ``*.key`` files) that authenticate clients (both None: loopback only)."""

    endpoint: str | None
    server_key: Path | None
    client_keys: Path | None


class RequestServer(ZmqOwner):
    """The daemon's end: a bound REP socket answered from the flight loop.

    endpoint : where to bind, e.g. ``tcp://127.0.0.1:5557`` or ``tcp://127.0.0.1:*``
        (see :attr:`endpoint`); None makes a disabled server whose poll does nothing.
        Anything but loopback, IPC or in-process needs ``curve``.
    curve : authenticate clients with CURVE (:func:`~groundstation.telemetry.curve.
        load_server_keys`); None: no authentication (loopback only)
    Raises TelemetryError if the socket cannot be bound or the bind is refused.
    """

    def __init__(self, endpoint: str | None, *, context: zmq.Context[Any] | None = None,
                 curve: CurveServer | None = None) -> None:
        self.endpoint: str | None = None
        """The bound endpoint with the actual port (None when disabled)."""
        self._stats = RequestStats()
        self._pending: bytes | None = None  # the reply owed to the request received
        self._draining = False  # inside a multipart request, discarding its frames
        self._reopen_at: float | None = None
        self._options: dict[int, int | bytes] = {
            zmq.MAXMSGSIZE: MAX_REQUEST_BYTES, zmq.RCVHWM: RECEIVE_QUEUE}
        self._keycheck: ClientKeyCheck | None = None
        self._auth: Any = None  # zmq.auth.thread.ThreadAuthenticator while CURVE is on
        self._socket: zmq.Socket[Any] | None = None
        if endpoint is not None and curve is None and not local_endpoint(endpoint):
            raise TelemetryError(
                f"control: refusing to bind {endpoint!r} beyond loopback without CURVE "
                "authentication (set telemetry.control_server_key and "
                "telemetry.control_client_keys, or bind 127.0.0.1)")
        self._open_context(context, needed=endpoint is not None)
        if endpoint is None:
            return
        if curve is not None:
            try:
                self._start_authentication(curve)
            except (zmq.ZMQError, RuntimeError) as exc:  # e.g. a ZAP handler already there
                self._close_context()
                raise TelemetryError(f"control: cannot start CURVE authentication: {exc}"
                                     ) from exc
        self.endpoint = self._bind_socket(zmq.REP, endpoint, "control", self._options)

    @classmethod
    def from_params(cls, params: RequestServerParams,
                    context: zmq.Context[Any] | None = None) -> RequestServer:
        """A server as ``params`` describe it (disabled without an endpoint), with CURVE
        when a server key is given. TelemetryError for unusable keys."""
        curve = None
        if params.endpoint is not None and params.server_key is not None:
            if params.client_keys is None:  # the configuration's validator pairs them
                raise TelemetryError("control: telemetry.control_client_keys is not set")
            curve = load_server_keys(params.server_key, params.client_keys)
        return cls(params.endpoint, context=context, curve=curve)

    def _start_authentication(self, curve: CurveServer) -> None:
        from zmq.auth.thread import ThreadAuthenticator

        assert self._context is not None
        self._keycheck = ClientKeyCheck(curve.clients)
        self._auth = ThreadAuthenticator(self._context)
        self._auth.start()
        self._auth.configure_curve_callback("*", credentials_provider=self._keycheck)
        self._options.update({zmq.CURVE_SERVER: 1, zmq.CURVE_PUBLICKEY: curve.public,
                              zmq.CURVE_SECRETKEY: curve.secret})

    # ------------------------------------------------------------------ the loop's side
    def poll(self, handler: Callable[[Request], Reply]) -> bool:
        """Answer at most one waiting request with ``handler(request)``; never blocks and
        never raises. Returns True if a reply went out."""
        if self._socket is None:
            if self._reopen_at is not None and time.monotonic() >= self._reopen_at:
                self._reopen()
            return False
        try:
            if self._pending is None:
                self._pending = self._receive(handler)
                if self._pending is None:
                    return False
            self._socket.send(self._pending, zmq.NOBLOCK)
        except zmq.Again:
            return False  # nothing waiting, or a reply that goes out on a later poll
        except Exception as exc:  # the socket failed: never into the flight loop
            self._socket_failed(exc)
            return False
        self._pending = None
        self._stats.answered += 1
        return True

    def _receive(self, handler: Callable[[Request], Reply]) -> bytes | None:
        """The encoded reply to the waiting request, None if none is complete yet.
        Raises zmq.Again if nothing is waiting."""
        assert self._socket is not None
        sock = self._socket
        if not self._draining:
            first = sock.recv(zmq.NOBLOCK)
            if not sock.getsockopt(zmq.RCVMORE):
                return self._answer(first, handler)
            self._draining = True
        for _ in range(FRAMES_PER_POLL):  # a multipart message arrives whole: never Again
            sock.recv(zmq.NOBLOCK, copy=False)
            self._stats.frames_discarded += 1
            if not sock.getsockopt(zmq.RCVMORE):
                self._draining = False
                return self._malformed("a request is one message frame, "
                                       "this was a multipart message")
        return None

    def _answer(self, raw: bytes, handler: Callable[[Request], Reply]) -> bytes:
        if len(raw) > MAX_PARSED_BYTES:
            return self._malformed(f"{len(raw)} bytes, a request is at most "
                                   f"{MAX_PARSED_BYTES}")
        try:
            text = raw.decode("utf-8")
        except UnicodeDecodeError as exc:
            return self._malformed(f"not UTF-8 text (byte {exc.start} of {len(raw)})")
        try:
            request = json.loads(text)
        except RecursionError:
            return self._malformed("JSON nested too deeply")
        except ValueError as exc:
            return self._malformed(f"not JSON: {exc}")
        if not isinstance(request, dict):
            return self._malformed("the request must be a JSON object")
        try:
            return json.dumps(handler(request)).encode()
        except Exception as exc:  # a handler bug must not stop the flight
            self._stats.failed += 1
            log.exception("control request failed")
            return _error_reply(f"internal error: {type(exc).__name__}: {exc}", "internal")

    def _malformed(self, why: str) -> bytes:
        self._stats.malformed += 1
        return _error_reply(f"malformed request: {why}", "request")

    def _socket_failed(self, exc: Exception) -> None:
        """Close the failed socket (whatever it owed is lost) and bind its endpoint again."""
        self._stats.socket_errors += 1
        log.error("control socket failed, binding it again", error=repr(exc),
                  endpoint=self.endpoint)
        self._pending, self._draining = None, False
        if self._socket is not None:
            self._socket.close(linger=0)
            self._socket = None
        self._reopen_at = time.monotonic()
        self._reopen()

    def _reopen(self) -> None:
        assert self.endpoint is not None
        try:
            self._socket, _ = self._new_bound_socket(zmq.REP, self.endpoint, self._options)
        except zmq.ZMQError:  # the old socket's port is released asynchronously
            self._reopen_at = time.monotonic() + REOPEN_RETRY_S
            return
        self._reopen_at = None
        self._stats.reopened += 1

    def serve(self, handler: Callable[[Request], Reply], stop: threading.Event,
              wait_s: float = SERVE_WAIT_S) -> None:
        """Answer requests with ``handler`` until ``stop`` is set (the daemon runs this in
        a thread of its own, so a handler may take its time without delaying a tick);
        waits at most ``wait_s`` [s] between checks of ``stop``. Never raises."""
        while not stop.is_set():
            sock = self._socket
            if sock is None:  # failed: poll() binds it again when the retry is due
                self.poll(handler)
                stop.wait(wait_s)
                continue
            try:
                ready = self._pending is not None or bool(sock.poll(round(1000 * wait_s)))
            except zmq.ZMQError:
                ready = True  # poll() meets the failure and binds the socket again
            if ready:
                self.poll(handler)

    # ------------------------------------------------------------------ counters, closing
    @property
    def answered(self) -> int:
        """Replies sent, error replies included."""
        return self._stats.answered

    @property
    def bad_requests(self) -> int:
        """Requests answered with an error because they were malformed or the handler failed."""
        return self._stats.malformed + self._stats.failed

    def stats(self) -> dict[str, int]:
        """Every counter of :class:`RequestStats` by name (for telemetry)."""
        if self._keycheck is not None:
            self._stats.refused = self._keycheck.refused
        return asdict(self._stats)

    def _close_context(self) -> None:
        if self._auth is not None:  # its ZAP socket must close before the context ends
            self._auth.stop()
            self._auth = None
        super()._close_context()


def _error_reply(error: str, kind: str) -> bytes:
    if len(error) > _ERROR_CHARS:
        error = error[:_ERROR_CHARS - 3] + "..."
    return json.dumps({"ok": False, "error": error, "kind": kind}).encode()


def send_request(endpoint: str, request: Request, timeout_s: float = 2.0, *,
                 curve: CurveClient | None = None) -> Reply:
    """Send one request to a daemon's control endpoint and return its reply.

    curve : the client's keys and the server's public key, for a daemon that
        authenticates (:func:`~groundstation.telemetry.curve.load_client_keys`)
    Raises TelemetryError if no reply arrives within ``timeout_s`` (no daemon
    flying, the endpoint is wrong, or the daemon does not accept our keys) or the
    reply is not a JSON object.
    """
    context = zmq.Context()
    sock = context.socket(zmq.REQ)
    try:
        sock.setsockopt(zmq.LINGER, 0)
        if curve is not None:
            curve.apply(sock)
        try:
            sock.connect(endpoint)
        except zmq.ZMQError as exc:
            raise TelemetryError(f"control: bad endpoint {endpoint!r}: {exc}") from exc
        sock.send(json.dumps(request).encode())
        if not sock.poll(int(timeout_s * 1000), zmq.POLLIN):
            keys = ("; does the daemon authenticate clients (gs channels --server-key, "
                    "--client-key)?" if curve is None else
                    "; are this client's public key in the daemon's "
                    "telemetry.control_client_keys and --server-key the daemon's?")
            raise TelemetryError(f"control: no reply from {endpoint} within {timeout_s:g} s "
                                 "(is a flight running, with telemetry.control_endpoint set"
                                 f"{keys})")
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
