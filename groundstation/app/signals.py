"""Stop signals shared by the flight daemon and the virtual lab's runner.

A stop request is any of :data:`STOP_SIGNALS`: SIGINT (Ctrl-C), SIGTERM (``kill``,
``timeout``, ``systemctl stop``), SIGHUP (the controlling terminal went away: a closed
window, a dropped ssh session) and SIGQUIT (Ctrl-\\). Python's default for SIGHUP and
SIGQUIT ends the process at once, which in the air means no landing, no summary and
no final COMMAND: the vehicle's watchdog hands it to the pilot 100 ms later.

SIGPIPE is deliberately not one of them. Python ignores it, so a reader of our output
that went away (``gs fly | tee`` ended, journald restarted under systemd) shows up as
EPIPE on the write that hit it: that output is lost, the flight goes on. Handling it
would let whoever reads the output land the vehicle, and would turn every later write
to that pipe into another signal.
"""

from __future__ import annotations

import contextlib
import signal
import threading
import time
from collections.abc import Callable, Iterator
from types import FrameType

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP, signal.SIGQUIT)
"""Signals that ask a flight to stop (see the module docstring)."""

HANGUP_SIGNALS = frozenset({signal.SIGHUP})
"""Stop signals that ask for a stop and never for more (:meth:`StopRequests.request`
with ``escalates=False``). One hangup reaches a process more than once (a shell forwards
it to its jobs, then the kernel sends it to the terminal's foreground group as the shell
exits), and a lost terminal is nobody asking to hand the vehicle back in the air."""


@contextlib.contextmanager
def on_stop_signals(callback: Callable[[signal.Signals], None]) -> Iterator[None]:
    """Call ``callback(signal)`` on each of :data:`STOP_SIGNALS` while inside; restore the
    previous handlers on exit. Python delivers signals to the main thread only, so
    elsewhere this is a no-op (the caller must offer another way to stop, e.g. an Event).
    The callback runs in the main thread between two bytecodes of whatever it was doing:
    it must not take a lock that code may hold."""
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
    """Counts stop requests, taking a repeat within ``repeat_after_s`` of the first as the
    same request.

    GNU ``timeout`` delivers SIGTERM to the process and then to its process group within
    a millisecond, and systemd and shells may do the same: two signals that close are
    one request to stop (land), not an operator asking twice (hand back at once). A
    request at least ``repeat_after_s`` after the first counts again, unless it is one
    that never escalates (a hangup, see :data:`HANGUP_SIGNALS`).

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
        """Signals taken as a repeat of the first, or as nothing more than a stop
        already requested."""

    def request(self, *, escalates: bool = True) -> bool:
        """Record one signal now; True if it counted as a new request.

        escalates : False for a request that asks for a stop and never for more (a
            hangup): it counts only if no request has counted yet."""
        now = self._clock()
        if self._first is not None and (
                not escalates or now - self._first < self.repeat_after_s):
            self.ignored += 1
            return False
        if self._first is None:
            self._first = now
        self.count += 1
        return True
