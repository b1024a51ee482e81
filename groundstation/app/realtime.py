"""What the daemon asks of the OS and the interpreter while it flies: CPU wake-up latency,
a real-time scheduling policy, GIL switching, and a garbage collector that stays off the
COMMAND path.

The loop sleeps about 8 ms of every 10 ms waiting for the next DATA sample. A CPU
that spends those 8 ms in a deep idle state (or, on a virtual machine, a vCPU
the hypervisor parks on ``HLT``) wakes slowly and runs the tick on cold caches:
on this project's VM the same estimator step cost 6x more after 8 ms of sleep
than back to back (``benchmarks/bench_flight.py``, README "Real-time tuning").

Linux's PM QoS interface fixes this from user space without rebooting the lab
PC: while a process holds ``/dev/cpu_dma_latency`` open with a latency bound
written to it, no CPU enters an idle state whose exit latency exceeds the bound
(0 us: the CPUs poll instead of halting). The kernel drops the request when the
file is closed, also when the process dies, so a crashed daemon cannot leave
the machine burning power. The device is root-only by default;
``config/99-groundstation.rules`` gives the ``groundstation`` group access.

Under the normal scheduling policy the loop shares the cores with every busy process
on the machine; :func:`fifo_priority` runs it (and the threads it starts: the serial
reader, the keep-alive, the Vicon reader) under the real-time FIFO policy instead.

CPython's cyclic garbage collector stops every thread of the process while it runs
(it holds the interpreter lock), the keep-alive thread included. See
:class:`CollectorPacer` for how the daemon keeps those pauses short and away from the
COMMANDs.
"""

from __future__ import annotations

import gc
import os
import struct
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType

import structlog

log = structlog.get_logger("groundstation.realtime")

CPU_DMA_LATENCY = Path("/dev/cpu_dma_latency")
"""The PM QoS device: write a native 32-bit integer bound [us], hold the file open."""


@contextmanager
def cpu_latency_request(max_us: int | None, device: Path = CPU_DMA_LATENCY) -> Iterator[bool]:
    """Hold a PM QoS request for a CPU wake-up latency of at most ``max_us`` [us].

    Yields True while the request is held. ``max_us=None`` makes no request. If
    the device cannot be opened or written (no permission, no such kernel
    interface) a warning names the reason and the block runs without the request
    (yields False): the flight is still safe, only each tick costs more.
    """
    if max_us is None:
        yield False
        return
    try:
        fd = os.open(device, os.O_WRONLY)
    except OSError as exc:
        log.warning("cpu latency request not held: ticks will pay for deep idle states",
                    device=str(device), reason=exc.strerror or str(exc),
                    hint="see config/99-groundstation.rules")
        yield False
        return
    try:
        try:
            os.write(fd, struct.pack("=i", max_us))  # the kernel reads an s32 in host order
        except OSError as exc:
            log.warning("cpu latency request refused", device=str(device),
                        reason=exc.strerror or str(exc), max_us=max_us)
            yield False
            return
        log.info("cpu latency request held", device=str(device), max_us=max_us)
        yield True
    finally:
        os.close(fd)


@contextmanager
def fifo_priority(priority: int | None, *, who: str = "flight loop") -> Iterator[bool]:
    """Run the calling thread, and every thread it starts inside the block, under the
    ``SCHED_FIFO`` real-time policy at ``priority`` (1-99; restored afterwards).

    Yields True while the policy is held. A thread under the normal policy shares the
    cores with every busy process: with two pure-Python spinners on the 2-core VM the
    vehicle saw COMMAND gaps of 55-114 ms, three times past its 100 ms watchdog, in 30
    flights, and a plain process sleeping 1 ms at a time woke up 100 ms late.
    A real-time thread preempts them as soon as it wakes. It needs ``CAP_SYS_NICE`` or
    an ``RLIMIT_RTPRIO`` of at least ``priority`` (systemd ``LimitRTPRIO=``, or
    ``@groundstation - rtprio 20`` in /etc/security/limits.d); without either a warning
    names the reason and the block runs under the normal policy (yields False). The
    kernel's real-time throttling (``sched_rt_runtime_us``, 95 % by default) keeps a
    runaway real-time thread from locking a core. ``priority=None`` asks nothing.
    Threads started in the block inherit the policy (Linux, ``PTHREAD_INHERIT_SCHED``).
    """
    if priority is None or not hasattr(os, "sched_setscheduler"):
        yield False
        return
    policy, param = os.sched_getscheduler(0), os.sched_getparam(0)
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except OSError as exc:
        log.warning(f"real-time priority not held: the {who} shares the cores with every "
                    "busy process", priority=priority, reason=exc.strerror or str(exc),
                    hint="needs CAP_SYS_NICE or LimitRTPRIO (see config/groundstation.service)")
        yield False
        return
    log.info("real-time priority held", policy="SCHED_FIFO", priority=priority, who=who)
    try:
        yield True
    finally:
        try:
            os.sched_setscheduler(0, policy, param)
        except OSError as exc:  # cannot happen for a lower priority; never raise on the way out
            log.warning("scheduling policy not restored", reason=str(exc))


