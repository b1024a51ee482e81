"""The run-time API in real time: command-to-motion latency and go-to arrival error.

Starts the virtual vehicle (``gs sim-device``) and the daemon (``gs fly --trajectory
none``) as the lab would run them, each in its own process, and drives the flight from
this process with :class:`groundstation.client.Client`: a take-off, then ``--moves``
go-tos around the volume (a new point, height and heading each time, waiting for each
to arrive), then a landing. Prints:

* command-to-motion latency: the daemon's request received to its reference starting to
  move (``Motion.latency_s``: the planning lead, the planning and the tick), p50/p99;
* the client's round trip of a go-to request (sent to reply), p50/p99;
* the arrival error: the true position (the lab's truth file) against the target when
  the daemon reports the motion arrived, and 1 s later, mean and max.

    .venv/bin/python benchmarks/bench_api.py            # 16 moves
    .venv/bin/python benchmarks/bench_api.py --moves 40
"""

from __future__ import annotations

import argparse
import math
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from groundstation.client import Client  # noqa: E402
from groundstation.config import apply_overrides, dump_config, load_config  # noqa: E402
from sim_device.realtime import SimDeviceProcess  # noqa: E402

POINTS = ([0.5, 0.0, -1.0], [0.5, 0.5, -1.3], [-0.4, 0.4, -0.8], [-0.6, -0.5, -1.2],
          [0.0, -0.6, -1.5], [0.7, -0.3, -0.9], [0.0, 0.0, -1.0], [-0.3, 0.6, -1.1])
"""Go-to targets, NED [m], visited in turn."""


def _free_port(kind: int) -> int:
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _pct(values: list[float], q: float) -> float:
    return float(np.percentile(values, q)) if values else math.nan


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--moves", type=int, default=16, help="go-tos to fly (default 16)")
    args = parser.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="bench-api-"))
    control = f"tcp://127.0.0.1:{_free_port(socket.SOCK_STREAM)}"
    telemetry = f"tcp://127.0.0.1:{_free_port(socket.SOCK_STREAM)}"
    cfg = apply_overrides(load_config(ROOT / "config" / "sim.yaml"), {
        "vicon.port": _free_port(socket.SOCK_DGRAM), "telemetry.endpoint": telemetry,
        "telemetry.control_endpoint": control, "logging.flight_log_dir": str(tmp / "logs"),
        "sim.truth_file": str(tmp / "truth.npz"), "trajectory.name": "none"})
    lab_file = tmp / "lab.yaml"
    lab_file.write_text(dump_config(cfg), encoding="utf-8")
    latencies, round_trips, arrivals = [], [], []
    with SimDeviceProcess(lab_file, tmp / "truth.npz") as device:
        fly_file = tmp / "fly.yaml"
        fly_file.write_text(dump_config(apply_overrides(cfg, {"serial.port": device.pty_path})),
                            encoding="utf-8")
        daemon = subprocess.Popen(
            [sys.executable, "-m", "groundstation", "fly", "--config", str(fly_file)],
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=ROOT)
        try:
            gs = Client(control, telemetry=telemetry, timeout_s=5.0)
            deadline = time.monotonic() + 20.0
            while True:  # the daemon is up once it answers
                try:
                    gs.status()
                    break
                except Exception:
                    if time.monotonic() > deadline:
                        raise
                    time.sleep(0.2)
            gs.takeoff(1.0, timeout=60.0)
            for k in range(args.moves):
                target = POINTS[k % len(POINTS)]
                yaw = (k * 70) % 360 - 180  # degrees from north
                sent = time.monotonic()
                motion = gs.go_to(target, yaw_deg=yaw)
                round_trips.append(time.monotonic() - sent)
                done = gs.wait_until_arrived(motion, timeout=30.0).motion
                assert done is not None and done.arrived_at is not None
                latencies.append(done.latency_s or math.nan)
                arrivals.append((target, done.arrived_at))
                time.sleep(1.2)  # the settled error is read 1 s after the arrival
            ended = gs.land(wait=True, timeout=60.0)
        finally:
            try:
                daemon.wait(30.0)
            except subprocess.TimeoutExpired:
                daemon.kill()
    truth = np.load(tmp / "truth.npz")
    times = float(truth["start_monotonic"]) + truth["t"]

    def error_at(target: list[float], t: float) -> float:
        k = min(int(np.searchsorted(times, t)), len(times) - 1)
        return float(np.linalg.norm(truth["position"][k] - target))

    at_arrival = [error_at(p, t) for p, t in arrivals]
    settled = [error_at(p, t + 1.0) for p, t in arrivals]
    print(f"run-time API, {len(arrivals)} go-tos in the virtual lab (daemon exit "
          f"{daemon.returncode}, {ended.state if ended else '?'})")
    print(f"  command-to-motion latency  p50 {1e3 * _pct(latencies, 50):6.1f} ms   "
          f"p99 {1e3 * _pct(latencies, 99):6.1f} ms   (request received -> reference moves)")
    print(f"  go_to round trip (client)  p50 {1e3 * _pct(round_trips, 50):6.1f} ms   "
          f"p99 {1e3 * _pct(round_trips, 99):6.1f} ms")
    print(f"  arrival error (truth)      mean {1e2 * np.mean(at_arrival):5.2f} cm   max "
          f"{1e2 * np.max(at_arrival):5.2f} cm   at the reported arrival")
    print(f"                             mean {1e2 * np.mean(settled):5.2f} cm   max "
          f"{1e2 * np.max(settled):5.2f} cm   1 s later")


if __name__ == "__main__":
    main()
