"""The run-time API end to end, as a researcher uses it: one real-time flight serves it all.

The virtual vehicle (``gs sim-device``) and the daemon (``gs fly --trajectory none``) each
run in a process of their own, talking over a pty, UDP and ZeroMQ on loopback, as in the
lab. On that one flight, in order (the tests of this module, sharing the module-scoped
``flight``):

1. before take-off a motion is refused (not airborne yet);
2. the command line (``gs status``, ``gs goto``, ``gs hold``) commands the flying daemon;
3. a :class:`groundstation.client.Client` in this process flies three go-tos;
4. refusals, each of its kind (outside the volume, infeasible, a bad request);
5. two clients at once: one asks for the status in a tight loop while the other flies a
   figure-eight;
6. a client killed in the middle of its motion: the motion goes on, the vehicle holds;
7. ``examples/fly_square.py`` flies its four corners and lands: the daemon exits 0;
8. the flight as a third client and the virtual lab saw it: the supervisor's transitions
   over the telemetry, every arrival and corner judged from the lab's ground truth.

Each test makes what it needs of the steps before it (a step runs once per flight), so a
test run alone (``pytest -k``) still flies; a step that fails fails its own test, and the
fixture's teardown still lands the vehicle (SIGINT to the daemon) and stops the lab.
"""

from __future__ import annotations

import contextlib
import json
import os
import select
import signal
import subprocess
import sys
import textwrap
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from lab_helpers import realtime_sim_config

from groundstation.client import (
    BadRequest,
    Client,
    DaemonUnreachableError,
    Infeasible,
    NotNow,
    OutsideVolume,
)
from groundstation.config import GroundStationConfig, apply_overrides, dump_config
from groundstation.endpoints import free_ports, free_udp_port
from sim_device.realtime import SimDeviceProcess

REPO = Path(__file__).resolve().parents[1]
GS = Path(sys.executable).parent / "gs"
EXAMPLE = REPO / "examples" / "fly_square.py"
pytestmark = [pytest.mark.realtime, pytest.mark.slow]

GOALS = ([0.5, 0.0, -1.0], [0.5, 0.5, -1.3], [-0.4, 0.2, -0.8])
"""Three go-tos, NED [m]: along x, diagonal with a climb, back across with a descent."""
KILLED_GOAL = [0.0, -0.5, -1.0]
"""Where the client that is killed mid-motion sends the vehicle, NED [m] (in 4 s)."""
CORNERS = np.array([[0.375, 0.375, -1.0], [0.375, -0.375, -1.0],
                    [-0.375, -0.375, -1.0], [-0.375, 0.375, -1.0]])
"""The square fly_square.py flies: 0.75 m side, centred on (0, 0), 1 m up (NED [m])."""
TRANSITIONS = [("PREFLIGHT", "TAKEOFF"), ("TAKEOFF", "TRACK"), ("TRACK", "LAND"),
               ("LAND", "DISARM"), ("DISARM", "DONE")]
"""The supervisor's transitions of a nominal commanded flight, in order."""


def _gs(*args: str, timeout: float = 30.0) -> subprocess.CompletedProcess[str]:
    """Run ``gs ARGS`` to completion."""
    return subprocess.run([str(GS), *args], capture_output=True, text=True, cwd=REPO,
                          timeout=timeout, check=False)


def _gs_together(*commands: tuple[str, ...],
                 timeout: float = 30.0) -> list[subprocess.CompletedProcess[str]]:
    """Run several ``gs`` commands at the same time, each to completion."""
    children = [subprocess.Popen([str(GS), *args], stdout=subprocess.PIPE,
                                 stderr=subprocess.PIPE, text=True, cwd=REPO)
                for args in commands]
    done: list[subprocess.CompletedProcess[str]] = []
    try:
        for args, child in zip(commands, children, strict=True):
            out, err = child.communicate(timeout=timeout)
            done.append(subprocess.CompletedProcess(args, child.returncode, out, err))
    finally:
        for child in children:
            if child.poll() is None:
                child.kill()
                child.wait(10.0)
    return done


