"""Fleet benchmark: Vicon relay-to-fuse latency, and how many virtual vehicles this
machine flies at 100 Hz.

Every part is a process of its own on loopback, as in ``gs fleet demo``: the virtual lab
(``gs sim-device --fleet``: N virtual X-3Ds, one Tracker stream), ``gs vicon-relay``, one
``gs fleet fly`` daemon per vehicle, and this process as the Fleet client.

1. **Relay to fuse.** Each daemon's fleet node times every Vicon pose from its receive
   stamp to the tick that hands it to the estimator ("fused"); through the relay the stamp
   is the relay's (the same machine: the same monotonic clock), so this is relay receive ->
   daemon fuses, and the pose source also times relay receive -> daemon receives (the
   Zenoh hop alone). A single vehicle reading Tracker's UDP itself (``relay: null``) gives
   the same figure without the relay: the difference is what the relay adds. Most of
   either is the wait for the next DATA tick (up to 10 ms at 100 Hz).
2. **Capacity at 100 Hz.** N vehicles hover through the relay with
   ``serial.command_rate_hz: 100`` for ``--seconds``; each daemon's DATA-to-COMMAND
   latency p99 (its own summary) and the vehicle's (the virtual lab's wire stamps), and
   the CPU each process used while hovering (from /proc). N grows until a vehicle's
   daemon-side p99 passes 5 ms or a flight does not end as it should.

    flock /tmp/realtime.lock .venv/bin/python benchmarks/bench_fleet.py
    flock /tmp/realtime.lock .venv/bin/python benchmarks/bench_fleet.py --vehicles 1-8 --seconds 20

Targets: DATA-to-COMMAND p99 <= 5 ms at 100 Hz for every vehicle flown.
"""

from __future__ import annotations

import argparse
import math
import os
import re
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from groundstation.client import Fleet  # noqa: E402
from groundstation.config import apply_overrides, load_config  # noqa: E402
from groundstation.fleetops.virtual import VirtualFleet, write_fleet  # noqa: E402
from sim_device.wire import WireRecord  # noqa: E402

TARGET_P99_S = 0.005
SUMMARY = re.compile(r"^\[(?P<name>v\d+)\].*DATA->COMMAND latency p50/p99 "
                     r"(?P<p50>[\d.]+)/(?P<p99>[\d.]+) ms")
TICK = os.sysconf("SC_CLK_TCK")


def cpu_seconds(pid: int) -> float:
    """User + system CPU time of process ``pid`` so far [s] (NaN if it is gone)."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return math.nan
    return (int(fields[11]) + int(fields[12])) / TICK


def grid(n: int, spacing: float = 1.0) -> list[tuple[float, float]]:
    """N homes on a square grid ``spacing`` apart, centred on the origin."""
    side = math.ceil(math.sqrt(n))
    cells = [((i - (side - 1) / 2) * spacing, (j - (side - 1) / 2) * spacing)
             for i in range(side) for j in range(side)]
    return cells[:n]


@dataclass
class Run:
    """One fleet flight's figures."""

    n: int
    codes: dict[str, int] = field(default_factory=dict)
    daemon_p99: dict[str, float] = field(default_factory=dict)
    vehicle_p99: dict[str, float] = field(default_factory=dict)
    health: dict[str, dict[str, Any]] = field(default_factory=dict)
    cpu: dict[str, float] = field(default_factory=dict)
    """Cores used while hovering, by process (v1.., relay, lab)."""
    load: float = math.nan


def fly(n: int, seconds: float, command_rate: float, relay: bool, workdir: Path) -> Run:
    """N vehicles take off, hover ``seconds``, land; the figures of :class:`Run`."""
    base = apply_overrides(load_config(REPO / "config" / "sim.yaml"), {
        "serial.command_rate_hz": command_rate,
        "safety.volume_x": [-3.0, 3.0], "safety.volume_y": [-3.0, 3.0],
        "sim.vicon.volume_x": [-3.5, 3.5], "sim.vicon.volume_y": [-3.5, 3.5]})
    fleet_file = write_fleet(workdir, base, grid(n), separation_m=0.5,
                             extra=None if relay else {"relay": None})
    lines: list[str] = []
    run = Run(n)
    with VirtualFleet(fleet_file, echo=lines.append, relay=relay) as vf:
        assert vf.processes is not None and vf._lab is not None
        pids = {c.name: c.process.pid for c in vf.processes.daemons if c.process is not None}
        if vf.processes.relay is not None and vf.processes.relay.process is not None:
            pids["relay"] = vf.processes.relay.process.pid
        pids["lab"] = vf._lab.pid
        with Fleet(vf.run_file) as fleet, fleet.telemetry("*", ["health"]) as health:
            fleet.wait_for_state("TRACK", timeout=240.0)
            before = {k: cpu_seconds(p) for k, p in pids.items()}
            t0 = time.monotonic()
            time.sleep(seconds)
            wall = time.monotonic() - t0
            run.cpu = {k: (cpu_seconds(p) - before[k]) / wall for k, p in pids.items()}
            run.load = os.getloadavg()[0]
            fleet.land(wait=True, timeout=60.0)
            while (message := health.receive(timeout=0.5)) is not None:
                if message[0] in fleet.names:  # not the relay's own health
                    run.health[message[0]] = message[2].get("fleet", {})
        run.codes = vf.wait()
    for line in lines:
        if (m := SUMMARY.match(line)) is not None:
            run.daemon_p99[m["name"]] = float(m["p99"]) / 1e3
    for name, truth in vf.truth_files.items():
        latencies = WireRecord.load(truth).latencies()
        if len(latencies):
            run.vehicle_p99[name] = float(np.percentile(latencies, 99))
    return run


