"""Output that cannot stop a flight: a LineSink's writer thread takes a terminal that
hung up (EIO), a reader that went away (EPIPE), a full device (ENOSPC) and a write that
blocks, and the caller never sees any of it. Every stream here is a real one: a pty whose
master side was closed, a pipe, /dev/full."""

from __future__ import annotations

import contextlib
import errno
import os
import select
import sys
import threading
from collections.abc import Iterator
from pathlib import Path

import pytest
import structlog

from groundstation.logs import LineSink, configure_logging, fd_writer, log_through_sink


def hung_up_terminal() -> int:
    """The slave side of a pty whose master was closed: what a process's stdout is after
    its terminal window closed (the kernel hung the terminal up)."""
    master, slave = os.openpty()
    os.close(master)
    return slave


def test_a_hung_up_terminal_loses_the_stream_not_the_caller() -> None:
    slave = hung_up_terminal()
    try:
        with pytest.raises(OSError) as direct:  # what a plain write does there
            os.write(slave, b"x\n")
        assert direct.value.errno == errno.EIO
        sink = LineSink(fd_writer(slave), "stdout")
        for k in range(5):
            sink.put(f"line {k}")  # returns, raises nothing
        assert sink.close(10.0)
        assert sink.lost == os.strerror(errno.EIO) and sink.written == 0
        assert sink.dropped == 5
        sink.put("after close")
        assert sink.dropped == 6
    finally:
        os.close(slave)


def test_a_reader_that_went_away_and_a_full_device() -> None:
    read, write = os.pipe()
    os.close(read)  # `gs fly | head` after head exited; Python ignores SIGPIPE: EPIPE
    full = os.open("/dev/full", os.O_WRONLY)
    try:
        for fd, err in ((write, errno.EPIPE), (full, errno.ENOSPC)):
            sink = LineSink(fd_writer(fd))
            sink.put("a")
            sink.put("b")
            assert sink.close(10.0)
            assert sink.lost == os.strerror(err) and sink.dropped == 2
    finally:
        os.close(write)
        os.close(full)


def test_lines_arrive_in_order_and_whole() -> None:
    read, write = os.pipe()
    with os.fdopen(read, encoding="utf-8") as reader:
        sink = LineSink(fd_writer(write))
        lines = [f"{k:04d} " + "é" * (k % 7) for k in range(300)]
        for line in lines:
            sink.put(line)
        assert sink.close(10.0) and sink.written == 300 and not sink.lost
        os.close(write)
        assert reader.read().splitlines() == lines


def test_a_blocked_write_blocks_the_writer_thread_only() -> None:
    """A terminal paused with Ctrl-S, a stalled ssh session: the write blocks. Here a pipe
    nobody reads (64 kB of buffer): put() keeps returning, the lines beyond the capacity
    are dropped, close() gives up after its timeout, and the thread finishes once the
    stream drains."""
    read, write = os.pipe()
    sink = LineSink(fd_writer(write), capacity=50)
    line = "x" * 3999  # 4000 bytes with the newline: 16 fill a 64 kB pipe
    done = threading.Event()

    def producer() -> None:
        for _ in range(2000):
            sink.put(line)
        done.set()

    thread = threading.Thread(target=producer, daemon=True)
    thread.start()
    try:
        # generous: 2000 puts take milliseconds; a put that blocks never returns
        assert done.wait(60.0), "put() blocked behind a stalled write"
        assert not sink.close(0.2)  # still blocked: the caller is not kept
        assert sink.written <= 17 and sink.dropped >= 2000 - 50 - 17
    finally:
        while not sink.close(0.0):  # read until the writer is done
            if select.select([read], [], [], 0.05)[0]:
                os.read(read, 1 << 16)
        os.close(read)
        os.close(write)
    assert sink.written + sink.dropped == 2000 and not sink.lost


@pytest.fixture
def structlog_restored() -> Iterator[None]:
    saved = structlog.get_config()
    yield
    structlog.configure(**saved)


def test_log_lines_on_a_hung_up_stderr_do_not_raise(
        monkeypatch: pytest.MonkeyPatch, structlog_restored: None) -> None:
    """structlog as `gs` configures it writes to stderr; on a hung-up terminal a log call
    in the flight loop raised EIO (and a supervisor transition's log line would have
    aborted the flight). Through the sink it does not."""
    slave = hung_up_terminal()
    stderr = os.fdopen(slave, "w", encoding="utf-8")
    monkeypatch.setattr(sys, "stderr", stderr)
    try:
        configure_logging("info", "json")
        log = structlog.get_logger("test")
        with pytest.raises(OSError):  # without the sink
            log.warning("supervisor", new="LAND")
        with log_through_sink() as sink:
            log.warning("supervisor", new="LAND")
            with log_through_sink() as inner:  # nested: the same sink
                assert inner is sink
                log.info("still flying")
        assert sink.lost == os.strerror(errno.EIO) and sink.dropped == 2
        # retired: the line the first call left in its buffer now flushes to /dev/null
        # (the interpreter's final flush at exit would otherwise fail: exit status 120)
        stderr.close()
    finally:
        monkeypatch.undo()
        with contextlib.suppress(OSError):
            stderr.close()


def test_log_lines_through_the_sink_reach_stderr(
        monkeypatch: pytest.MonkeyPatch, structlog_restored: None, tmp_path: Path) -> None:
    out = tmp_path / "stderr.txt"
    with out.open("w", encoding="utf-8") as stderr:
        monkeypatch.setattr(sys, "stderr", stderr)
        configure_logging("info", "json")
        with log_through_sink() as sink:
            structlog.get_logger("test").warning("signal", signal="SIGHUP")
        monkeypatch.undo()
    assert sink.written == 1
    assert '"event": "signal"' in out.read_text() and '"signal": "SIGHUP"' in out.read_text()