def _stop(child: subprocess.Popen[Any] | None, grace_s: float) -> None:
    """End ``child`` if it still runs: SIGINT (the daemon lands) and, after ``grace_s``,
    SIGKILL."""
    if child is None or child.poll() is not None:
        return
    child.send_signal(signal.SIGINT)
    try:
        child.wait(grace_s)
    except subprocess.TimeoutExpired:
        child.kill()
        child.wait(10.0)


def _without_systemd() -> dict[str, str]:
    """This environment without NOTIFY_SOCKET: the daemon must not notify a service
    manager the test may run under."""
    return {k: v for k, v in os.environ.items() if k != "NOTIFY_SOCKET"}


def _tail(path: Path, lines: int = 30) -> str:
    text = path.read_text(encoding="utf-8", errors="replace") if path.exists() else ""
    return "\n".join(text.splitlines()[-lines:])


def _truth_at(truth: Any, t: float) -> np.ndarray:
    """The true position [m] at monotonic time ``t`` [s] (the sample before it)."""
    times = float(truth["start_monotonic"]) + truth["t"]
    k = int(np.searchsorted(times, t))
    return np.asarray(truth["position"][max(0, min(k, len(times)) - 1)])


class ThirdClient(Client):
    """A Client whose telemetry subscription says when its first message arrived (the
    connection is made by ZeroMQ's own thread: only then are its sockets all open)."""

    def __init__(self, endpoint: str, *, telemetry: str) -> None:
        super().__init__(endpoint, telemetry=telemetry)
        self.listening = threading.Event()

    def subscribe(self, topics: Sequence[str] = ("state", "health"),
                  timeout: float | None = None) -> Iterator[tuple[str, dict[str, Any]]]:
        for message in super().subscribe(topics, timeout):
            self.listening.set()
            yield message


class StepFailedError(Exception):
    """A step of the flight that an earlier test ran failed (that test says why)."""


