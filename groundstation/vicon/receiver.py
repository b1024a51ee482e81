"""The Vicon object stream's UDP receiver: a thin I/O shell around :class:`PoseFilter`.

A reader thread receives datagrams on a UDP socket bound to the configured
address and port, stamps each one with the monotonic receive time and feeds it to
a :class:`PoseFilter` (decoding, frame bookkeeping, lost-tracking and outlier
rejection, conversion to NED: see :mod:`.posefilter` and :mod:`.frames`). Poses
come out through :meth:`ViconReceiver.get` (next pose, blocking) or
:meth:`ViconReceiver.latest` (newest pose, non-blocking); :meth:`ViconReceiver.evidence`
(rival streams, sightings outside the volume) and :meth:`ViconReceiver.diagnosis`
read the filter under the same lock.

Socket errors become :class:`groundstation.errors.ViconError` (``raise ... from``).
A reader that fails does not die silently: its error is stored and raised, as a
ViconError, by the next call to ``get``, ``latest`` or ``health``.
"""

from __future__ import annotations

import collections
import contextlib
import socket
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from types import TracebackType
from typing import Literal, Unpack

import numpy.typing as npt
import structlog

from groundstation.errors import ViconError
from groundstation.types import Pose
from groundstation.vicon.frames import (
    DEFAULT_BODY_TO_OBJECT,
    DEFAULT_WORLD_TO_NED,
)
from groundstation.vicon.health import ViconEvidence, ViconHealth
from groundstation.vicon.posefilter import FilterOptions, PoseFilter, PoseFilterParams

DEFAULT_PORT = 51001
MAX_DATAGRAM = 65536


@dataclass(frozen=True, slots=True)
class ViconParams:
    """The Vicon stream: the UDP ``bind_address`` and ``port`` it arrives on, and the
    pose ``filter`` every datagram goes through; ``source`` says who receives it:
    ``udp``, this receiver; ``zenoh``, a fleet's relay, whose items go through the same
    filter (:mod:`groundstation.fleet.posesource`)."""

    bind_address: str
    port: int
    filter: PoseFilterParams
    source: Literal["udp", "zenoh"]


