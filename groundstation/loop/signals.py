"""SIGINT/SIGTERM handling shared by the flight daemon and the virtual lab's runner."""

from __future__ import annotations

import contextlib
import signal
import threading
import time
from collections.abc import Callable, Iterator
from types import FrameType

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)


@contextlib.contextmanager
def on_stop_signals(callback: Callable[[signal.Signals], None]) -> Iterator[None]:
    """Call ``callback(signal)`` on SIGINT/SIGTERM while inside; restore the previous
    handlers on exit. Python delivers signals to the main thread only, so elsewhere
    this is a no-op (the caller must offer another way to stop, e.g. an Event)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def handler(signum: int, frame: FrameType | None) -> None:
        callback(signal.Signals(signum))

    previous = {s: signal.signal(s, handler) for s in STOP_SIGNALS}
    try:
        yield
    finally:
        for s, h in previous.items():
            signal.signal(s, h)


class StopRequests:
    """Counts stop requests (SIGINT, SIGTERM), taking a repeat within ``repeat_after_s`` of
    the first as the same request.

    GNU ``timeout`` delivers SIGTERM to the process and then to its process group within
    a millisecond, and systemd and shells may do the same: two signals that close are
    one request to stop (land), not an operator asking twice (hand back at once). A
    request at least ``repeat_after_s`` after the first counts again.

    repeat_after_s : [s], >= 0 (0 counts every signal)
    clock : monotonic clock [s] (injectable for tests)
    """

    def __init__(self, repeat_after_s: float,
                 clock: Callable[[], float] = time.monotonic) -> None:
        if not repeat_after_s >= 0.0:
            raise ValueError(f"repeat_after_s must be >= 0, got {repeat_after_s!r}")
        self.repeat_after_s = repeat_after_s
        self._clock = clock
        self._first: float | None = None
        self.count = 0
        """Requests that counted."""
        self.ignored = 0
        """Signals taken as a repeat of the first."""

    def request(self) -> bool:
        """Record one signal now; True if it counted as a new request."""
        now = self._clock()
        if self._first is not None and now - self._first < self.repeat_after_s:
            self.ignored += 1
            return False
        if self._first is None:
            self._first = now
        self.count += 1
        return True