class Flight:
    """The one flight of this module: the lab and the daemon in processes of their own, a
    Client in this process, a third client following the transitions in a thread, and
    what each step recorded for the last test to judge against the ground truth."""

    def __init__(self, tmp: Path, stack: contextlib.ExitStack) -> None:
        self.tmp = tmp
        self.control, self.telemetry = (f"tcp://127.0.0.1:{p}" for p in free_ports(2))
        self.truth_file = tmp / "truth.npz"
        self.cfg: GroundStationConfig = apply_overrides(
            realtime_sim_config(), {
                "vicon.port": free_udp_port(), "telemetry.endpoint": self.telemetry,
                "telemetry.control_endpoint": self.control,
                "logging.flight_log_dir": str(tmp / "logs"),
                "sim.truth_file": str(self.truth_file),
                # each `gs` command and the example take seconds to start on a loaded
                # machine: the idle landing must not come between them (and a test that
                # stalls still ends with a landing)
                "api.idle_land_s": 90.0,
            })
        cfg_file = tmp / "lab.yaml"
        cfg_file.write_text(dump_config(self.cfg), encoding="utf-8")
        self.daemon_out = tmp / "fly.out"
        # per step, the goals the client was told it arrived at, and when (monotonic [s])
        self.arrivals: dict[str, list[tuple[list[float], float]]] = {}
        self.seen: list[tuple[str, str]] = []  # the transitions the third client saw
        self.truth: dict[str, np.ndarray] | None = None
        self._steps: dict[str, BaseException | None] = {}
        self.daemon: subprocess.Popen[bytes] | None = None
        self.example: subprocess.Popen[bytes] | None = None
        self.follower: threading.Thread | None = None
        # the vehicle's own bound: it stops even if this process dies without stopping it
        self.device = stack.enter_context(SimDeviceProcess(
            cfg_file, self.truth_file, duration=300.0, stderr=tmp / "sim.err"))
        stack.callback(self._stop_everything)
        with self.daemon_out.open("wb") as out:
            self.daemon = subprocess.Popen(
                [str(GS), "fly", "--config", str(cfg_file), "--trajectory", "none",
                 "--serial-port", self.device.pty_path], cwd=REPO, stdout=out,
                stderr=subprocess.STDOUT, env=_without_systemd())
        self.gs = Client(self.control, telemetry=self.telemetry, timeout_s=5.0)
        self._wait_until_answering(self.daemon)
        # a third client follows the supervisor's transitions over the telemetry, from
        # PREFLIGHT (the daemon answers before its preflight checks can have passed)
        third = ThirdClient(self.control, telemetry=self.telemetry)
        self.follower = threading.Thread(target=lambda: self.seen.extend(
            third.transitions(30.0)), name="transitions")
        self.follower.start()
        assert third.listening.wait(30.0), self.fail("no telemetry within 30 s")

    def _wait_until_answering(self, daemon: subprocess.Popen[bytes]) -> None:
        """Block until the daemon answers on its control socket; fail with its output if
        it exits or does not answer within a minute (generous: a loaded 2-core machine)."""
        client = Client(self.control, timeout_s=2.0)
        deadline = time.monotonic() + 60.0
        while time.monotonic() < deadline:
            assert daemon.poll() is None, \
                f"gs fly exited {daemon.returncode}:\n{_tail(self.daemon_out)}"
            with contextlib.suppress(DaemonUnreachableError):
                client.status()
                return
            time.sleep(0.1)
        pytest.fail(f"gs fly did not answer within 60 s:\n{_tail(self.daemon_out)}")

    def once(self, name: str, step: Callable[[], object]) -> None:
        """Run ``step`` unless it ran before in this flight; StepFailedError if it failed
        then (its own test reported why)."""
        if name in self._steps:
            error = self._steps[name]
            if error is not None:
                raise StepFailedError(f"the step {name!r} failed earlier in this flight: "
                                      f"{type(error).__name__}: {str(error)[:300]}")
            return
        self._steps[name] = None
        try:
            step()
        except BaseException as exc:
            self._steps[name] = exc
            raise

    def ran(self, name: str) -> bool:
        """The step ``name`` ran (or runs) in this flight."""
        return name in self._steps

    def passed(self, name: str) -> bool:
        """The step ``name`` ran in this flight and did not fail."""
        return name in self._steps and self._steps[name] is None

    def take_off(self) -> None:
        """Airborne at 1 m (the daemon takes off by itself; this waits for TRACK)."""
        self.once("take_off", lambda: self.gs.takeoff(1.0, timeout=60.0))

    def stop_lab(self) -> dict[str, np.ndarray]:
        """Stop the lab (it writes the ground truth) and the follower; the truth."""
        if self.truth is None:
            self.device.__exit__(None, None, None)
            if self.follower is not None:
                self.follower.join(40.0)
            with np.load(self.truth_file) as npz:
                self.truth = {key: np.asarray(npz[key]) for key in npz.files}
        return self.truth

    def _stop_everything(self) -> None:
        """Teardown: the example and the daemon stop (SIGINT: the daemon lands first);
        the lab stops after them (the stack), the follower once the telemetry ends."""
        _stop(self.example, 5.0)
        _stop(self.daemon, 30.0)
        if self.follower is not None:
            self.follower.join(40.0)

    def fail(self, message: str) -> str:
        """``message`` with the end of the daemon's output."""
        return f"{message}\n--- gs fly:\n{_tail(self.daemon_out)}"


@pytest.fixture(scope="module")
def flight(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Flight]:
    with contextlib.ExitStack() as stack:
        yield Flight(tmp_path_factory.mktemp("api-flight"), stack)


def test_a_motion_before_take_off_is_refused(flight: Flight) -> None:
    if flight.ran("take_off"):
        pytest.fail("this flight took off already: this test runs first in its module")
    with pytest.raises(NotNow, match="not airborne yet"):
        flight.gs.go_to(GOALS[0])


