"""The serial link to the X-3D on pyserial: reader thread, serialised writes, keep-alive.

:class:`SerialLink` opens any pyserial URL (``serial.serial_for_url``): a device
such as ``/dev/ttyUSB0``, a pty slave path (the virtual X-3D), or ``loop://``.
The port is opened exclusively (pyserial's ``exclusive=True``: an ``flock`` on POSIX),
so a second ground station cannot open a port a flight is using; it gets a
:class:`~groundstation.errors.LinkError` saying the port is in use, and has written
nothing. A reader thread feeds a :class:`~groundstation.asctec.decoder.StreamDecoder`
and queues every DATA message with its monotonic receive time
(``time.monotonic()`` when its last chunk was read) in a bounded queue that
drops the oldest sample when full. Writes are serialised by one lock.

Errors: every pyserial/OS error becomes a :class:`~groundstation.errors.LinkError`
(``raise ... from``). A failure in a background thread is stored, exposed as
:attr:`SerialLink.error`, and re-raised by the next :meth:`get`/:meth:`send`;
the threads never die silently.

While armed (:meth:`arm`), a sender thread guarantees a COMMAND at least every
``1 / command_rate`` s (see :mod:`groundstation.asctec.keepalive` for what it
sends). :meth:`close` is idempotent: it stops the threads, sends a final
COMMAND with ctrl mask 0 if this link ever sent a COMMAND with a non-zero mask
(:attr:`SerialLink.flew`; a link that never flew the vehicle writes nothing on its way
out: the vehicle may be another ground station's), and closes the port.
"""

from __future__ import annotations

import errno
import threading
import time
from collections import deque
from dataclasses import dataclass
from types import TracebackType
from typing import Any, Self

import serial
import structlog

from groundstation.asctec.crc import DEFAULT_PROFILE, profile_init
from groundstation.asctec.decoder import StreamDecoder, encode_frame
from groundstation.asctec.keepalive import GAP_WARNING_S, CommandSchedule
from groundstation.asctec.messages import CommandMsg, ConfigMsg, DataMsg, Message
from groundstation.asctec.params import LinkParams
from groundstation.asctec.stats import DataStreamMonitor, LinkStats
from groundstation.errors import ConfigError, LinkError

_log = structlog.get_logger("groundstation.asctec")


@dataclass(frozen=True, slots=True)
class ReceivedData:
    """One DATA message with its receive time.

    t : monotonic receive time [s] (``time.monotonic()``)
    msg : the decoded DATA message (raw counts)
    """

    t: float
    msg: DataMsg


def _link_error(message: str, cause: BaseException) -> LinkError:
    """A LinkError whose ``__cause__`` is ``cause`` (as ``raise ... from cause``)."""
    error = LinkError(f"{message}: {cause}")
    error.__cause__ = cause
    return error


def _open_port(url: str, baudrate: int, read_timeout: float, write_timeout: float) -> Any:
    """Open ``url`` exclusively with pyserial (8N1, no flow control); LinkError if it fails
    (saying "in use" when another process holds the port's lock)."""
    try:
        return serial.serial_for_url(
            url, baudrate=baudrate, timeout=read_timeout, write_timeout=write_timeout,
            exclusive=True,
        )
    except (serial.SerialException, OSError, ValueError) as exc:
        if getattr(exc, "errno", None) in (errno.EAGAIN, errno.EWOULDBLOCK):
            raise LinkError(f"serial port {url!r} is in use by another process (is a "
                            f"flight already running on it?): {exc}") from exc
        raise LinkError(f"cannot open serial port {url!r}: {exc}") from exc


