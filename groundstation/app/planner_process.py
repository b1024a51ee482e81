"""The daemon's planner: a process of its own that plans run-time motions with a deadline.

A motion is planned where it cannot touch the flight loop (see
:mod:`groundstation.flight.planner` for why a thread is not enough): the request socket's
thread sends the planner a picklable job (:class:`~groundstation.flight.planner.PlanJob`:
the request's numbers, and for a motion the :class:`~groundstation.flight.commander.
PlanBase` the loop handed out) over a socket pair and waits for the pickled result, at
most until the request's deadline (``api.plan_timeout_s``). A job not done by then is
refused (``infeasible``, with the reason) and the process is killed and started again;
the next request waits for the new one to be ready. The loop never waits for any of it.

The process is started with ``os.posix_spawn`` rather than :mod:`multiprocessing`, for
three things the flight needs and ``multiprocessing`` does not give:

* it runs under the normal scheduling policy (``scheduler``) and ``nice``
  :data:`PLANNER_NICE`, whatever the thread that starts it runs under: the daemon's
  threads run ``SCHED_FIFO`` in the air, and a child that inherited that would compete
  with the loop for a core at real-time priority;
* it sits in a process group of its own (``setpgroup``), so a Ctrl-C at the terminal or
  GNU ``timeout`` signalling the daemon's group reaches the daemon, which lands, and never
  prints a planner's traceback;
* it starts a fresh interpreter that imports the planning modules only (``spawn`` would
  import the parent's ``__main__`` again, the CLI or the test runner).

Wire protocol (``multiprocessing.connection`` framing, pickles, parent to child): the
parent's ``sys.path`` (so jobs defined outside the package unpickle), the
:class:`~groundstation.flight.planner.PlannerSettings`, then ``(seq, job)`` per job; the
child answers ``("ready", pid)`` once it has imported, then ``(seq, "ok", result)``,
``(seq, "refused", kind, reason)`` or ``(seq, "error", text)`` per job. The child ends
when its end of the socket closes.
"""

from __future__ import annotations

import contextlib
import os
import pickle
import signal
import socket
import sys
import threading
import time
from multiprocessing.connection import Connection
from types import TracebackType
from typing import Any

import structlog

from groundstation.flight.commander import CommandRefusedError
from groundstation.flight.planner import PlanJob, PlannerSettings

log = structlog.get_logger(__name__)

PLANNER_NICE = 5
"""The planner's nice increment: on a loaded machine a plan waits for the daemon's threads,
never the other way round (the flight loop also runs ``SCHED_FIFO`` when it may). Five,
not more: at 10 a machine busy with other work (a CI runner) starved the planner's start
for longer than a take-off, and the first motion was refused as busy."""

START_WAIT_S = 10.0
"""How long a request waits for a planner that is still starting [s], beyond its own
planning budget (which starts once the planner is ready): an import under load."""

STOP_WAIT_S = 1.0
"""How long :meth:`PlannerProcess.close` lets the process end by itself before killing it
[s]; it ends at once when its socket closes unless it is planning."""

_BOOT = ("import os, sys; os.nice({nice}); "
         "from groundstation.app.planner_process import serve; serve(int(sys.argv[1]))")
"""The child's command line: lower its priority before any import, then serve."""


