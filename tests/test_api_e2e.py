"""The run-time API end to end, through the real processes, as a researcher uses it.

The virtual vehicle (``gs sim-device``), the daemon (``gs fly --trajectory none``), the
command line (``gs status``, ``gs goto``, ``gs hold``) and ``examples/fly_square.py`` each
run in a process of their own, talking over a pty, UDP and ZeroMQ on loopback. The
vehicle's visits to the square's corners are judged from the virtual lab's ground truth.
"""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from lab_helpers import free_udp_port

from groundstation.client import Client, DaemonUnreachableError
from groundstation.config import apply_overrides, dump_config, load_config
from sim_device.realtime import SimDeviceProcess

REPO = Path(__file__).resolve().parents[1]
GS = Path(sys.executable).parent / "gs"
EXAMPLE = REPO / "examples" / "fly_square.py"
CORNERS = np.array([[0.375, 0.375, -1.0], [0.375, -0.375, -1.0],
                    [-0.375, -0.375, -1.0], [-0.375, 0.375, -1.0]])
"""The square fly_square.py flies: 0.75 m side, centred on (0, 0), 1 m up (NED [m])."""


def free_tcp_ports(count: int) -> list[int]:
    """``count`` different TCP ports nothing on loopback listens on now (the daemon, another
    process, binds them a moment later: ``*`` ports could not be read back from here)."""
    sockets = [socket.socket(socket.AF_INET, socket.SOCK_STREAM) for _ in range(count)]
    try:
        for s in sockets:  # all held at once: no port is handed out twice
            s.bind(("127.0.0.1", 0))
        return [int(s.getsockname()[1]) for s in sockets]
    finally:
        for s in sockets:
            s.close()


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


def _stop(child: subprocess.Popen[bytes] | None, grace_s: float) -> None:
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


@pytest.mark.realtime
@pytest.mark.slow
@pytest.mark.timeout(240)  # about 50 s on an idle 2-core machine; each process start is
# seconds of imports, several times that on a loaded one
def test_the_example_and_the_cli_fly_a_real_daemon(tmp_path: Path) -> None:
    control, telemetry = (f"tcp://127.0.0.1:{port}" for port in free_tcp_ports(2))
    truth_file = tmp_path / "truth.npz"
    cfg = apply_overrides(load_config(REPO / "config" / "sim.yaml"), {
        "vicon.port": free_udp_port(), "telemetry.endpoint": telemetry,
        "telemetry.control_endpoint": control, "logging.flight_log_dir": str(tmp_path),
        "sim.truth_file": str(truth_file),
        # each `gs` command takes seconds to start on a loaded machine: the idle landing
        # must not come between them (and a test that stalls still ends with a landing)
        "api.idle_land_s": 90.0,
    })
    cfg_file = tmp_path / "lab.yaml"
    cfg_file.write_text(dump_config(cfg), encoding="utf-8")
    daemon_out, example_out = tmp_path / "fly.out", tmp_path / "example.out"
    daemon: subprocess.Popen[bytes] | None = None
    example: subprocess.Popen[bytes] | None = None
    # the vehicle's own bound: it stops even if this process dies without stopping it
    with SimDeviceProcess(cfg_file, truth_file, duration=180.0,
                          stderr=tmp_path / "sim.err") as device:
        try:
            with daemon_out.open("wb") as out:
                daemon = subprocess.Popen(
                    [str(GS), "fly", "--config", str(cfg_file), "--trajectory", "none",
                     "--serial-port", device.pty_path], cwd=REPO, stdout=out,
                    stderr=subprocess.STDOUT, env=_without_systemd())
            _wait_for_track(control, daemon, daemon_out)

            # the command line, while the vehicle holds at the take-off height; the two that
            # change nothing run at once (each `gs` takes seconds to start when loaded)
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

            # the example: four corners, then it lands and reports how the flight ended
            with example_out.open("wb") as out:
                example = subprocess.Popen(
                    [sys.executable, str(EXAMPLE), "--endpoint", control,
                     "--telemetry", telemetry], cwd=REPO, stdout=out,
                    stderr=subprocess.STDOUT)
            code = example.wait(90.0)
            printed = example_out.read_text(encoding="utf-8")
            assert code == 0, printed + "\n--- daemon:\n" + _tail(daemon_out)
            corners = [line for line in printed.splitlines()
                       if line.startswith("corner") and "arrived" in line]
            assert len(corners) == 4, printed
            assert "flight ended in DONE (COMPLETED)" in printed, printed
            # the daemon ends on its own once landed and handed back: COMPLETED, exit 0
            assert daemon.wait(30.0) == 0, _tail(daemon_out)
        finally:
            _stop(example, 5.0)
            _stop(daemon, 20.0)
    assert "land requested by a client" in daemon_out.read_text(encoding="utf-8")

    # judged from the ground truth: the true path passed within 5 cm of every corner, and
    # the vehicle ended on the floor
    truth = np.load(truth_file)
    path = np.asarray(truth["position"])
    for corner in CORNERS:
        closest = float(np.min(np.linalg.norm(path - corner, axis=1)))
        assert closest < 0.05, (corner, closest)
    assert bool(truth["on_ground"][-1]) and abs(path[-1, 2] - path[0, 2]) < 0.03, path[-1]


def _wait_for_track(control: str, daemon: subprocess.Popen[bytes], output: Path) -> None:
    """Block until the daemon answers and has taken off (TRACK); fail with its output if
    it exits or does not get there within a minute (generous: a loaded 2-core machine)."""
    client = Client(control, timeout_s=2.0)
    deadline = time.monotonic() + 60.0
    while time.monotonic() < deadline:
        assert daemon.poll() is None, f"gs fly exited {daemon.returncode}:\n{_tail(output)}"
        try:
            if client.status().state == "TRACK":
                return
        except DaemonUnreachableError:
            pass  # not bound yet
        time.sleep(0.2)
    pytest.fail(f"not in TRACK within 60 s:\n{_tail(output)}")
