"""The planner process: run-time motions are planned where they cannot touch the flight loop.

The real process (``os.posix_spawn``, a socket pair, pickles), no flight: a motion planned
there meets its boundary conditions; a plan past its deadline is refused and the process
replaced; a process that dies or a job that fails is answered ``internal``; the process
runs at normal priority in its own process group whatever the thread that starts it; and
an allocation storm in a plan leaves this process's collections young-only, where the
same storm in a thread of this process makes the paced collector walk it (the control
experiment, so the test can fail).

The jobs below are defined here; the planner imports this module to run them (it gets this
process's ``sys.path``).
"""

from __future__ import annotations

import gc
import math
import os
import threading
import time
from dataclasses import dataclass
from typing import Any

import numpy as np
import pytest
from lab_helpers import sim_config

from groundstation.app.planner_process import PLANNER_NICE, PlannerProcess
from groundstation.app.realtime import CollectorPacer, fifo_priority
from groundstation.flight.assembly import assemble
from groundstation.flight.commander import Commander, CommandRefusedError
from groundstation.flight.planner import (
    GoTo,
    InlinePlanner,
    PlanMotion,
    Planner,
    PlannerSettings,
)

SETTINGS = assemble(sim_config(**{"trajectory.name": "none"})).planner
HOME = np.array([0.0, 0.0, -1.0])


# --------------------------------------------------------------------------- jobs
@dataclass(frozen=True)
class Sleep:
    """Takes ``seconds`` [s]."""

    seconds: float

    def run(self, settings: PlannerSettings) -> float:
        time.sleep(self.seconds)
        return self.seconds


@dataclass(frozen=True)
class Exit:
    """Ends the process with ``code``, as a crash would."""

    code: int

    def run(self, settings: PlannerSettings) -> None:
        os._exit(self.code)


@dataclass(frozen=True)
class Fail:
    """Raises ``error``."""

    error: Exception

    def run(self, settings: PlannerSettings) -> None:
        raise self.error


@dataclass(frozen=True)
class Probe:
    """Where the job runs: (pid, scheduling policy, nice value, process group)."""

    def run(self, settings: PlannerSettings) -> tuple[int, int, int, int]:
        return os.getpid(), os.sched_getscheduler(0), os.nice(0), os.getpgid(0)


@dataclass(frozen=True)
class Churn:
    """A deliberately allocation-heavy plan: ``seconds`` [s] of self-referencing dicts in
    batches of 1000, the last ``keep`` batches kept alive (promoted to the oldest
    generation, as a planner's samples are). Returns the full collections the process made
    meanwhile and the batches made."""

    seconds: float = 1.5
    keep: int = 300

    def run(self, settings: PlannerSettings | None) -> tuple[int, int]:
        full0 = gc.get_stats()[2]["collections"]
        ring: list[list[dict[str, Any]]] = []
        end = time.monotonic() + self.seconds
        batches = 0
        while time.monotonic() < end:
            batch = []
            for _ in range(1000):
                d: dict[str, Any] = {}
                d["self"] = d
                batch.append(d)
            ring.append(batch)
            del ring[:-self.keep]
            batches += 1
        return gc.get_stats()[2]["collections"] - full0, batches


def _base(commander: Commander) -> Any:
    return commander.base(0.0, 0.0, "TRACK", np.zeros(3))


def _soon(seconds: float = 30.0) -> float:
    return time.monotonic() + seconds


