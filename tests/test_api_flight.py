"""A real-time flight driven only through the run-time API.

The daemon flies ``--trajectory none`` against the virtual vehicle in its own process
(a pty and UDP, as in the lab); a :class:`groundstation.client.Client` takes off,
flies three go-tos and a figure-eight, and lands. Arrival is judged from the virtual
lab's ground truth. On the way: refusals, two clients at once, and a client killed in
the middle of a motion.
"""

from __future__ import annotations

import subprocess
import sys
import textwrap
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from lab_helpers import free_udp_port

from groundstation.app.daemon import FlightDaemon, FlightSummary
from groundstation.client import (
    BadRequest,
    Client,
    Infeasible,
    Motion,
    NotNow,
    OutsideVolume,
)
from groundstation.config import apply_overrides, dump_config, load_config
from groundstation.flight.assembly import assemble
from groundstation.flight.supervisor import Outcome, State
from sim_device.realtime import SimDeviceProcess

REPO = Path(__file__).resolve().parents[1]

GOALS = ([0.5, 0.0, -1.0], [0.5, 0.5, -1.3], [-0.4, 0.2, -0.8])
"""Three go-tos, NED [m]: along x, diagonal with a climb, back across with a descent."""


def _truth_at(truth: Any, t: float) -> np.ndarray:
    """The true position [m] at monotonic time ``t`` [s] (the sample before it)."""
    times = float(truth["start_monotonic"]) + truth["t"]
    k = int(np.searchsorted(times, t))
    return np.asarray(truth["position"][max(0, min(k, len(times)) - 1)])


@pytest.mark.realtime
@pytest.mark.slow
def test_a_flight_driven_only_by_the_client(tmp_path: Path) -> None:
    cfg = apply_overrides(load_config(REPO / "config" / "sim.yaml"), {
        "trajectory.name": "none", "vicon.port": free_udp_port(),
        "telemetry.endpoint": "tcp://127.0.0.1:*", "logging.flight_log_dir": str(tmp_path),
        "telemetry.control_endpoint": "tcp://127.0.0.1:*",
        "sim.truth_file": str(tmp_path / "truth.npz"), "api.idle_land_s": 30.0,
    })
    cfg_file = tmp_path / "lab.yaml"
    cfg_file.write_text(dump_config(cfg), encoding="utf-8")
    arrivals: list[tuple[list[float], float]] = []  # (goal, monotonic arrival time)
    with SimDeviceProcess(cfg_file, tmp_path / "truth.npz") as device:
        cfg = apply_overrides(cfg, {"serial.port": device.pty_path})
        abandon = threading.Event()  # a failed test stops the flight (the daemon lands)
        daemon = FlightDaemon(assemble(cfg), stop=abandon)
        out: dict[str, FlightSummary] = {}
        runner = threading.Thread(target=lambda: out.setdefault("s", daemon.run()))
        runner.start()
        follower: threading.Thread | None = None
        try:
            assert daemon.ready.wait(10.0)
            assert daemon.control_endpoint is not None and daemon.telemetry_endpoint
            gs = Client(daemon.control_endpoint, telemetry=daemon.telemetry_endpoint,
                        timeout_s=5.0)
            # a third client follows the supervisor's transitions over the telemetry
            seen: list[tuple[str, str]] = []
            follower = threading.Thread(target=lambda: seen.extend(gs.transitions(30.0)))
            follower.start()
            # before take-off: refused, the vehicle is not in the air yet
            with pytest.raises(NotNow, match="not airborne yet"):
                gs.go_to(GOALS[0])
            gs.takeoff(1.0, timeout=40.0)  # waits for TRACK, then to 1 m
            for goal in GOALS:
                motion = gs.go_to(goal, wait=True, timeout=30.0)
                assert motion.state == "arrived"
                arrivals.append((goal, time.monotonic()))
            # refusals, each with the daemon's reason
            with pytest.raises(OutsideVolume, match=r"safety\.volume_x"):
                gs.go_to([3.0, 0.0, -1.0])
            with pytest.raises(Infeasible, match="max_speed"):
                gs.go_to([0.5, 0.0, -1.0], duration=0.4)
            with pytest.raises(BadRequest, match="3 numbers"):
                gs.request({"request": "go_to", "position": [0.0, 0.0]})
            # two clients at once: one asks for the status in a tight loop while the other
            # commands; neither waits for the other's requests to fail
            other = Client(daemon.control_endpoint, timeout_s=5.0)
            states: list[str] = []
            stop = threading.Event()

            def watch() -> None:
                while not stop.is_set():
                    states.append(other.status().state)
            watcher = threading.Thread(target=watch)
            watcher.start()
            try:
                figure8 = gs.follow({"name": "figure-eight", "period_s": 8.0,
                                     "center": [0.0, 0.0, -1.0], "size_m": 0.75},
                                    wait=True, timeout=60.0)
            finally:
                stop.set()
                watcher.join(10.0)
            assert figure8.state == "arrived" and len(states) > 20
            assert set(states) == {"TRACK"}
            # a client killed in the middle of a motion: the motion goes on to its end and
            # the vehicle holds there; the daemon keeps answering
            killed = subprocess.Popen([sys.executable, "-c", textwrap.dedent(f"""
                import time
                from groundstation.client import Client
                Client({daemon.control_endpoint!r}).go_to([0.0, -0.5, -1.0], duration=4.0)
                print("sent", flush=True)
                time.sleep(60)
            """)], stdout=subprocess.PIPE, text=True, cwd=REPO)
            assert killed.stdout is not None and killed.stdout.readline().strip() == "sent"
            killed.kill()
            killed.wait(10.0)
            arrived = gs.wait_until_arrived(timeout=30.0)
            assert arrived.motion is not None and arrived.motion.state == "arrived"
            arrivals.append(([0.0, -0.5, -1.0], time.monotonic()))
            time.sleep(1.0)
            held = gs.status()
            assert held.state == "TRACK" and held.error_m is not None and held.error_m < 0.05
            latencies = [m.latency_s for m in _motions(gs) if m.latency_s is not None]
            final = gs.land(wait=True, timeout=60.0)
        except BaseException:
            abandon.set()
            raise
        finally:
            runner.join(60.0)
            if follower is not None:
                follower.join(10.0)
        time.sleep(0.3)  # the lab applies the final COMMAND
    summary = out["s"]
    assert final is not None and final.state == "DONE" and final.outcome == "COMPLETED"
    assert summary.outcome is Outcome.COMPLETED and summary.final_state is State.DONE
    assert seen == [("PREFLIGHT", "TAKEOFF"), ("TAKEOFF", "TRACK"), ("TRACK", "LAND"),
                    ("LAND", "DISARM"), ("DISARM", "DONE")]
    assert summary.reason.startswith("landed") and any(
        tr.reason == "land requested by a client" for tr in summary.transitions)
    # arrival judged from the ground truth: within 5 cm of each goal once the client
    # was told it arrived (the lab's clock is the same monotonic clock, offset by its start)
    truth = np.load(tmp_path / "truth.npz")
    for goal, t_arrived in arrivals:
        error = np.linalg.norm(_truth_at(truth, t_arrived) - goal)
        assert error < 0.06, (goal, error)
    # planned within api.plan_timeout_s or refused (the planner runs niced, so on a loaded
    # machine a plan waits for the CPU; bench_api.py measures the latency on a quiet one)
    assert latencies and max(latencies) < cfg.api.plan_timeout_s + 0.1


def _motions(gs: Client) -> list[Motion]:
    status = gs.status()
    return [status.motion] if status.motion is not None else []