def test_the_command_line_commands_the_flying_daemon(flight: Flight) -> None:
    flight.take_off()

    def cli() -> None:
        # while the vehicle holds at the take-off height; the two that change nothing run
        # at once (each `gs` takes seconds to start when loaded)
        control = flight.control
        now, refused = _gs_together(("status", "--json", "--endpoint", control),
                                    ("goto", "3", "0", "-1", "--endpoint", control))
        assert now.returncode == 0, now.stderr
        reply = json.loads(now.stdout)
        assert reply["state"] == "TRACK" and reply["commanded"] is True
        assert refused.returncode == 1, (refused.stdout, refused.stderr)
        assert "safety.volume_x" in refused.stderr, refused.stderr
        moved = _gs("goto", "0.3", "0", "-1", "--wait", "--endpoint", control,
                    "--timeout", "10", timeout=60.0)
        assert moved.returncode == 0, moved.stderr
        assert "arrived" in moved.stdout, moved.stdout
        held = _gs("hold", "--endpoint", control)
        assert held.returncode == 0, held.stderr
        assert "holding at" in held.stdout, held.stdout
    flight.once("cli", cli)


def test_the_client_flies_three_go_tos(flight: Flight) -> None:
    flight.take_off()

    def go_tos() -> None:
        arrivals = flight.arrivals.setdefault("go_tos", [])  # judged from the truth last
        for goal in GOALS:
            motion = flight.gs.go_to(goal, wait=True, timeout=30.0)
            assert motion.state == "arrived", (goal, motion)
            arrivals.append((goal, time.monotonic()))
    flight.once("go_tos", go_tos)


def test_refusals_carry_their_kind_and_reason(flight: Flight) -> None:
    flight.take_off()

    def refusals() -> None:
        gs = flight.gs
        with pytest.raises(OutsideVolume, match=r"safety\.volume_x"):
            gs.go_to([3.0, 0.0, -1.0])
        with pytest.raises(Infeasible, match="max_speed"):
            gs.go_to([0.5, 0.0, -1.0], duration=0.4)
        with pytest.raises(BadRequest, match="3 numbers"):
            gs.request({"request": "go_to", "position": [0.0, 0.0]})
    flight.once("refusals", refusals)


def test_two_clients_at_once(flight: Flight) -> None:
    """One client asks for the status in a tight loop while the other flies a
    figure-eight: neither waits for the other's requests to fail."""
    flight.take_off()

    def figure_eight() -> None:
        other = Client(flight.control, timeout_s=5.0)
        states: list[str] = []
        stop = threading.Event()

        def watch() -> None:
            while not stop.is_set():
                states.append(other.status().state)
        watcher = threading.Thread(target=watch)
        watcher.start()
        try:
            figure8 = flight.gs.follow({"name": "figure-eight", "period_s": 8.0,
                                        "center": [0.0, 0.0, -1.0], "size_m": 0.75},
                                       wait=True, timeout=60.0)
        finally:
            stop.set()
            watcher.join(10.0)
        assert figure8.state == "arrived" and len(states) > 20, (figure8, len(states))
        assert set(states) == {"TRACK"}
    flight.once("figure_eight", figure_eight)


def test_a_client_killed_mid_motion(flight: Flight) -> None:
    """The motion goes on to its end and the vehicle holds there; the daemon keeps
    answering."""
    flight.take_off()

    def killed() -> None:
        gs = flight.gs
        client = subprocess.Popen([sys.executable, "-c", textwrap.dedent(f"""
            import time
            from groundstation.client import Client
            Client({flight.control!r}).go_to({KILLED_GOAL!r}, duration=4.0)
            print("sent", flush=True)
            time.sleep(60)
        """)], stdout=subprocess.PIPE, text=True, cwd=REPO)
        try:
            assert client.stdout is not None
            assert select.select([client.stdout], [], [], 60.0)[0], "the client sent nothing"
            assert client.stdout.readline().strip() == "sent"
        finally:
            client.kill()
            client.wait(10.0)
            assert client.stdout is not None
            client.stdout.close()
        arrived = gs.wait_until_arrived(timeout=30.0)
        assert arrived.motion is not None and arrived.motion.state == "arrived", arrived
        flight.arrivals["killed_client"] = [(KILLED_GOAL, time.monotonic())]
        time.sleep(1.0)
        held = gs.status()
        assert held.state == "TRACK" and held.error_m is not None and held.error_m < 0.05, held
        # planned within api.plan_timeout_s or refused (the planner runs niced, so on a
        # loaded machine a plan waits for the CPU; bench_api.py measures the latency on a
        # quiet one)
        latency = held.motion.latency_s if held.motion is not None else None
        assert latency is not None and latency < flight.cfg.api.plan_timeout_s + 0.1, held
    flight.once("killed_client", killed)