class ViconReceiver:
    """Receive one object's pose from Vicon Tracker over UDP.

    bind_address : local address to bind ("0.0.0.0" for all interfaces)
    port : UDP port (Tracker's default 51001; 0 picks a free port, see :attr:`address`)
    object_name : the Tracker object to follow
    world_to_ned, body_to_object : (3, 3) rotations C_wn, C_bo (see :mod:`.frames`)
    latency_s : subtracted from the monotonic receive time to stamp each pose [s]
    rcvbuf_bytes : requested SO_RCVBUF (the kernel may cap it at net.core.rmem_max)
    queue_size : poses kept for :meth:`get`; the oldest are dropped when full
    clock : monotonic clock [s] used to stamp datagrams (default time.monotonic)
    poll_interval_s : reader wake-up interval to notice :meth:`close` [s]
    logger : structlog logger (default ``structlog.get_logger("groundstation.vicon")``)
    **filter_options : frame-restart, plausibility-gate and rate-band parameters,
        passed to :class:`PoseFilter` (see :class:`FilterOptions`)

    The filter is available as :attr:`filter` (read it only through :meth:`health`
    while the reader runs).
    """

    def __init__(
        self,
        bind_address: str,
        port: int,
        object_name: str,
        world_to_ned: npt.ArrayLike = DEFAULT_WORLD_TO_NED,
        body_to_object: npt.ArrayLike = DEFAULT_BODY_TO_OBJECT,
        latency_s: float = 0.005,
        *,
        rcvbuf_bytes: int = 1 << 20,
        queue_size: int = 64,
        clock: Callable[[], float] = time.monotonic,
        poll_interval_s: float = 0.1,
        logger: structlog.typing.FilteringBoundLogger | None = None,
        **filter_options: Unpack[FilterOptions],
    ) -> None:
        self.filter = PoseFilter(
            object_name,
            world_to_ned=world_to_ned,
            body_to_object=body_to_object,
            latency_s=latency_s,
            logger=logger,
            **filter_options,
        )
        self._bind = (bind_address, port)
        self._rcvbuf_bytes = rcvbuf_bytes
        self._clock = clock
        self._poll_interval_s = poll_interval_s
        self._log = logger if logger is not None else structlog.get_logger("groundstation.vicon")
        self._cond = threading.Condition()
        self._queue: collections.deque[Pose] = collections.deque(maxlen=queue_size)
        self._latest: Pose | None = None
        self._failure: BaseException | None = None
        self._stop = threading.Event()
        self._sock: socket.socket | None = None
        self._thread: threading.Thread | None = None
        self._closed = False

    @classmethod
    def from_params(
        cls,
        params: ViconParams,
        *,
        clock: Callable[[], float] = time.monotonic,
        logger: structlog.typing.FilteringBoundLogger | None = None,
    ) -> ViconReceiver:
        """Build (not start) a receiver as ``params`` describe it."""
        f = params.filter
        return cls(params.bind_address, params.port, f.object_name, f.world_to_ned,
                   f.body_to_object, f.latency_s, clock=clock, logger=logger, **f.options())

    # -- lifecycle -------------------------------------------------------------

    def start(self) -> ViconReceiver:
        """Bind the socket and start the reader thread (no-op if already started).

        Raises ViconError if the socket cannot be created or bound, or if closed.
        """
        if self._closed:
            raise ViconError("ViconReceiver is closed")
        if self._thread is not None:
            return self
        try:
            sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        except OSError as exc:
            raise ViconError(f"cannot create a UDP socket: {exc}") from exc
        try:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, self._rcvbuf_bytes)
            sock.bind(self._bind)
            sock.settimeout(self._poll_interval_s)
        except OSError as exc:
            sock.close()
            raise ViconError(f"cannot bind UDP {self._bind[0]}:{self._bind[1]}: {exc}") from exc
        self._sock = sock
        self._thread = threading.Thread(target=self._run, name="vicon-reader", daemon=True)
        self._thread.start()
        self._log.info("vicon_listening", address=self.address, object=self.filter.object_name)
        return self

    def close(self) -> None:
        """Stop the reader thread and close the socket; idempotent."""
        if self._closed:
            return
        self._closed = True
        self._stop.set()
        sock, thread = self._sock, self._thread
        if sock is not None:
            # Wake the reader now with an empty datagram to ourselves (it checks the
            # stop flag first); should that fail, the poll interval still ends it.
            with contextlib.suppress(OSError):
                host, port = sock.getsockname()[:2]
                sock.sendto(b"", ("127.0.0.1" if host == "0.0.0.0" else host, port))
        if thread is not None:
            thread.join()
        if sock is not None:
            sock.close()
        with self._cond:
            self._cond.notify_all()

    def __enter__(self) -> ViconReceiver:
        return self.start()

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    # -- user calls ------------------------------------------------------------

    @property
    def address(self) -> tuple[str, int]:
        """The bound (host, port); raises ViconError before :meth:`start`."""
        if self._sock is None:
            raise ViconError("ViconReceiver not started")
        host, port = self._sock.getsockname()[:2]
        return str(host), int(port)

    def fileno(self) -> int:
        """The socket's file descriptor (for select-based callers); -1 once closed."""
        if self._sock is None:
            raise ViconError("ViconReceiver not started")
        return self._sock.fileno()

    def get(self, timeout: float | None = None) -> Pose | None:
        """Return the next pose not yet returned, waiting up to ``timeout`` [s].

        None on timeout or once closed. Raises ViconError if the reader failed.
        """
        with self._cond:
            self._check()
            if not self._queue and not self._closed:
                self._cond.wait_for(
                    lambda: bool(self._queue) or self._failure is not None or self._closed,
                    timeout,
                )
                self._check()
            return self._queue.popleft() if self._queue else None

    def latest(self) -> Pose | None:
        """Return the newest accepted pose (None if none yet); does not wait or consume."""
        with self._cond:
            self._check()
            return self._latest

    def rate_and_age(self) -> tuple[float, float]:
        """``(pose rate [Hz], time since the last accepted pose [s])`` now.

        The cheap per-tick subset of :meth:`health` for the flight loop; it also drives
        the rate-band warning. Raises ViconError if the reader failed.
        """
        with self._cond:
            self._check()
            return self.filter.rate_and_age(self._clock())

    def health(self) -> ViconHealth:
        """Snapshot of rate and counters now; also drives the rate-band warning."""
        with self._cond:
            self._check()
            return self.filter.health(self._clock())

    def evidence(self) -> ViconEvidence:
        """What the stream says now beyond the poses (:meth:`PoseFilter.evidence`): cheap,
        for every loop tick. Raises ViconError if the reader failed."""
        with self._cond:
            self._check()
            return self.filter.evidence(self._clock())

    def diagnosis(self) -> str:
        """One line: datagrams, poses passed and refusals by reason
        (:meth:`PoseFilter.diagnosis`). Works after :meth:`close` too (the counters stay),
        and never raises: it is what a failure message quotes."""
        with self._cond:
            return self.filter.diagnosis()

    # -- internals -------------------------------------------------------------

    def _check(self) -> None:
        """Raise ViconError for use before start or a stored reader failure (lock held)."""
        if self._thread is None:
            raise ViconError("ViconReceiver not started")
        if self._failure is not None:
            raise ViconError(f"Vicon reader failed: {self._failure}") from self._failure

    def _run(self) -> None:
        """Reader thread: receive, stamp, filter, publish; store any failure."""
        sock = self._sock
        assert sock is not None
        buffer = bytearray(MAX_DATAGRAM)
        view = memoryview(buffer)
        try:
            while not self._stop.is_set():
                try:
                    n = sock.recv_into(buffer)
                except TimeoutError:
                    continue
                t_receive = self._clock()
                if self._stop.is_set():
                    return
                with self._cond:
                    pose = self.filter.process(view[:n], t_receive)
                    if pose is not None:
                        self._latest = pose
                        self._queue.append(pose)
                        self._cond.notify_all()
        except Exception as exc:  # stored and re-raised to the user, never lost
            if self._stop.is_set() and isinstance(exc, OSError):
                return  # the socket was shut down by close()
            self._log.error("vicon_reader_failed", error=repr(exc))
            with self._cond:
                self._failure = exc
                self._cond.notify_all()
