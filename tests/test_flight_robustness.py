"""Nothing from outside may crash, blind or silently abort a flight.

Real-time flights of the daemon against the virtual lab over a real pty and UDP, each
reproducing one of the hostile tester's findings and asserting that the flight goes
on, or ends as documented (`gs fly --help`: exit 0 mission completed and landed, 1
failsafe or abort, 3 could not start, 4 stopped on request). Finding 7 (a second `gs fly`
on a flying vehicle's port) is asserted on the flight of tests/test_flight_e2e.py's
``test_real_time_flight_over_pty_and_udp``, which it shares.

The assertions are about what happened, never about how fast the machine is: a
COMMAND gap is compared with the vehicle's 100 ms watchdog (the nominal gap is 20 ms),
a collector pause is measured in the collecting thread's CPU time. Speed figures
(latency percentiles, gaps over 30 flights, with and without load) are in
``benchmarks/bench_flight.py``.
"""

from __future__ import annotations

import contextlib
import gc
import os
import signal
import subprocess
import sys
import threading
import time
from collections import deque
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from lab_helpers import realtime_sim_config
from structlog.testing import capture_logs

from groundstation.app.daemon import FlightDaemon
from groundstation.app.fly import fly_command
from groundstation.app.recorder import read_flight
from groundstation.config import GroundStationConfig, apply_overrides, dump_config
from groundstation.endpoints import free_udp_port
from groundstation.flight.assembly import assemble
from groundstation.flight.supervisor import State
from sim_device.realtime import SimDeviceProcess, SimDeviceThread

REPO = Path(__file__).resolve().parents[1]
pytestmark = [pytest.mark.slow, pytest.mark.realtime]


def lab_config(tmp_path: Path, **overrides: object) -> GroundStationConfig:
    return apply_overrides(realtime_sim_config(), {
        "trajectory.name": "hover", "vicon.port": free_udp_port(),
        "telemetry.endpoint": "tcp://127.0.0.1:*", "telemetry.control_endpoint": None,
        "logging.flight_log_dir": str(tmp_path / "logs"),
        "sim.truth_file": str(tmp_path / "truth.npz"), **overrides,
    })


@contextlib.contextmanager
def vehicle_process(tmp_path: Path) -> Iterator[tuple[SimDeviceProcess, GroundStationConfig]]:
    """`gs sim-device` in a process of its own (it sees the daemon's pauses as the real
    X-3D would) and the lab configuration pointing at its pty."""
    cfg = lab_config(tmp_path)
    cfg_file = tmp_path / "lab.yaml"
    cfg_file.write_text(dump_config(cfg), encoding="utf-8")
    with SimDeviceProcess(cfg_file, tmp_path / "truth.npz") as vehicle:
        yield vehicle, apply_overrides(cfg, {"serial.port": vehicle.pty_path})


def wait_until(predicate: Callable[[], bool], timeout: float, what: str) -> None:
    deadline = time.monotonic() + timeout
    while not predicate():
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        time.sleep(0.02)


class Churn:
    """A busy neighbour in the daemon's process making cyclic garbage: every 2 ms 300
    self-referencing dicts, each batch kept alive for 60 ms (the last 9000). That is long
    enough to be promoted to the oldest generation, where only a full collection frees
    it; with the interpreter's own collector a full collection then comes every second
    or so and walks every object of the process."""

    def __init__(self) -> None:
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="churn", daemon=True)
        self.batches = 0

    def _run(self) -> None:
        ring: deque[list[dict[str, Any]]] = deque(maxlen=30)
        while not self._stop.wait(0.002):
            batch = []
            for _ in range(300):
                d: dict[str, Any] = {}
                d["self"] = d
                batch.append(d)
            ring.append(batch)
            self.batches += 1

    def __enter__(self) -> Churn:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join()


class CollectorWatch:
    """Every garbage collection in this process: generation, thread CPU time [s], the
    monotonic time it ended [s] and the collecting thread (the collecting thread's CPU
    time does not grow while the thread waits for a core on a loaded machine)."""

    def __init__(self) -> None:
        self.collections: list[tuple[int, float, float, int]] = []
        self._start = 0.0

    def __call__(self, phase: str, info: dict[str, int]) -> None:
        if phase == "start":
            self._start = time.thread_time()
        else:
            self.collections.append((info["generation"], time.thread_time() - self._start,
                                     time.monotonic(), threading.get_ident()))

    def __enter__(self) -> CollectorWatch:
        gc.callbacks.append(self)
        return self

    def __exit__(self, *exc: object) -> None:
        gc.callbacks.remove(self)


