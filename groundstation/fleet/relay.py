"""``gs vicon-relay``: receive Tracker's UDP object stream once, publish every object.

Today a daemon binds the Vicon port itself, so a second daemon on the same host cannot
receive the same stream. The relay binds it instead and, for each datagram, stamps it
with its monotonic receive time, decodes it with the project's sans-IO decoder, checks
each object item (every value finite, the raw values within the sighting range and one
turn: :meth:`~groundstation.vicon.plausibility.Plausibility.raw`) and publishes the items
that pass as :class:`~groundstation.fleet.messages.RelayedPose` on
``<fleet>/vicon/<object>``. Lost-tracking encodings (all zeros, the held identity) are
plausible values and are relayed: the daemon's pose filter reads them as "no
measurement" as it would from UDP. A datagram that is malformed, or an item that is not
finite or implausible, is counted and not relayed. A Tracker restart, a second sender on
the port: relayed as they come, for the daemons' pose filters to judge.

The relay's counters go to ``<fleet>/relay/health`` once a second (JSON).
"""

from __future__ import annotations

import contextlib
import json
import math
import socket
import threading
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from typing import TYPE_CHECKING, Any

import structlog

from groundstation.errors import FleetError, ViconError
from groundstation.fleet import keys
from groundstation.fleet.messages import BOOT_ID, RelayedPose
from groundstation.vicon.decoder import DatagramDecoder, ViconFrame
from groundstation.vicon.plausibility import Plausibility
from groundstation.vicon.receiver import MAX_DATAGRAM

if TYPE_CHECKING:
    import zenoh

log = structlog.get_logger(__name__)

HEALTH_PERIOD_S = 1.0
"""How often the relay publishes its counters [s]."""

KEY_FORBIDDEN = frozenset("/*$#?")
"""Characters a Zenoh key chunk cannot hold: an object named with one is not relayed."""


@dataclass
class RelayStats:
    """The relay's counters.

    datagrams : datagrams received; rejected : malformed ones by reason (decoder)
    items : object items relayed, by object; non_finite, implausible : items not relayed
    unkeyable : items whose name cannot be a Zenoh key chunk; publish_errors : puts that
    failed
    """

    datagrams: int = 0
    rejected: dict[str, int] = field(default_factory=dict)
    items: dict[str, int] = field(default_factory=dict)
    non_finite: int = 0
    implausible: int = 0
    unkeyable: int = 0
    publish_errors: int = 0