class PlannerProcess:
    """Runs planning jobs in a child process, each by a deadline. Use ``with`` (or
    :meth:`start` and :meth:`close`); :meth:`run` is called from one thread at a time
    (the request socket's), never from the flight loop.

    settings : what the jobs plan with; timeout_s : the configured planning budget of a
    request [s] (``api.plan_timeout_s``), named in refusals; nice : the child's nice
    increment.
    """

    def __init__(self, settings: PlannerSettings, *, timeout_s: float,
                 nice: int = PLANNER_NICE) -> None:
        self._settings = settings
        self._timeout_s = timeout_s
        self._nice = nice
        self._lock = threading.Lock()
        self._open = False
        self._conn: Connection | None = None
        self._pid: int | None = None
        self._ready = False
        self._seq = 0
        self.plans = 0
        """Jobs answered (refusals included)."""
        self.timeouts = 0
        """Jobs not done by their deadline (the process was restarted for each)."""
        self.restarts = 0
        """Times the process was started again (a deadline missed, the process died)."""

    @property
    def pid(self) -> int | None:
        """The planner process's id (None when none runs)."""
        return self._pid

    def __enter__(self) -> PlannerProcess:
        self.start()
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()

    def start(self) -> None:
        """Start the process (it imports for about a second; :meth:`run` waits for it). A
        process that cannot be started is logged; :meth:`run` tries again."""
        with self._lock:
            self._open = True
            self._spawn()

    def close(self) -> None:
        """Stop the process: its socket is closed (it ends at once unless it is planning,
        in which case it is killed after :data:`STOP_WAIT_S`)."""
        self._open = False
        pid = self._pid
        if pid is not None and self._lock.locked():  # a job under way: end it now
            _kill(pid)
        with self._lock:
            self._stop(STOP_WAIT_S)

    # ------------------------------------------------------------------ jobs
    def run(self, job: PlanJob, deadline: float) -> Any:
        """``job``'s result, computed in the planner process. Raises CommandRefusedError:
        the job's own refusal; ``infeasible`` if it is not done by ``deadline``
        (``time.monotonic()`` [s]; the process is then restarted; a start the request had
        to wait for does not count against it); ``busy`` if the process is still starting
        :data:`START_WAIT_S` after the request; ``internal`` if it failed or died."""
        with self._lock:
            if not self._open:
                raise CommandRefusedError("internal", "the planner process is not running")
            if self._conn is None:
                self._spawn()
                if self._conn is None:
                    raise CommandRefusedError("internal", "the planner process cannot be "
                                              "started (see the daemon's log)")
            if not self._ready:  # the start does not count against the plan's budget
                self._await_ready(max(deadline, time.monotonic() + START_WAIT_S))
                deadline = max(deadline, time.monotonic() + self._timeout_s)
            self._seq += 1
            try:
                self._conn.send((self._seq, job))
            except (OSError, ValueError) as exc:  # a job that does not pickle is ours
                if isinstance(exc, OSError):
                    self._died("while receiving a job")
                raise CommandRefusedError("internal", f"the job could not be sent to the "
                                          f"planner: {exc}") from None
            return self._result(self._seq, deadline)

    def _await_ready(self, deadline: float) -> None:
        assert self._conn is not None
        if not self._conn.poll(max(0.0, deadline - time.monotonic())):
            raise CommandRefusedError("busy", "the planner process is starting (it takes "
                                      "about a second): try again")
        try:
            message = self._conn.recv()
        except (EOFError, OSError):
            why = self._died("while starting")
            raise CommandRefusedError("internal", f"the planner process ended {why}; it "
                                      "is being started again") from None
        self._ready = message[0] == "ready"

    def _result(self, seq: int, deadline: float) -> Any:
        assert self._conn is not None
        while True:
            if not self._conn.poll(max(0.0, deadline - time.monotonic())):
                self.timeouts += 1
                log.warning("plan not made in time: planner restarted",
                            timeout_s=self._timeout_s, pid=self._pid)
                self._restart()
                raise CommandRefusedError(
                    "infeasible", f"not planned within api.plan_timeout_s "
                    f"({self._timeout_s:g} s): a shorter motion or a simpler path plans "
                    "faster")
            try:
                reply = self._conn.recv()
            except (EOFError, OSError):
                why = self._died("while planning")
                raise CommandRefusedError("internal", f"the planner process ended {why}; "
                                          "it is being started again") from None
            if reply[0] not in (seq, None):
                continue  # a reply to a job given up on cannot come (the process was killed)
            self.plans += 1
            if reply[1] == "ok":
                return reply[2]
            if reply[1] == "refused":
                raise CommandRefusedError(reply[2], reply[3])
            raise CommandRefusedError("internal", f"the planner failed: {reply[2]}")

    # ------------------------------------------------------------------ the process
    def _spawn(self) -> None:
        """Start a child and hand it the settings (never blocks on the child's imports)."""
        parent, child = socket.socketpair()
        try:
            child.set_inheritable(True)
            extra: dict[str, Any] = {}
            if sys.platform == "linux":  # the normal policy, whatever the caller's
                extra["scheduler"] = (os.SCHED_OTHER, os.sched_param(0))
            pid = os.posix_spawn(
                sys.executable,
                [sys.executable, "-c", _BOOT.format(nice=self._nice), str(child.fileno())],
                os.environ, setpgroup=0, **extra)
        except OSError as exc:
            parent.close()
            log.error("planner process not started: motions will be refused",
                      error=str(exc))
            return
        finally:
            child.close()
        conn = Connection(parent.detach())
        try:
            conn.send(list(sys.path))
            conn.send(self._settings)
        except OSError as exc:  # it died at once
            conn.close()
            _reap(pid, STOP_WAIT_S)
            log.error("planner process ended at its start", error=str(exc))
            return
        self._conn, self._pid, self._ready = conn, pid, False
        log.info("planner process started", pid=pid)

    def _stop(self, wait_s: float) -> str:
        """Close the socket and reap the child (killed after ``wait_s`` [s]); how it ended."""
        conn, pid = self._conn, self._pid
        self._conn, self._pid, self._ready = None, None, False
        if conn is not None:
            conn.close()
        return _reap(pid, wait_s) if pid is not None else ""

    def _restart(self) -> None:
        if self._pid is not None:
            _kill(self._pid)
        self._stop(STOP_WAIT_S)
        if self._open:
            self.restarts += 1
            self._spawn()

    def _died(self, when: str) -> str:
        """The child went away ``when``: reap it, start another; how it ended."""
        why = self._stop(STOP_WAIT_S)
        log.error("planner process ended", when=when, how=why)
        if self._open:
            self.restarts += 1
            self._spawn()
        return f"{when} ({why})"