def test_the_example_flies_its_square_and_lands(flight: Flight) -> None:
    """examples/fly_square.py: four corners, then it lands and reports how the flight
    ended; the daemon ends on its own once landed and handed back: COMPLETED, exit 0."""
    def example() -> None:
        example_out = flight.tmp / "example.out"
        with example_out.open("wb") as out:
            flight.example = subprocess.Popen(
                [sys.executable, str(EXAMPLE), "--endpoint", flight.control,
                 "--telemetry", flight.telemetry], cwd=REPO, stdout=out,
                stderr=subprocess.STDOUT)
        code = flight.example.wait(90.0)
        printed = example_out.read_text(encoding="utf-8")
        assert code == 0, flight.fail(printed)
        corners = [line for line in printed.splitlines()
                   if line.startswith("corner") and "arrived" in line]
        assert len(corners) == 4, printed
        # what Client.land(wait=True) returned: the flight's final telemetry message
        assert "flight ended in DONE (COMPLETED)" in printed, printed
        assert flight.daemon is not None and flight.daemon.wait(30.0) == 0, \
            flight.fail("gs fly did not exit 0")
    flight.once("example", example)


@pytest.mark.timeout(300)  # run alone, it flies the steps it judges: a minute or two
def test_the_flight_as_the_lab_and_a_third_client_saw_it(flight: Flight) -> None:
    # run alone (pytest -k), this test flies the steps whose records it judges; a step that
    # failed in its own test is passed over here (that test failed, and says why)
    for name, step in (("go_tos", test_the_client_flies_three_go_tos),
                       ("killed_client", test_a_client_killed_mid_motion),
                       ("example", test_the_example_flies_its_square_and_lands)):
        if not flight.ran(name):
            step(flight)
    landed_by_the_example = flight.passed("example")
    if not landed_by_the_example and flight.daemon is not None and flight.daemon.poll() is None:
        flight.gs.land(wait=True, timeout=60.0)  # the example failed: land all the same
        flight.daemon.wait(30.0)
    truth = flight.stop_lab()
    assert flight.seen == TRANSITIONS, flight.seen
    # the daemon's own account: landed on the client's request, a nominal end
    out = flight.daemon_out.read_text(encoding="utf-8")
    assert "TRACK -> LAND: land requested by a client" in out, flight.fail("no such line")
    (meta_file,) = (flight.tmp / "logs").glob("*/meta.json")
    outcome = json.loads(meta_file.read_text(encoding="utf-8"))["outcome"]
    assert outcome["outcome"] == "COMPLETED" and outcome["final_state"] == "DONE", outcome
    assert outcome["exit_code"] == 0 and outcome["reason"].startswith("landed"), outcome
    # arrival judged from the ground truth: within 6 cm of each goal once the client was
    # told it arrived (the lab's clock is the same monotonic clock, offset by its start)
    expected = {"go_tos": list(GOALS), "killed_client": [KILLED_GOAL]}
    for name, goals in expected.items():
        recorded = flight.arrivals.get(name, [])
        if flight.passed(name):
            assert [goal for goal, _ in recorded] == goals, (name, recorded)
        for goal, t_arrived in recorded:
            error = float(np.linalg.norm(_truth_at(truth, t_arrived) - goal))
            assert error < 0.06, (name, goal, error)
    # the example's square: the true path passed within 5 cm of every corner, and the
    # vehicle ended on the floor
    path = np.asarray(truth["position"])
    if landed_by_the_example:
        for corner in CORNERS:
            closest = float(np.min(np.linalg.norm(path - corner, axis=1)))
            assert closest < 0.05, (corner, closest)
    assert bool(truth["on_ground"][-1]) and abs(path[-1, 2] - path[0, 2]) < 0.03, path[-1]