class ViconRelay:
    """Receive the Vicon UDP stream on ``bind_address:port`` and publish every object on
    ``session`` under ``fleet``'s prefix (see the module docstring).

    plausibility : the raw-value check (the fleet's plausible volume); clock_ns : the
    monotonic clock stamping datagrams [ns]; poll_interval_s : the reader's wake-up to
    notice :meth:`close` [s]
    """

    def __init__(self, session: zenoh.Session, fleet: str, bind_address: str, port: int,
                 plausibility: Plausibility, *,
                 clock_ns: Callable[[], int] = time.monotonic_ns,
                 poll_interval_s: float = 0.1) -> None:
        self._session = session
        self._fleet = fleet
        self._bind = (bind_address, port)
        self._plausibility = plausibility
        self._clock_ns = clock_ns
        self._poll = poll_interval_s
        self._decoder = DatagramDecoder()
        self._publishers: dict[str, Any] = {}
        self.stats = RelayStats()
        self._sock: socket.socket | None = None
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._health: Any = None
        self._next_health = 0.0

    @property
    def address(self) -> tuple[str, int]:
        """The bound (host, port); ViconError before :meth:`start`."""
        if self._sock is None:
            raise ViconError("the relay is not started")
        host, port = self._sock.getsockname()[:2]
        return str(host), int(port)

    def start(self) -> ViconRelay:
        """Bind the UDP port and start the reader thread. ViconError if it cannot be
        bound (another relay, or a daemon reading the stream itself)."""
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
            sock.bind(self._bind)
            sock.settimeout(self._poll)
        except OSError as exc:
            sock.close()
            raise ViconError(f"cannot bind UDP {self._bind[0]}:{self._bind[1]}: {exc}") from exc
        self._sock = sock
        self._health = self._session.declare_publisher(keys.relay_health_key(self._fleet))
        self._thread = threading.Thread(target=self._run, name="vicon-relay", daemon=True)
        self._thread.start()
        log.info("vicon relay listening", address=self.address,
                 key=keys.vicon_key(self._fleet, "*"))
        return self

    def close(self) -> None:
        """Stop the reader and close the socket (idempotent)."""
        self._stop.set()
        sock, thread = self._sock, self._thread
        if sock is not None:
            with contextlib.suppress(OSError):  # wake the reader at once
                host, port = sock.getsockname()[:2]
                sock.sendto(b"", ("127.0.0.1" if host == "0.0.0.0" else host, port))
        if thread is not None:
            thread.join()
            self._thread = None
        if sock is not None:
            sock.close()
            self._sock = None

    def __enter__(self) -> ViconRelay:
        return self.start()

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    def counters(self) -> dict[str, Any]:
        """The counters as JSON-able values."""
        out = asdict(self.stats)
        out["rejected"] = dict(self._decoder.rejected)
        return out

    # ------------------------------------------------------------------ the reader
    def _run(self) -> None:
        sock = self._sock
        assert sock is not None
        buffer = bytearray(MAX_DATAGRAM)
        view = memoryview(buffer)
        while not self._stop.is_set():
            try:
                n = sock.recv_into(buffer)
            except TimeoutError:
                self._maybe_health()
                continue
            except OSError as exc:
                if not self._stop.is_set():
                    log.error("vicon relay socket failed", error=str(exc))
                return
            t_ns = self._clock_ns()
            if self._stop.is_set():
                return
            try:
                self.relay(view[:n], t_ns)
            except Exception:  # a bug of ours must not stop the stream for every vehicle
                log.exception("vicon relay failed on a datagram")
            self._maybe_health()

    def relay(self, datagram: bytes | bytearray | memoryview, t_receive_ns: int) -> int:
        """Decode one datagram received at ``t_receive_ns`` (monotonic [ns]) and publish its
        plausible object items; returns how many were published."""
        self.stats.datagrams += 1
        frame = self._decoder.decode(datagram)
        if not isinstance(frame, ViconFrame):
            return 0
        published = 0
        for obj in frame.objects:
            values = (*obj.translation, *obj.rotation)
            if not all(math.isfinite(v) for v in values):
                self.stats.non_finite += 1
                continue
            if self._plausibility.raw(obj.translation, obj.rotation) is not None:
                self.stats.implausible += 1
                continue
            if not obj.name or KEY_FORBIDDEN & set(obj.name):
                self.stats.unkeyable += 1
                continue
            message = RelayedPose(frame.frame, t_receive_ns, self._clock_ns(), BOOT_ID,
                                  obj.translation, obj.rotation)
            try:
                self._publisher(obj.name).put(message.pack())
            except Exception as exc:  # zenoh.ZError: counted, the stream goes on
                self.stats.publish_errors += 1
                if self.stats.publish_errors == 1:
                    log.warning("vicon relay could not publish", object=obj.name,
                                error=str(exc))
                continue
            self.stats.items[obj.name] = self.stats.items.get(obj.name, 0) + 1
            published += 1
        return published

    def _publisher(self, name: str) -> Any:
        publisher = self._publishers.get(name)
        if publisher is None:
            import zenoh

            publisher = self._session.declare_publisher(
                keys.vicon_key(self._fleet, name), express=True,
                congestion_control=zenoh.CongestionControl.DROP,
                priority=zenoh.Priority.REAL_TIME)
            self._publishers[name] = publisher
        return publisher

    def _maybe_health(self) -> None:
        now = time.monotonic()
        if now < self._next_health or self._health is None:
            return
        self._next_health = now + HEALTH_PERIOD_S
        try:
            self._health.put(json.dumps(self.counters()).encode())
        except Exception as exc:  # the counters are a convenience, the stream is not
            log.warning("vicon relay health not published", error=str(exc))


def run_relay(session: zenoh.Session, fleet: str, bind_address: str, port: int,
              plausibility: Plausibility, stop: threading.Event,
              on_ready: Callable[[ViconRelay], None] | None = None) -> RelayStats:
    """Relay until ``stop`` is set; returns the counters. FleetError/ViconError if the
    relay cannot start."""
    relay = ViconRelay(session, fleet, bind_address, port, plausibility)
    try:
        relay.start()
    except ViconError:
        raise
    except Exception as exc:
        raise FleetError(f"the relay could not start: {exc}") from exc
    try:
        if on_ready is not None:
            on_ready(relay)
        stop.wait()
    finally:
        relay.close()
    return relay.stats
