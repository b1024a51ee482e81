"""Shared fixtures and the suite's rules.

* The autouse ``no_leaks`` fixture fails any test that leaves threads, sockets or
  pseudo-terminals open (STYLE.md item 14, python-can's conftest).
* A test that flies in real time (a virtual vehicle on a pty, the flight daemon, a
  ``gs fly`` or ``gs sim-device`` process) is marked ``realtime``: the mark puts it in one
  ``xdist_group``, so under ``pytest -n N --dist loadgroup`` (``make test``) the real-time
  flights run one after another on one worker, never beside each other, and
  ``make test-fast`` leaves them out (``-m "not realtime"``). A test that starts such a
  flight without the mark fails and says so, so the mark cannot go stale.
* Hypothesis runs derandomized and without its wall-clock deadline: a property test
  draws the same examples on every run (a pass cannot depend on the draw), and a loaded
  machine cannot fail it.
"""

from __future__ import annotations

import functools
import os
import subprocess
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any

import pytest
from hypothesis import settings

REPO = Path(__file__).resolve().parents[1]
DATA = Path(__file__).resolve().parent / "data"

settings.register_profile("groundstation", deadline=None, derandomize=True)
settings.load_profile("groundstation")

REALTIME_GROUP = "realtime"
"""The xdist group of every ``realtime`` test: one worker flies them one at a time."""

_flights_started: list[str] = []
"""What the current test started that flies in real time (see :func:`_watch`)."""


def _watch(owner: Any, name: str, what: str) -> None:
    """Record in :data:`_flights_started` each call of ``owner.name``."""
    original: Callable[..., Any] = getattr(owner, name)

    @functools.wraps(original)
    def watched(*args: Any, **kwargs: Any) -> Any:
        _flights_started.append(what)
        return original(*args, **kwargs)

    setattr(owner, name, watched)


def _starts_a_flight(args: object) -> bool:
    """``args`` of a process that runs a virtual vehicle in real time: ``gs sim-device`` or
    ``gs fly --demo`` (also as ``python -m groundstation ...``). A ``gs fly`` against a
    vehicle the test started is caught by the vehicle; one that cannot start is quick."""
    words = [os.fspath(a) if isinstance(a, str | os.PathLike) else str(a)
             for a in (args if isinstance(args, Sequence) and not isinstance(args, str)
                       else str(args).split())]
    return "sim-device" in words or ("fly" in words and "--demo" in words)


def pytest_configure(config: pytest.Config) -> None:
    from sim_device.realtime import SimDeviceProcess, SimDeviceThread

    _watch(SimDeviceThread, "__enter__", "SimDeviceThread")
    _watch(SimDeviceProcess, "__enter__", "SimDeviceProcess")
    popen_init = subprocess.Popen.__init__

    @functools.wraps(popen_init)
    def init(self: subprocess.Popen[Any], args: Any, *rest: Any, **kwargs: Any) -> None:
        if _starts_a_flight(args):
            _flights_started.append(f"a process: {' '.join(map(str, args))[:80]}")
        popen_init(self, args, *rest, **kwargs)

    subprocess.Popen.__init__ = init  # type: ignore[method-assign]


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    for item in items:
        if item.get_closest_marker("realtime") is not None:
            item.add_marker(pytest.mark.xdist_group(REALTIME_GROUP))


def pytest_runtest_logstart(nodeid: str, location: object) -> None:
    _flights_started.clear()


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item: pytest.Item, call: pytest.CallInfo[None]) -> Iterator[None]:
    outcome = yield
    report = outcome.get_result()  # type: ignore[attr-defined]
    if (call.when == "teardown" and _flights_started and report.passed
            and item.get_closest_marker("realtime") is None):
        report.outcome = "failed"
        report.longrepr = (f"{item.nodeid} flies in real time ({', '.join(_flights_started)}) "
                           "but is not marked realtime: add @pytest.mark.realtime so it runs "
                           "alone in the real-time group (tests/conftest.py)")


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