def _kill(pid: int) -> None:
    with contextlib.suppress(ProcessLookupError):  # it has ended by itself
        os.kill(pid, signal.SIGKILL)


def _reap(pid: int, wait_s: float) -> str:
    """Wait up to ``wait_s`` [s] for child ``pid`` to end, then kill it; how it ended."""
    deadline = time.monotonic() + wait_s
    killed = False
    while True:
        try:
            done, status = os.waitpid(pid, os.WNOHANG)
        except ChildProcessError:
            return "already reaped"
        if done:
            code = os.waitstatus_to_exitcode(status)
            return f"exit status {code}" if code >= 0 else \
                f"killed by {signal.Signals(-code).name}"
        if time.monotonic() >= deadline and not killed:
            _kill(pid)
            killed = True
        time.sleep(0.005)


# --------------------------------------------------------------------------- the child
def serve(fd: int) -> None:
    """The planner process's main loop on socket ``fd``: run each job it receives and send
    its result back, until the socket closes. Never raises for a job's failure."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the daemon decides when this ends
    conn = Connection(fd)
    try:
        sys.path[:] = conn.recv()
        settings: PlannerSettings = conn.recv()
        conn.send(("ready", os.getpid()))
        while True:
            conn.send_bytes(_answer(conn.recv_bytes(), settings))
    except (EOFError, OSError):  # the daemon closed its end (or went away): done, quietly
        return


def _answer(message: bytes, settings: PlannerSettings) -> bytes:
    """The pickled reply to one pickled ``(seq, job)``."""
    seq = None
    try:
        seq, job = pickle.loads(message)
        return pickle.dumps((seq, "ok", job.run(settings)))  # one that does not pickle fails
    except CommandRefusedError as exc:
        return pickle.dumps((seq, "refused", exc.kind, exc.reason))
    except Exception as exc:  # any failure of a job is its reply, never this process's end
        return pickle.dumps((seq, "error", f"{type(exc).__name__}: {exc}"[:400]))
