"""What the daemon asks of the OS while it flies: CPU wake-up latency and GIL switching.

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
"""

from __future__ import annotations

import os
import struct
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

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