def test_object_churn_does_not_stall_the_commands(tmp_path: Path) -> None:
    """Finding 3: a full collection (~64 ms) stalled the keep-alive and the vehicle's
    watchdog expired in the air. The virtual vehicle runs in its own process here, so it
    sees the daemon's pauses as the real X-3D would."""
    with vehicle_process(tmp_path) as (vehicle, cfg):
        # a 3 s hover: with the take-off and the landing, 11 s of COMMANDs under the churn
        daemon = FlightDaemon(assemble(cfg), duration_s=3.0)
        with Churn() as churn, CollectorWatch() as watch:
            summary = daemon.run()
    assert vehicle.wire is not None
    assert churn.batches > 1000  # it churned all along (about 500 batches a second)
    assert summary.final_state is State.DONE, summary.transitions
    assert summary.success == (not summary.events), summary.events  # an expiry is a failsafe
    first, last = vehicle.wire.commanding_span()
    gaps = vehicle.wire.command_gaps(first, last)
    # The COMMANDs kept their 20 ms rhythm. How long the longest gap is depends on the
    # machine's load as much as on the collector (a busy CI machine stalls this process
    # too), so the gaps' tail is measured by benchmarks/bench_flight.py, and this test
    # asserts what the collector does, in CPU time, below (the interpreter's own collector
    # made gaps of 93-170 ms here on a quiet machine).
    assert len(gaps) > 300
    assert np.median(gaps) < 0.025, np.sort(gaps)[-10:]
    # No collection in the air walked the whole process: full collections ran only on
    # the loop's thread (right after a COMMAND), never at some allocation of the churn,
    # and the longest took a fraction of a full collection of this process, timed the
    # same way now (60-80 ms of CPU here; in the air p50 ~3 ms, at most ~8 ms).
    flying = [c for c in watch.collections if first <= c[2] <= last]
    assert flying, "the churn made no garbage collections?"
    assert {c[3] for c in flying if c[0] == 2} == {threading.get_ident()}
    longest = max(c[1] for c in flying)
    cpu0 = time.thread_time()
    gc.collect()
    whole = time.thread_time() - cpu0
    print(f"gaps max {1e3 * gaps.max():.1f} ms, p99 {1e3 * np.percentile(gaps, 99):.1f} ms; "
          f"{len(flying)} collections in the air, longest {1e3 * longest:.2f} ms CPU, whole "
          f"process {1e3 * whole:.1f} ms CPU; {summary.collector}")
    assert longest < 0.5 * whole, f"longest collection in the air: {1e3 * longest:.1f} ms"
    # ...and the flight log has what the vehicle reported on every tick: whether it
    # applied our commands, agreeing with the failsafe events the daemon logged (a
    # watchdog expiry in the air, if this machine stalled the loop that long).
    rows, _, _ = read_flight(summary.log_dir)
    applying = (rows["vehicle_flags"] & 0x01) != 0
    k0 = int(np.argmax(applying))
    k1 = int(np.flatnonzero(rows["state"] == int(State.DISARM))[-1])
    assert applying[k0:k1].all() == (not summary.events), summary.events


def gs_fly(config_file: Path) -> subprocess.Popen[str]:
    """`gs fly` in its own process group, as `timeout` or systemd would start it."""
    return subprocess.Popen(
        [str(Path(sys.executable).parent / "gs"), "fly", "--config", str(config_file)],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, start_new_session=True)


def read_until(child: subprocess.Popen[str], marker: str, timeout: float) -> list[str]:
    """Lines of the child's output up to and including the first one starting with
    ``marker`` (the progress lines start with the supervisor state)."""
    assert child.stdout is not None
    lines: list[str] = []
    done = threading.Event()

    def reader() -> None:
        assert child.stdout is not None
        for line in child.stdout:
            lines.append(line)
            if line.startswith(marker):
                done.set()
                return

    thread = threading.Thread(target=reader, daemon=True)
    thread.start()
    assert done.wait(timeout), "".join(lines)
    thread.join()
    return lines