def ms(seconds: float) -> str:
    return f"{1e3 * seconds:.2f}"


def latency_part(seconds: float) -> None:
    print("== relay to fuse (loopback), 100 Hz Vicon, 50 Hz commands")
    with tempfile.TemporaryDirectory(prefix="bench-fleet-") as tmp:
        direct = fly(1, seconds, 50.0, relay=False, workdir=Path(tmp) / "udp")
        relayed = fly(3, seconds, 50.0, relay=True, workdir=Path(tmp) / "relay")
    d = direct.health.get("v1", {})
    print(f"UDP, the daemon reading Tracker itself: receive -> fused p50/p99 "
          f"{ms(d.get('fuse_p50_s', math.nan))}/{ms(d.get('fuse_p99_s', math.nan))} ms "
          f"({d.get('fused')} poses; exit {direct.codes})")
    for name, h in sorted(relayed.health.items()):
        print(f"relay, {name}: relay receive -> daemon receives p50/p99 "
              f"{ms(h.get('relay_hop_p50_s', math.nan))}/{ms(h.get('relay_hop_p99_s', math.nan))}"
              f" ms; relay receive -> fused p50/p99 {ms(h.get('fuse_p50_s', math.nan))}/"
              f"{ms(h.get('fuse_p99_s', math.nan))} ms ({h.get('fused')} poses)")
    print(f"exit codes: {relayed.codes}")


def capacity_part(counts: list[int], seconds: float, command_rate: float) -> None:
    print(f"== capacity: vehicles hovering through the relay, {command_rate:g} Hz commands, "
          f"{seconds:g} s each, target DATA->COMMAND p99 <= {ms(TARGET_P99_S)} ms")
    for n in counts:
        with tempfile.TemporaryDirectory(prefix="bench-fleet-") as tmp:
            run = fly(n, seconds, command_rate, relay=True, workdir=Path(tmp))
        worst = max(run.daemon_p99.values(), default=math.inf)
        vehicle = max(run.vehicle_p99.values(), default=math.inf)
        daemons = [v for k, v in run.cpu.items() if k.startswith("v")]
        ok = (worst <= TARGET_P99_S and len(run.daemon_p99) == n
              and all(c == 0 for c in run.codes.values()))
        print(f"N={n}: daemon-side p99 worst {ms(worst)} ms (each: "
              f"{', '.join(ms(run.daemon_p99.get(f'v{k + 1}', math.nan)) for k in range(n))}); "
              f"vehicle-side p99 worst {ms(vehicle)} ms; cores: daemons "
              f"{sum(daemons):.2f} ({np.mean(daemons):.3f} each), relay "
              f"{run.cpu.get('relay', math.nan):.3f}, lab {run.cpu.get('lab', math.nan):.3f}; "
              f"load {run.load:.1f}; exits {sorted(set(run.codes.values()))} -> "
              + ("held" if ok else "NOT held"))
        if not ok:
            break


def parse_counts(text: str) -> list[int]:
    if "-" in text:
        lo, hi = (int(v) for v in text.split("-"))
        return list(range(lo, hi + 1))
    return [int(v) for v in text.split(",")]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--vehicles", default="1-6", help="the fleet sizes (1-6 or 1,3,5)")
    parser.add_argument("--seconds", type=float, default=15.0, help="hover per flight [s]")
    parser.add_argument("--command-rate", type=float, default=100.0)
    parser.add_argument("--skip-latency", action="store_true")
    parser.add_argument("--skip-capacity", action="store_true")
    args = parser.parse_args()
    if not args.skip_latency:
        latency_part(args.seconds)
    if not args.skip_capacity:
        capacity_part(parse_counts(args.vehicles), args.seconds, args.command_rate)


if __name__ == "__main__":
    main()