@contextmanager
def switch_interval(seconds: float) -> Iterator[None]:
    """Set the interpreter's thread switch interval [s] for the block (restored afterwards).

    A reader thread that holds the GIL delays a tick by up to this long; the
    default 5 ms is half the 100 Hz budget.
    """
    previous = sys.getswitchinterval()
    sys.setswitchinterval(seconds)
    try:
        yield
    finally:
        sys.setswitchinterval(previous)


_OUT_OF_REACH = 2**31 - 1
"""A generation-2 threshold the interpreter never reaches (a C int)."""


@dataclass
class CollectorStats:
    """Garbage collections while a :class:`CollectorPacer` was active.

    young, full : collections of generations 0-1 / of generation 2
    longest_young_s, longest_full_s : their longest wall-clock pause [s]
    """

    young: int = 0
    full: int = 0
    longest_young_s: float = 0.0
    longest_full_s: float = 0.0


class CollectorPacer:
    """Keeps the garbage collector's full collections short and off the COMMAND path.

    A full collection walks every tracked object of the process: after start-up about
    93,000 (modules, numpy, scipy, pydantic), 50-64 ms on the project's VM. The
    interpreter starts one at whatever allocation, in whatever thread, finds enough
    objects promoted to the oldest generation, and while it runs no thread runs: in
    the hostile tester's flights the COMMAND gap reached 122 ms and the vehicle's
    100 ms watchdog expired in the air. While active (``with``):

    * entering: one full collection (on the ground, before the loop), then
      ``gc.freeze()``: every object alive now moves to the permanent generation, which
      no collection walks again;
    * the interpreter still collects the young generations whenever they fill (objects
      allocated since; tens of microseconds), but never starts a full collection: the
      oldest generation's threshold is out of reach;
    * the loop calls :meth:`after_command` right after each COMMAND it writes; if
      generation 1 was collected since the last full collection (objects may have been
      promoted to the oldest generation), a full collection runs there. It walks only
      the objects created since the freeze that are still tracked (at most one young
      generation's worth of promotions since the last one), and the next COMMAND is a
      command period away (20 ms at 50 Hz). The daemon alone allocates so little that
      a whole flight may see a single young collection and no full one;
    * leaving: the thresholds are restored and the frozen objects unfrozen.

    With ``enabled=False`` the interpreter's own collector runs unchanged; either way
    :attr:`stats` counts the collections and their longest pauses.
    """

    def __init__(self, enabled: bool = True) -> None:
        self.enabled = enabled
        self.stats = CollectorStats()
        self._thresholds = gc.get_threshold()
        self._started = 0.0
        self._active = False

    def __enter__(self) -> CollectorPacer:
        self._active = self.enabled and gc.isenabled()
        if self._active:
            self._thresholds = gc.get_threshold()
            gc.collect()
            gc.freeze()
            gc.set_threshold(self._thresholds[0], self._thresholds[1], _OUT_OF_REACH)
        gc.callbacks.append(self._on_collection)
        return self

    def after_command(self) -> None:
        """Run a full collection now if one is due (call right after a COMMAND went out)."""
        if self._active and gc.get_count()[2] > 0:
            gc.collect()

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        if self._active:
            gc.set_threshold(*self._thresholds)
            gc.unfreeze()
            self._active = False
        gc.callbacks.remove(self._on_collection)

    def _on_collection(self, phase: str, info: dict[str, int]) -> None:
        if phase == "start":
            self._started = time.perf_counter()
            return
        pause = time.perf_counter() - self._started
        s = self.stats
        if info["generation"] == 2:
            s.full += 1
            s.longest_full_s = max(s.longest_full_s, pause)
        else:
            s.young += 1
            s.longest_young_s = max(s.longest_young_s, pause)