@pytest.mark.parametrize(("apart_s", "landed"), [(0.001, True), (1.0, False)])
def test_two_sigterms(tmp_path: Path, apart_s: float, landed: bool) -> None:
    """Finding 6: GNU `timeout` (and systemd) signal the process, then its group, within a
    millisecond. Two signals that close are one stop request: the vehicle lands. A second
    request a second later is the operator's: hand back now."""
    cfg = lab_config(tmp_path)
    with SimDeviceThread(cfg) as device:
        config_file = tmp_path / "fly.yaml"
        config_file.write_text(dump_config(apply_overrides(
            cfg, {"serial.port": device.info.pty_path})), encoding="utf-8")
        child = gs_fly(config_file)
        try:
            head = read_until(child, "TAKEOFF", 60.0)
            time.sleep(1.0)  # climbing
            os.kill(child.pid, signal.SIGTERM)  # what `timeout 60 gs fly` does
            time.sleep(apart_s)
            os.killpg(child.pid, signal.SIGTERM)
            out = "".join(head) + child.communicate(timeout=60)[0]
        finally:
            if child.poll() is None:
                child.kill()
                child.communicate()
    assert child.returncode == 4, out  # stopped on request
    if landed:
        assert "TAKEOFF -> LAND: stop requested: landing" in out, out
        assert "DISARM -> DONE" in out and "HANDBACK" not in out, out
    else:
        assert "LAND -> HANDBACK: stop requested twice" in out, out
    assert "stopped on request" in out


def test_a_failsafe_landing_exits_1_with_a_warning(tmp_path: Path) -> None:
    """Finding 5: a landing forced by Vicon loss printed 'normal end' and exited 0."""
    # Vicon goes at 6 s of the lab's clock: the vehicle is in the air by then (take-off
    # starts ~1.2 s after the daemon, REALTIME_SETTLE_S, and reaches the hover ~2.5 s later
    # with REALTIME_MOVES' climb and the handover's blend; on a loaded machine it may still
    # be climbing, and a landing forced there is as much the finding's).
    cfg = lab_config(tmp_path, **{"sim.vicon.outages": [[6.0, 60.0]]})
    lines: list[str] = []
    with SimDeviceThread(cfg) as device, capture_logs() as logs:
        code = fly_command(assemble(apply_overrides(cfg, {"serial.port": device.info.pty_path})),
                           duration_s=30.0, echo=lines.append)
    text = "\n".join(lines)
    assert code == 1, text
    assert "Vicon lost" in text and "failsafe" in text and "normal end" not in text, text
    failsafes = [e for e in logs if e.get("event") == "supervisor" and e.get("failsafe")]
    assert failsafes and all(e["log_level"] == "warning" for e in failsafes), failsafes
    assert any(e["new"] == "LAND" for e in failsafes)


def test_a_link_failure_ends_with_a_summary_and_a_final_row(tmp_path: Path) -> None:
    """Finding 9: after a serial link failure no summary was printed and the flight log's
    last row said TRACK with ctrl mask 15."""
    cfg = lab_config(tmp_path)
    lines: list[str] = []
    with SimDeviceThread(cfg) as device:
        cfg = apply_overrides(cfg, {"serial.port": device.info.pty_path})
        result: dict[str, int] = {}
        thread = threading.Thread(target=lambda: result.setdefault(
            "code", fly_command(assemble(cfg), duration_s=30.0, echo=lines.append)))
        thread.start()
        try:
            wait_until(lambda: any(line.startswith("TRACK") for line in lines), 30.0,
                       "TRACK")
            device.unplug()  # the adapter is pulled out
        finally:
            thread.join(30.0)
    text = "\n".join(lines)
    assert result.get("code") == 1, text
    assert "flight ended in LINK_LOST" in text, text
    log_dir = next(line.split("flight log:")[1].strip() for line in lines
                   if "flight log:" in line)
    rows, meta, _ = read_flight(log_dir)
    assert rows["state"][-1] == int(State.LINK_LOST) and rows["cmd_mask"][-1] == 0
    assert meta["outcome"]["final_state"] == "LINK_LOST"
    assert meta["outcome"]["exit_code"] == 1
