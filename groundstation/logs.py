"""structlog configured once for the whole process, and output that cannot stop a flight.

Console renderer when stderr is a terminal, JSON lines otherwise (systemd,
Docker, CI) or when the configuration asks for it. Library modules only call
``structlog.get_logger(__name__)``; only the CLI calls :func:`configure_logging`.

A flight must not stop for its output. A terminal paused with Ctrl-S or a stalled ssh
session blocks a write; a closed terminal fails it with EIO (after a SIGHUP), a reader
that went away with EPIPE (Python ignores SIGPIPE), a full disk with ENOSPC. So while a
flight runs its lines go through a :class:`LineSink`: a thread of its own does the
writing, takes the blocking and the errors, and the flight's threads only queue.
:func:`log_through_sink` does this for the log lines :func:`configure_logging` sends to
stderr.
"""

from __future__ import annotations

import contextlib
import errno
import io
import logging
import os
import queue
import select
import sys
import threading
from collections.abc import Callable, Iterator
from typing import Literal, TextIO

import structlog

LogFormat = Literal["auto", "console", "json"]
_LEVELS = {"debug": logging.DEBUG, "info": logging.INFO, "warning": logging.WARNING,
           "error": logging.ERROR}

SINK_CAPACITY = 2000
"""Lines a :class:`LineSink` holds behind a blocked write before it drops new ones (a
flight's progress and log lines are a few per second: minutes of them)."""

OUTPUT_DRAIN_S = 2.0
"""How long the end of a flight waits for its last lines to be written [s]: long enough
for any terminal that reads, short enough that a paused one does not keep the process."""

_STOP = object()

_DEAD = frozenset({errno.EIO, errno.EPIPE, errno.EBADF})
"""Write errors after which a descriptor never takes output again: a hung-up terminal,
a reader that went away, a closed descriptor."""


class LineSink:
    """Writes lines from a thread of its own: :meth:`put` never blocks and never raises.

    After the first failed write the stream is lost (:attr:`lost` says why) and later
    lines are only counted in :attr:`dropped`, as are lines beyond ``capacity`` waiting
    behind a blocked write. :meth:`put` is safe in a signal handler and in any thread:
    it takes no lock (``queue.SimpleQueue.put`` is reentrant), so a handler that
    interrupts a ``put`` of the same thread cannot deadlock.

    write : writes one line (without its newline; e.g. :func:`stream_writer`)
    name : the stream's name (the thread's name, messages)
    capacity : lines waiting at most, >= 1
    """

    def __init__(self, write: Callable[[str], None], name: str = "output",
                 capacity: int = SINK_CAPACITY) -> None:
        if capacity < 1:
            raise ValueError(f"capacity must be >= 1, got {capacity!r}")
        self.name = name
        self._write = write
        self._capacity = capacity
        self._queue: queue.SimpleQueue[object] = queue.SimpleQueue()
        self._closed = False
        self.lost = ""
        """Why the stream is lost (the first write error), empty while it is not."""
        self.lost_errno: int | None = None
        """The errno of that error, if it was an OSError."""
        self.dropped = 0
        """Lines not written: the stream lost, the queue full, or put after close."""
        self.written = 0
        """Lines written."""
        self._thread = threading.Thread(target=self._run, name=f"gs-{name}", daemon=True)
        self._thread.start()

    def put(self, line: str) -> None:
        """Queue ``line`` (no newline) for writing; return at once."""
        if self._closed or self.lost or self._queue.qsize() >= self._capacity:
            self.dropped += 1  # a counter raced by two threads may miss one: it is a count
            return
        self._queue.put(line)

    def _run(self) -> None:
        while (line := self._queue.get()) is not _STOP:
            if self.lost:
                self.dropped += 1
                continue
            try:
                self._write(str(line))
            except Exception as exc:  # whatever the stream raises, it is lost
                self.lost = _why(exc)
                self.lost_errno = exc.errno if isinstance(exc, OSError) else None
                self.dropped += 1
            else:
                self.written += 1

    def close(self, timeout_s: float = OUTPUT_DRAIN_S) -> bool:
        """Stop taking lines and wait up to ``timeout_s`` [s] for the queued ones to be
        written; True if they were (False: the stream blocks, the thread is left to it).
        Idempotent."""
        if not self._closed:
            self._closed = True
            self._queue.put(_STOP)
        self._thread.join(timeout_s)
        return not self._thread.is_alive()


def _why(exc: BaseException) -> str:
    """A short reason for a failed write: the OS's words (``Input/output error``)."""
    if isinstance(exc, OSError) and exc.strerror:
        return exc.strerror
    return str(exc) or type(exc).__name__


