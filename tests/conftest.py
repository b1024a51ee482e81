"""Shared fixtures and the suite's rules.

* The autouse ``no_leaks`` fixture fails any test that leaves threads, sockets or
  pseudo-terminals open (STYLE.md item 14, python-can's conftest).
* A test that flies in real time (the flight daemon, in this process or as ``gs fly``,
  against a virtual vehicle on a pty) is marked ``realtime``; a test that runs a virtual
  vehicle in real time that nobody flies (``gs calibrate``, ``gs link-check``,
  ``gs motors``, the pty itself) is marked ``virtual_vehicle``. Each mark puts its tests
  in one ``xdist_group``, so under ``pytest -n N --dist loadgroup`` (``make test``) one
  worker flies the real-time flights one after another (never two at once), another
  runs the grounded vehicles one after another, and ``make test-fast`` leaves both out.
  A test that starts either without its mark fails and says which mark it needs, so the
  marks cannot go stale. The tests of a module that share a module-scoped fixture (a
  recorded flight) are a group too, so the fixture is made once, not once per worker.
* Hypothesis runs derandomized and without its wall-clock deadline: a property test
  draws the same examples on every run (a pass cannot depend on the draw), and a loaded
  machine cannot fail it.
* A fleet's flight (several daemons, the virtual lab's vehicles and the relay: about a
  core and a half, the daemons under the FIFO policy) never runs beside a grounded
  virtual vehicle, whose tests time the link to the millisecond: both take one lock
  shared by the session's workers (``fleet_alone``, module-scoped, for a module's fleet
  flights; every ``virtual_vehicle`` test, autouse). The fleet's flights are collected
  last, so they end the real-time lane after the grounded vehicles' lane is done: the
  lock then keeps them apart without either waiting for the other.
* structlog's configuration is put back after every test (``fresh_logging``): a command
  run in-process configures it (level, output), and a later test on the same worker that
  captures log events would otherwise see only those at the level that command set.
* The in-process evaluation flights are flown once per session, whichever worker asks
  first, and read by the others from a directory the controller names and removes
  (``eval_flights``).
"""

from __future__ import annotations

import contextlib
import fcntl
import functools
import os
import shutil
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

GROUPS = {"realtime": "realtime-flights", "virtual_vehicle": "virtual-vehicles"}
"""Mark -> the xdist group whose tests one worker runs one at a time."""

_started: dict[str, list[str]] = {"vehicle": [], "flight": []}
"""What the current test started in real time: virtual vehicles and flights."""


def _watch(owner: Any, name: str, kind: str, what: str) -> None:
    """Record ``what`` under ``kind`` in :data:`_started` at each call of ``owner.name``."""
    original: Callable[..., Any] = getattr(owner, name)

    @functools.wraps(original)
    def watched(*args: Any, **kwargs: Any) -> Any:
        _started[kind].append(what)
        return original(*args, **kwargs)

    setattr(owner, name, watched)


def _kinds_of_process(args: object) -> list[str]:
    """What a process with ``args`` runs in real time: ``gs sim-device`` a vehicle, ``gs fly``
    a flight (``--demo``: and its vehicle); also as ``python -m groundstation ...``."""
    words = [os.fspath(a) if isinstance(a, str | os.PathLike) else str(a)
             for a in (args if isinstance(args, Sequence) and not isinstance(args, str)
                       else str(args).split())]
    kinds = []
    if "sim-device" in words or ("fly" in words and "--demo" in words):
        kinds.append("vehicle")
    if "fly" in words:
        kinds.append("flight")
    return kinds


def pytest_configure(config: pytest.Config) -> None:
    if not hasattr(config, "workerinput"):  # the session's controller, or pytest without -n
        from eval_flights import share_on_disk

        root = share_on_disk()
        if root is not None:
            config.add_cleanup(lambda: shutil.rmtree(root, ignore_errors=True))
    from groundstation.app.daemon import FlightDaemon
    from sim_device.realtime import SimDeviceProcess, SimDeviceThread

    _watch(SimDeviceThread, "__enter__", "vehicle", "SimDeviceThread")
    _watch(SimDeviceProcess, "__enter__", "vehicle", "SimDeviceProcess")
    _watch(FlightDaemon, "run", "flight", "FlightDaemon.run")
    popen_init = subprocess.Popen.__init__

    @functools.wraps(popen_init)
    def init(self: subprocess.Popen[Any], args: Any, *rest: Any, **kwargs: Any) -> None:
        for kind in _kinds_of_process(args):
            _started[kind].append(f"a process: {' '.join(map(str, args))[:80]}")
        popen_init(self, args, *rest, **kwargs)

    subprocess.Popen.__init__ = init  # type: ignore[method-assign]


def _shares_a_module_fixture(item: pytest.Item) -> bool:
    """The test uses a module-scoped fixture of its own module (a recorded flight, a
    simulation): under xdist each worker that runs one of the module's tests would make
    it again, so the module's tests that use it run on one worker."""
    info = getattr(item, "_fixtureinfo", None)
    module = item.nodeid.split("::")[0]
    for name in info.names_closure if info is not None else ():
        defs = info.name2fixturedefs.get(name) if info is not None else None
        if defs and defs[-1].scope in ("module", "package") and defs[-1].baseid == module:
            return True
    return False