@pytest.mark.slow
# --------------------------------------------------------------------------- planning
def test_a_motion_planned_in_the_planner_process_meets_its_boundary_conditions() -> None:
    commander = Commander(HOME, 0.0, arrival_tolerance_m=0.05, idle_land_s=60.0)
    base = _base(commander)
    target = np.array([0.5, -0.3, -1.2])
    with PlannerProcess(SETTINGS, timeout_s=30.0) as planner:
        pieces, motion = planner.run(PlanMotion(GoTo(target, 1.0, None), base), _soon())
        pid = planner.pid
    assert pid is not None and pid != os.getpid()
    move, rest = pieces
    start, end = move.sample(base.start), rest.sample(motion.end + 1.0)
    # it starts where the reference was, at rest, and ends at rest at the target, turned
    assert np.allclose(start.position, HOME) and np.allclose(start.velocity, 0.0)
    assert np.allclose(end.position, target) and np.allclose(end.velocity, 0.0)
    assert math.isclose(end.yaw, 1.0, abs_tol=1e-12)
    # pid reaped: no zombie left behind
    with pytest.raises(ChildProcessError):
        os.waitpid(pid, os.WNOHANG)


@pytest.mark.slow
def test_a_plan_past_its_deadline_is_refused_and_the_planner_replaced() -> None:
    commander = Commander(HOME, 0.0, arrival_tolerance_m=0.05, idle_land_s=60.0)
    with PlannerProcess(SETTINGS, timeout_s=0.5) as planner:
        planner.run(Sleep(0.0), _soon())  # ready
        first = planner.pid
        began = time.monotonic()
        with pytest.raises(CommandRefusedError, match=r"api\.plan_timeout_s \(0\.5 s\)") as exc:
            planner.run(Sleep(30.0), time.monotonic() + 0.5)
        waited = time.monotonic() - began
        assert exc.value.kind == "infeasible"
        assert waited < 10.0  # the 30 s job was abandoned, not waited for
        assert planner.pid is not None and planner.pid != first
        assert (planner.timeouts, planner.restarts) == (1, 1)
        # the one that planned past its deadline is gone (killed and reaped)
        assert first is not None
        with pytest.raises(ChildProcessError):
            os.waitpid(first, os.WNOHANG)
        # the new one plans
        pieces, _ = planner.run(PlanMotion(GoTo(np.array([0.2, 0.0, -1.0]), None, None),
                                           _base(commander)), _soon())
    assert np.allclose(pieces[-1].sample(99.0).position, [0.2, 0.0, -1.0])


@pytest.mark.slow
def test_a_planner_that_dies_or_fails_is_answered_internal_and_refusals_keep_their_kind(
        ) -> None:
    with PlannerProcess(SETTINGS, timeout_s=30.0) as planner:
        with pytest.raises(CommandRefusedError, match=r"ended while planning \(exit status 7\)") \
                as died:
            planner.run(Exit(7), _soon())
        assert died.value.kind == "internal" and planner.restarts == 1
        with pytest.raises(CommandRefusedError, match="ZeroDivisionError: sorry") as failed:
            planner.run(Fail(ZeroDivisionError("sorry")), _soon())
        assert failed.value.kind == "internal"
        with pytest.raises(CommandRefusedError, match="out there") as refused:
            planner.run(Fail(CommandRefusedError("volume", "out there")), _soon())
        assert refused.value.kind == "volume"
        assert planner.run(Sleep(0.0), _soon()) == 0.0  # and it goes on planning
    with pytest.raises(CommandRefusedError, match="not running") as closed:
        planner.run(Sleep(0.0), _soon())
    assert closed.value.kind == "internal"


@pytest.mark.slow
def test_closing_ends_a_plan_under_way() -> None:
    planner = PlannerProcess(SETTINGS, timeout_s=60.0)
    planner.start()
    planner.run(Sleep(0.0), _soon())
    pid = planner.pid
    outcome: list[BaseException] = []

    def plan() -> None:
        try:
            planner.run(Sleep(60.0), _soon(60.0))
        except CommandRefusedError as exc:
            outcome.append(exc)
    thread = threading.Thread(target=plan)
    thread.start()
    time.sleep(0.3)
    planner.close()
    thread.join(10.0)
    assert not thread.is_alive()
    assert outcome and isinstance(outcome[0], CommandRefusedError)
    assert outcome[0].kind == "internal"
    assert pid is not None
    with pytest.raises(ChildProcessError):
        os.waitpid(pid, os.WNOHANG)
    assert planner.pid is None


