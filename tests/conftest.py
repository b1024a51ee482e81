"""Shared fixtures. The autouse ``no_leaks`` fixture fails any test that leaves
threads, sockets or pseudo-terminals open (STYLE.md item 14, python-can's conftest)."""

from __future__ import annotations

import os
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
DATA = Path(__file__).resolve().parent / "data"


def _io_fds() -> set[str]:
    """Open fds that are sockets or terminals, as 'fd -> target' strings."""
    out = set()
    for name in os.listdir("/proc/self/fd"):
        try:
            target = os.readlink(f"/proc/self/fd/{name}")
        except OSError:
            continue
        if target.startswith(("socket:", "/dev/pts/", "/dev/ptmx")):
            out.add(f"{name}->{target}")
    return out


@pytest.fixture(autouse=True)
def no_leaks() -> Iterator[None]:
    """Fail the test if it leaks threads, sockets or ptys (1 s grace to finish)."""
    threads_before = set(threading.enumerate())
    fds_before = _io_fds()
    yield
    deadline = time.monotonic() + 1.0
    while True:
        new_threads = [t for t in threading.enumerate()
                       if t not in threads_before and t.is_alive()]
        new_fds = _io_fds() - fds_before
        if not new_threads and not new_fds:
            return
        if time.monotonic() > deadline:
            break
        time.sleep(0.01)
    problems = []
    if new_threads:
        problems.append(f"threads still running: {[t.name for t in new_threads]}")
    if new_fds:
        problems.append(f"sockets/ptys still open: {sorted(new_fds)}")
    pytest.fail("resource leak: " + "; ".join(problems))


@pytest.fixture
def repo() -> Path:
    """The repository root."""
    return REPO