class PortLink:
    """What the links of both dialects share: the exclusively opened port, a reader thread
    that hands every chunk to :meth:`_on_bytes`, background failures stored and re-raised,
    the context manager. ``_cond`` guards the subclass's state and wakes its waiters.

    url : device path or pyserial URL; baudrate [baud]; write_timeout [s]; name : the
    threads' name prefix. Raises LinkError if the port cannot be opened. The subclass
    starts the reader (:meth:`_start_reader`) once its decoder is in place.
    """

    READ_TIMEOUT = 0.05
    """Longest a read blocks; bounds how long closing waits for the reader [s]."""

    _queue: deque[ReceivedData]
    """Received samples for :meth:`get` (the subclass creates it, bounded)."""

    def __init__(self, url: str, baudrate: int, write_timeout: float, name: str) -> None:
        self.url = url
        self._cond = threading.Condition()
        self._error: LinkError | None = None
        self._closed = False
        self._stop = threading.Event()
        self._port = _open_port(url, baudrate, self.READ_TIMEOUT, write_timeout)
        self._reader = threading.Thread(target=self._read_loop, name=f"{name}-reader {url}",
                                        daemon=True)

    @property
    def error(self) -> LinkError | None:
        """The failure of a background thread, if any (the link is then unusable)."""
        return self._error

    def get(self, timeout: float) -> ReceivedData | None:
        """The oldest queued IMU sample (X-3D DATA, or the LL dialect's IMU_RAWDATA as
        DATA), waiting up to ``timeout`` [s]; None on timeout.

        Raises LinkError if the link failed or is closed.
        """
        deadline = time.monotonic() + timeout
        with self._cond:
            while True:
                self._check_usable()
                if self._queue:
                    return self._queue.popleft()
                remaining = deadline - time.monotonic()
                if remaining <= 0.0:
                    return None
                self._cond.wait(remaining)

    def __enter__(self) -> Self:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()

    def close(self) -> None:
        """Close the link (the subclass hands back first); idempotent, never raises."""
        self._close_port()

    def _start_reader(self) -> None:
        self._reader.start()

    def _on_bytes(self, chunk: bytes, t: float) -> None:
        """Decode ``chunk`` received at monotonic ``t`` [s] (the subclass's job)."""
        raise NotImplementedError

    def _check_usable(self) -> None:
        """Raise the stored background failure, or LinkError if closed."""
        if self._error is not None:
            raise LinkError(f"serial link {self.url!r} failed: {self._error}") from self._error
        if self._closed:
            raise LinkError(f"serial link {self.url!r} is closed")

    def _fail(self, error: LinkError) -> None:
        """Store a background failure and wake every waiter."""
        with self._cond:
            if self._error is None:
                self._error = error
            self._cond.notify_all()
        _log.error("serial link failed", url=self.url, error=str(error))

    def _read_loop(self) -> None:
        """Reader thread: read whatever is waiting and hand it to :meth:`_on_bytes`."""
        port = self._port
        try:
            while not self._stop.is_set():
                chunk = port.read(port.in_waiting or 1)
                if chunk:
                    self._on_bytes(chunk, time.monotonic())
        except Exception as exc:  # any failure must surface to the user, never vanish
            if not self._stop.is_set():
                self._fail(_link_error(f"read from {self.url!r} failed", exc))

    def _close_port(self) -> None:
        """Stop the reader, close the port and wake every waiter (never raises)."""
        self._stop.set()
        cancel = getattr(self._port, "cancel_read", None)
        if cancel is not None:
            cancel()
        if self._reader.is_alive():
            self._reader.join()
        try:
            self._port.close()
        except (serial.SerialException, OSError) as exc:
            _log.warning("closing the serial port failed", url=self.url, error=str(exc))
        with self._cond:
            self._cond.notify_all()