@pytest.hookimpl(tryfirst=True)  # before xdist reads the groups into the node ids
def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    for item in items:
        for mark, group in GROUPS.items():
            if item.get_closest_marker(mark) is not None:
                item.add_marker(pytest.mark.xdist_group(group))
        if item.get_closest_marker("xdist_group") is None and _shares_a_module_fixture(item):
            item.add_marker(pytest.mark.xdist_group(item.nodeid.split("::")[0]))
    # The order xdist hands out the work in (make test: --no-loadscope-reorder). The
    # real-time flights' lane is the longest (about 5.5 min, one flight after another),
    # so it goes first, or it starts behind whatever the worker that takes it holds; then
    # the grounded vehicles' lane, then the other modules, most tests first (xdist's own
    # order). Within a lane the fleet's flights come last, so they end the real-time lane
    # by when the grounded vehicles' shorter lane is done, instead of waiting for the lock
    # they take. A stable sort: the order is otherwise kept.
    scopes = [_scope(item) for item in items]
    sizes = {scope: scopes.count(scope) for scope in set(scopes)}
    lanes = list(GROUPS.values())
    first = {scope: i for i, scope in reversed(list(enumerate(scopes)))}

    def rank(pair: tuple[pytest.Item, str]) -> tuple[int, int, int, bool]:
        item, scope = pair
        lane = lanes.index(scope) if scope in lanes else len(lanes)
        return (lane, -sizes[scope], first[scope],
                "fleet_alone" in item.fixturenames)  # type: ignore[attr-defined]

    items[:] = [item for item, _ in sorted(zip(items, scopes, strict=True), key=rank)]


def _scope(item: pytest.Item) -> str:
    """The unit xdist's --dist loadgroup gives one worker: the item's group, or its module
    (or class) as --dist loadscope has it."""
    group = item.get_closest_marker("xdist_group")
    if group is not None:
        return str(group.args[0] if group.args else group.kwargs.get("name", "default"))
    return item.nodeid.rsplit("::", 1)[0]


def pytest_collection_finish(session: pytest.Session) -> None:
    """In an xdist worker under ``--dist loadgroup``: every grouped test's node id carries
    its group, or the groups would be ignored without a word (pytest 9.2 with
    pytest-xdist 3.8 did that) and real-time flights would fly side by side."""
    if not session.config.getoption("loadgroup", default=False):
        return
    lost = [item.nodeid for item in session.items
            if item.get_closest_marker("xdist_group") is not None and "@" not in item.nodeid]
    if lost:
        raise pytest.UsageError(
            f"--dist loadgroup is not grouping ({len(lost)} tests, e.g. {lost[0]}): this "
            "pytest and pytest-xdist do not work together; install the versions "
            "pyproject.toml's dev extra asks for")


def pytest_runtest_logstart(nodeid: str, location: object) -> None:
    for started in _started.values():
        started.clear()


def _mark_needed(item: pytest.Item) -> str | None:
    """The mark the test's real-time activity needs and it lacks, or None. A flight needs
    ``realtime`` only with a vehicle (a ``gs fly`` without one fails at once)."""
    vehicle, flight = _started["vehicle"], _started["flight"]
    if vehicle and flight and item.get_closest_marker("realtime") is None:
        return "realtime"
    if vehicle and not flight and not any(item.get_closest_marker(m) for m in GROUPS):
        return "virtual_vehicle"
    return None


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item: pytest.Item, call: pytest.CallInfo[None]) -> Iterator[None]:
    outcome = yield
    report = outcome.get_result()  # type: ignore[attr-defined]
    if call.when == "teardown" and report.passed and (mark := _mark_needed(item)) is not None:
        what = ", ".join(_started["vehicle"] + _started["flight"])
        report.outcome = "failed"
        report.longrepr = (f"{item.nodeid} runs in real time ({what}) but is not marked "
                           f"{mark}: add @pytest.mark.{mark} so it runs in its group, one "
                           "test at a time (tests/conftest.py)")


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


def _cpu_lock_path(factory: pytest.TempPathFactory) -> Path:
    """A lock file every worker of this session shares: in the session's temporary root
    (under pytest-xdist each worker's base is a directory in it)."""
    base = factory.getbasetemp()
    return (base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base) / "cpu.lock"


@contextlib.contextmanager
def _cpu_alone(path: Path) -> Iterator[None]:
    with path.open("a") as handle:
        fcntl.flock(handle, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)


@pytest.fixture(scope="module")
def fleet_alone(tmp_path_factory: pytest.TempPathFactory) -> Iterator[None]:
    """Held by a module's fleet flights: no grounded virtual vehicle runs meanwhile."""
    with _cpu_alone(_cpu_lock_path(tmp_path_factory)):
        yield


@pytest.fixture(autouse=True)
def grounded_vehicles_alone(request: pytest.FixtureRequest,
                            tmp_path_factory: pytest.TempPathFactory) -> Iterator[None]:
    """A ``virtual_vehicle`` test waits for a fleet's flights to end (see the docstring)."""
    if request.node.get_closest_marker("virtual_vehicle") is None:
        yield
        return
    with _cpu_alone(_cpu_lock_path(tmp_path_factory)):
        yield


@pytest.fixture
def repo() -> Path:
    """The repository root."""
    return REPO


@pytest.fixture(autouse=True)
def fresh_logging() -> Iterator[None]:
    """structlog's defaults before and after each test (see the module docstring)."""
    import structlog

    structlog.reset_defaults()
    yield
    structlog.reset_defaults()