@pytest.mark.slow
def test_a_planner_closed_while_it_starts_ends_quietly(capfd: pytest.CaptureFixture[str]
                                                       ) -> None:
    """Closed before it has imported (a flight that ends at once): reaped, and nothing on
    stderr (it writes to the daemon's)."""
    planner = PlannerProcess(SETTINGS, timeout_s=30.0)
    planner.start()
    pid = planner.pid
    planner.close()
    assert pid is not None
    with pytest.raises(ChildProcessError):
        os.waitpid(pid, os.WNOHANG)
    time.sleep(0.2)
    # only this process's own log lines (when a test before configured logging to stderr):
    # nothing from the child, which would be a traceback
    err = [line for line in capfd.readouterr().err.splitlines()
           if "planner process started" not in line]
    assert err == []


@pytest.mark.slow
def test_the_planner_runs_at_normal_priority_in_a_process_group_of_its_own() -> None:
    """The daemon's threads run SCHED_FIFO in the air; its planner must not: a plan at
    real-time priority would compete with the loop for a core. Started from a SCHED_FIFO
    thread when this machine allows one."""
    result: dict[str, Any] = {}

    def start_and_probe() -> None:
        with fifo_priority(10, who="test") as held:
            result["fifo"] = held
            with PlannerProcess(SETTINGS, timeout_s=30.0) as planner:
                result["probe"] = planner.run(Probe(), _soon())
    thread = threading.Thread(target=start_and_probe)
    thread.start()
    thread.join(60.0)
    pid, policy, nice, group = result["probe"]
    assert pid != os.getpid()
    assert policy == os.SCHED_OTHER, (result["fifo"], policy)
    assert nice == min(19, os.nice(0) + PLANNER_NICE)
    assert group == pid != os.getpgid(0)  # a Ctrl-C to our group never reaches it
    if not result["fifo"]:
        pytest.skip("SCHED_FIFO not allowed here: only the normal-policy start was tested")


# --------------------------------------------------------------------------- the collector
class _LoopLike:
    """A thread that does what the daemon's loop does for the collector: every 10 ms a
    COMMAND's worth of nothing, then :meth:`CollectorPacer.after_command`."""

    def __init__(self, pacer: CollectorPacer) -> None:
        self._pacer = pacer
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="loop-like")

    def _run(self) -> None:
        while not self._stop.wait(0.01):
            self._pacer.after_command()

    def __enter__(self) -> _LoopLike:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join()


def _collections_during(planner: Planner) -> tuple[list[int], tuple[int, int]]:
    """The generations of this process's collections while ``planner`` runs a churning
    plan, under the daemon's paced collector, and the plan's result."""
    generations: list[int] = []

    def watch(phase: str, info: dict[str, int]) -> None:
        if phase == "stop":
            generations.append(info["generation"])
    with CollectorPacer(True) as pacer, _LoopLike(pacer):
        gc.callbacks.append(watch)
        try:
            result = planner.run(Churn(), _soon())
        finally:
            gc.callbacks.remove(watch)
    return generations, result


@pytest.mark.slow
def test_a_churning_plan_leaves_this_process_young_only() -> None:
    """The hostile tester's plan kept hundreds of thousands of objects alive and every full
    collection of the daemon walked them. In the planner process the churn is the planner's
    own: this process sees no full collection while it runs. The same plan run in a thread
    of this process (the control experiment) makes the paced collector run full ones."""
    with PlannerProcess(SETTINGS, timeout_s=60.0) as planner:
        planner.run(Sleep(0.0), _soon())  # ready: its start-up is not part of the plan
        away, (full_there, batches) = _collections_during(planner)
    assert batches > 50 and full_there > 0  # it churned, and collected fully, over there
    assert 2 not in away, away  # here: young collections at most
    inline, (_, inline_batches) = _collections_during(InlinePlanner(SETTINGS))
    assert inline_batches > 50
    assert inline.count(2) > 0, inline  # the same churn here reaches the full collection