class SerialLink(PortLink):
    """Serial link to the X-3D: DATA in (queued, timestamped), any message out.

    Parameters
    ----------
    url : device path or pyserial URL ("/dev/ttyUSB0", "/dev/pts/5", "loop://").
    baudrate : line rate [baud] (8N1, no flow control).
    profile : CRC profile ("asctec", "kermit", "mcrf4xx").
    command_rate : keep-alive COMMAND rate while armed [Hz] (> 10).
    keepalive_slack : the keep-alive writes only after ``1 / command_rate`` plus this
        without a COMMAND [s] (see :mod:`groundstation.asctec.keepalive`).
    stale_after : keep-alive re-sends the loop's command only this long [s].
    queue_size : DATA samples held for :meth:`get`; the oldest is dropped when full.
    rate_window : window of the DATA rate measurement [s].
    write_timeout : a write blocked this long fails with LinkError [s].
    stream : the CONFIG :meth:`start_stream` sends; DATA of another block mask is then
        dropped and counted (``unexpected_data``): an AscTec LL IMU_RAWDATA can pass for
        X-3D DATA of mask 0x1B or 0x1D.

    Raises LinkError if the port cannot be opened, ConfigError for bad parameters.
    """

    def __init__(
        self,
        url: str,
        *,
        baudrate: int = 57600,
        profile: str = DEFAULT_PROFILE,
        command_rate: float = 50.0,
        keepalive_slack: float = 0.0,
        stale_after: float = 0.25,
        queue_size: int = 256,
        rate_window: float = 1.0,
        write_timeout: float = 1.0,
        stream: ConfigMsg | None = None,
    ) -> None:
        if queue_size < 1:
            raise ConfigError(f"queue_size must be >= 1, got {queue_size}")
        profile_init(profile)  # validates the name before opening anything
        self._profile = profile
        self._decoder = StreamDecoder(profile)
        self._monitor = DataStreamMonitor(rate_window=rate_window)
        self._schedule = CommandSchedule(command_rate=command_rate, stale_after=stale_after,
                                         slack=keepalive_slack)
        self._queue: deque[ReceivedData] = deque(maxlen=queue_size)
        self._write_lock = threading.Lock()  # serialises writes and the schedule
        self._queue_dropped = 0
        self._unexpected = 0
        self._stream = stream
        self._bytes_out = 0
        self._flew = False
        self._close_lock = threading.Lock()
        self._keepalive_stop = threading.Event()
        self._keepalive: threading.Thread | None = None
        # the port opens here; the queue, decoder, monitor and counters are under _cond
        super().__init__(url, baudrate, write_timeout, "x3d")
        self._start_reader()

    @classmethod
    def from_params(cls, params: LinkParams) -> SerialLink:
        """A link to the X-3D as ``params`` describe it (the DATA stream it starts: its
        sensor mask at its period).

        The loop sends its COMMANDs on the DATA frames it receives, so they jitter with
        the DATA stream; the keep-alive fills in only when the loop has missed a whole
        DATA period (``data_period_ms`` of slack; less if the keep-alive period would
        then exceed half the watchdog). Without the slack it raced the loop and wrote a
        copy of the loop's command just before the loop's own: 60 of 820 COMMANDs in a
        `gs fly --demo` flight, each a late COMMAND as the vehicle sees it."""
        period = 1.0 / params.command_rate_hz
        slack = max(0.0, min(params.data_period_ms / 1000.0, GAP_WARNING_S - period))
        return cls(
            params.port,
            baudrate=params.baud,
            profile=params.crc_profile,
            command_rate=params.command_rate_hz,
            keepalive_slack=slack,
            stale_after=params.stale_command_s,
            stream=ConfigMsg(params.sensor_mask, params.data_period_ms),
        )

    # --- user API -----------------------------------------------------------------

    @property
    def flew(self) -> bool:
        """True once a COMMAND with a non-zero ctrl mask was written: only then does
        :meth:`close` send the final mask-0 COMMAND."""
        return self._flew

    @property
    def armed(self) -> bool:
        """True while the keep-alive guarantees the COMMAND rate."""
        return self._keepalive is not None

    def start_stream(self) -> None:
        """Send the CONFIG the link was built with (the vehicle then streams DATA); again
        whenever the stream stopped. ConfigError if the link has none."""
        if self._stream is None:
            raise ConfigError("this link was built without a CONFIG to start the stream with")
        self.send(self._stream)

    def send(self, msg: Message) -> None:
        """Encode and write ``msg`` now. A COMMAND also becomes the keep-alive's command.

        Raises LinkError if the write fails or the link has failed or is closed.
        """
        self._check_usable()
        frame = encode_frame(msg, self._profile)
        with self._write_lock:
            t = self._write(frame)
            if isinstance(msg, CommandMsg):
                self._flew = self._flew or msg.ctrl != 0
                self._schedule.loop_command(msg, t)
                self._schedule.record_write(t)

    def arm(self) -> None:
        """Start the keep-alive sender thread (no-op if already armed)."""
        self._check_usable()
        if self._keepalive is not None:
            return
        with self._write_lock:
            self._schedule.arm(time.monotonic())
        self._keepalive_stop.clear()
        self._keepalive = threading.Thread(
            target=self._keepalive_loop, name=f"x3d-keepalive {self.url}", daemon=True
        )
        self._keepalive.start()

    def disarm(self) -> None:
        """Stop the keep-alive thread and send COMMAND with ctrl mask 0."""
        self._stop_keepalive()
        self.send(CommandMsg.release())

    def command_write_times(self) -> tuple[float, ...]:
        """Monotonic times [s] of the most recent COMMAND writes, oldest first."""
        with self._write_lock:
            return self._schedule.write_times()

    def stats(self) -> LinkStats:
        """A consistent snapshot of the link's counters."""
        with self._cond:
            counts = self._decoder.counts()
            rate = self._monitor.rate(time.monotonic())
            monitor = self._monitor
            gaps, missed, repeats = (
                monitor.counter_gaps,
                monitor.samples_missed,
                monitor.counter_repeats,
            )
            dropped = self._queue_dropped
            unexpected = self._unexpected
        with self._write_lock:
            s = self._schedule
            return LinkStats(
                bytes_in=counts.bytes_in,
                bytes_out=self._bytes_out,
                frames=counts.frames,
                rejections=counts.rejections,
                bytes_skipped=counts.bytes_skipped,
                data_rate_hz=rate,
                counter_gaps=gaps,
                samples_missed=missed,
                counter_repeats=repeats,
                queue_dropped=dropped,
                commands_sent=s.commands_sent,
                keepalive_resends=s.resends,
                keepalive_releases=s.releases,
                max_command_gap=s.max_gap,
                command_gap_warnings=s.gap_warnings,
                unexpected_data=unexpected,
            )

    def close(self) -> None:
        """Stop the keep-alive, send a final mask-0 COMMAND if this link :attr:`flew` the
        vehicle, stop the reader, close the port.

        Idempotent. Never raises: a failed final write is logged (the vehicle's
        watchdog then returns control to the pilot within 100 ms).
        """
        with self._close_lock:
            if self._closed:
                return
            self._closed = True
        self._stop_keepalive()
        if self._flew:
            try:
                with self._write_lock:
                    self._schedule.record_write(
                        self._write(encode_frame(CommandMsg.release(), self._profile))
                    )
            except LinkError as exc:
                _log.warning("final mask-0 COMMAND not sent", url=self.url, error=str(exc))
        self._close_port()

    # --- internals ----------------------------------------------------------------

    def _write(self, frame: bytes) -> float:
        """Write ``frame`` (caller holds the write lock); returns the write time [s]."""
        try:
            self._port.write(frame)
        except (serial.SerialException, OSError) as exc:
            error = _link_error(f"write to {self.url!r} failed", exc)
            self._fail(error)
            raise error from exc
        self._bytes_out += len(frame)
        return time.monotonic()

    def _on_bytes(self, chunk: bytes, t: float) -> None:
        """Decode ``chunk`` received at ``t`` and queue its DATA messages."""
        with self._cond:
            queued = False
            expected = self._stream.sensor_mask if self._stream is not None else None
            for item in self._decoder.feed(chunk):
                if isinstance(item, DataMsg):
                    if expected is not None and item.mask != expected:
                        self._unexpected += 1  # not the stream we asked for: never fused
                        continue
                    self._monitor.update(item.counter, t)
                    if len(self._queue) == self._queue.maxlen:
                        self._queue_dropped += 1
                    self._queue.append(ReceivedData(t, item))
                    queued = True
            if queued:
                self._cond.notify_all()

    def _keepalive_loop(self) -> None:
        """Sender thread: write the due COMMAND at each deadline until stopped."""
        try:
            while not self._keepalive_stop.is_set():
                with self._write_lock:
                    msg = self._schedule.due(time.monotonic())
                    if msg is not None:
                        frame = encode_frame(msg, self._profile)
                        self._schedule.record_write(self._write(frame))
                    deadline = self._schedule.next_deadline()
                if deadline is None:
                    return
                self._keepalive_stop.wait(max(0.0, deadline - time.monotonic()))
        except Exception as exc:  # any failure must surface to the user, never vanish
            if self._error is None:
                self._fail(_link_error(f"keep-alive on {self.url!r} failed", exc))

    def _stop_keepalive(self) -> None:
        """Stop and join the keep-alive thread, if running, and disarm the schedule."""
        thread = self._keepalive
        if thread is None:
            return
        self._keepalive_stop.set()
        thread.join()
        self._keepalive = None
        with self._write_lock:
            self._schedule.disarm()