def fd_writer(fd: int) -> Callable[[str], None]:
    """Writes a line and its newline to the file descriptor ``fd`` with ``os.write``.

    Below Python's buffered streams on purpose: a write blocked on a paused terminal then
    holds no lock of ``sys.stdout``, so the interpreter's final flush at exit cannot wait
    for it. A descriptor someone made non-blocking is waited for, not lost."""

    def write(line: str) -> None:
        data = memoryview((line + "\n").encode("utf-8", "backslashreplace"))
        while data:
            try:
                n = os.write(fd, data)
            except BlockingIOError:
                select.select([], [fd], [])
                continue
            data = data[n:]

    return write


def stream_writer(stream: TextIO) -> Callable[[str], None]:
    """A line writer for ``stream``: its file descriptor (:func:`fd_writer`, after
    flushing what the stream holds) when it has a real one, else the stream's own
    ``write`` and ``flush`` (a test runner's capture, a ``StringIO``)."""
    try:
        fd = stream.fileno()
        stream.flush()
    except (OSError, ValueError, io.UnsupportedOperation):
        def write(line: str) -> None:
            stream.write(line + "\n")
            stream.flush()

        return write
    return fd_writer(fd)


def retire_lost_stream(stream: TextIO, sink: LineSink) -> None:
    """If ``sink`` lost ``stream`` for good (EIO: a hung-up terminal; EPIPE: its reader
    went away), point the stream's descriptor at /dev/null: whatever Python still
    buffers for it, or writes to it later, then goes nowhere instead of failing again at
    exit, where a failed final flush makes the interpreter exit 120 instead of the
    flight's code (Python docs, "Note on SIGPIPE")."""
    if sink.lost_errno not in _DEAD:
        return
    try:
        fd = stream.fileno()
    except (OSError, ValueError, io.UnsupportedOperation):
        return
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, fd)
    finally:
        os.close(devnull)


class _SinkLogger:
    """structlog's logger interface (every level is ``msg``) putting lines into a sink."""

    def __init__(self, sink: LineSink) -> None:
        self._sink = sink

    def msg(self, message: str) -> None:
        self._sink.put(message)

    log = debug = info = warn = warning = err = error = critical = fatal = exception = msg
    failure = msg


_sink: LineSink | None = None


def _stderr_logger(*_args: object) -> structlog.PrintLogger | _SinkLogger:
    """A logger on whatever ``sys.stderr`` is now (it may be replaced after configuration,
    e.g. by a test runner or a daemoniser; binding the object at configuration time would
    then write to a closed file), or on the sink of :func:`log_through_sink`."""
    sink = _sink
    if sink is not None:
        return _SinkLogger(sink)
    return structlog.PrintLogger(file=sys.stderr)


@contextlib.contextmanager
def log_through_sink(timeout_s: float = OUTPUT_DRAIN_S) -> Iterator[LineSink]:
    """While inside, the log lines :func:`configure_logging` sends to stderr go through a
    :class:`LineSink` on stderr (yielded), so no log call blocks or raises for its
    output; on leaving, up to ``timeout_s`` [s] for them to be written, and a stderr lost
    for good is retired (:func:`retire_lost_stream`). Nested uses share the outermost
    sink."""
    global _sink
    if _sink is not None:
        yield _sink
        return
    stream = sys.stderr
    sink = LineSink(stream_writer(stream), "stderr")
    _sink = sink
    try:
        yield sink
    finally:
        _sink = None
        sink.close(timeout_s)
        retire_lost_stream(stream, sink)


def configure_logging(level: str = "info", fmt: LogFormat = "auto") -> None:
    """Configure structlog: ``level`` is debug/info/warning/error, ``fmt`` auto/console/json.

    Output goes to stderr so stdout stays free for command results.
    """
    use_console = fmt == "console" or (fmt == "auto" and sys.stderr.isatty())
    renderer: structlog.typing.Processor = (
        structlog.dev.ConsoleRenderer() if use_console else structlog.processors.JSONRenderer()
    )
    structlog.configure(
        processors=[
            structlog.contextvars.merge_contextvars,
            structlog.processors.add_log_level,
            structlog.processors.TimeStamper(fmt="iso", utc=True),
            structlog.processors.StackInfoRenderer(),
            structlog.processors.format_exc_info,
            renderer,
        ],
        wrapper_class=structlog.make_filtering_bound_logger(_LEVELS[level]),
        logger_factory=_stderr_logger,
        cache_logger_on_first_use=False,
    )
