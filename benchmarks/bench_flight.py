"""Real-time flight benchmark: the daemon against the virtual lab in another process.

Measures, in real-time flights over a real pty and UDP against `gs sim-device` in a
child process:

* from the **vehicle's side** (as an independent lab measures it): for each
  COMMAND, the time from the last byte of the DATA frame before it leaving the virtual
  vehicle to the COMMAND arriving (latency p50/p99), and the COMMAND gaps the
  vehicle's 100 ms watchdog sees (the time after each COMMAND with a non-zero mask
  until the next one): its longest, and how many exceed 50 ms. The virtual lab's
  real-time runner stamps both instants (``sim_device/wire.py``);
* from the daemon's side: tick compute time p50/p99 (DATA sample in hand ->
  COMMAND written), schedule jitter p99 (tick start minus the DATA frame's receive
  time), DATA-to-COMMAND latency p50/p99, the COMMAND rate sustained, the garbage
  collector's pauses, and the resident set size over the flight (flat = no growth
  beyond a few MB; peak reported).

    .venv/bin/python benchmarks/bench_flight.py                       # 60 s on the square
    .venv/bin/python benchmarks/bench_flight.py --flights 30 --seconds 20
    .venv/bin/python benchmarks/bench_flight.py --flights 30 --seconds 20 --load 2
    .venv/bin/python benchmarks/bench_flight.py --minutes 30          # the memory soak
    .venv/bin/python benchmarks/bench_flight.py --command-rate 100
    .venv/bin/python benchmarks/bench_flight.py --cpu-latency-us none # idle states allowed

``--load N`` starts N busy processes (a pure-Python spin each) competing for the cores
for the whole run.

Targets: vehicle-side latency p50 <= 2 ms and p99 <= 3 ms on a quiet machine, no
COMMAND gap over 50 ms in 30 consecutive flights, also under ``--load 2``; jitter p99
<= 1 ms, daemon-side latency p99 <= 2 ms, commands at the configured rate, RSS growth
<= a few MB over 30 minutes. Compute (DATA in hand to COMMAND written) is printed but has
no target of its own: the old 200 us is retired, because on the 57600-baud link the
latency the vehicle sees, of which compute is a part, is the binding constraint.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from groundstation.app.daemon import FlightDaemon, FlightSummary  # noqa: E402
from groundstation.config import (  # noqa: E402
    GroundStationConfig,
    apply_overrides,
    dump_config,
    load_config,
)
from groundstation.endpoints import free_udp_port  # noqa: E402
from groundstation.flight.assembly import assemble  # noqa: E402
from sim_device.realtime import SimDeviceProcess  # noqa: E402
from sim_device.wire import WireRecord  # noqa: E402

GAP_LIMIT_S = 0.05
"""COMMAND gaps longer than this count against the target (half the 100 ms watchdog)."""


def rss_mb() -> float:
    """Resident set size of this process [MB] from /proc."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024.0
    return float("nan")


@dataclass
class Flight:
    """One benchmark flight: the daemon's summary and what the vehicle saw."""

    summary: FlightSummary
    wire: WireRecord
    cpu_s: float

    @property
    def span(self) -> tuple[float, float]:
        return self.wire.commanding_span()

    def latencies(self) -> np.ndarray:
        """Vehicle-side DATA -> COMMAND latency of every COMMAND while flying [s]."""
        return self.wire.latencies(*self.span)

    def gaps(self) -> np.ndarray:
        """Vehicle-side COMMAND gaps after every flying COMMAND [s]."""
        return self.wire.command_gaps(*self.span)


def fly_once(base: GroundStationConfig, tmp: Path, k: int, seconds: float,
             samples: list[tuple[float, float]] | None) -> Flight:
    """One flight against a fresh `gs sim-device` (fresh battery, vehicle on the floor)."""
    cfg = apply_overrides(base, {"vicon.port": free_udp_port(),
                                 "sim.truth_file": str(tmp / f"truth-{k}.npz")})
    cfg_file = tmp / f"bench-{k}.yaml"
    cfg_file.write_text(dump_config(cfg))
    done = threading.Event()

    def sample_rss() -> None:
        t0 = time.monotonic()
        while samples is not None and not done.wait(5.0):
            samples.append((time.monotonic() - t0, rss_mb()))

    with SimDeviceProcess(cfg_file, tmp / f"truth-{k}.npz") as vehicle:
        cfg = apply_overrides(cfg, {"serial.port": vehicle.pty_path})
        sampler = threading.Thread(target=sample_rss, daemon=True)
        sampler.start()
        cpu0 = time.process_time()
        try:
            summary = FlightDaemon(assemble(cfg), duration_s=seconds).run()
        finally:
            done.set()
        cpu = time.process_time() - cpu0
    assert vehicle.wire is not None, vehicle.output
    return Flight(summary, vehicle.wire, cpu)


CANARY = """
import os, sys, time
# Sleeps 1 ms at a time and prints every wake-up later than the threshold: the stalls of
# the whole machine (a vCPU descheduled by the hypervisor, memory reclaim), as opposed to
# those of the ground-station process. Real-time (FIFO 30, above the daemon and the
# virtual vehicle) when permitted, so the --load spinners cannot delay it.
threshold = float(sys.argv[1])
try:
    os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(30))
    print("fifo", flush=True)
except OSError:
    print("normal", flush=True)
while True:
    t0 = time.monotonic()
    time.sleep(0.001)
    late = time.monotonic() - t0 - 0.001
    if late > threshold:
        print(f"{t0:.6f} {late:.6f}", flush=True)
"""
"""A process whose own wake-ups show when the machine, not the daemon, stalled."""

CANARY_THRESHOLD_S = 0.02
"""A canary wake-up this late [s] is a stall of the machine."""


class Canary:
    """The :data:`CANARY` process and the stalls it reported (start [monotonic s], length [s])."""

    def __init__(self) -> None:
        self.stalls: list[tuple[float, float]] = []
        self.policy = "?"
        """'fifo' if the canary runs real-time (its stalls are the machine's), else 'normal'."""
        self._proc = subprocess.Popen([sys.executable, "-c", CANARY, str(CANARY_THRESHOLD_S)],
                                      stdout=subprocess.PIPE, text=True)
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        assert self._proc.stdout is not None
        self.policy = self._proc.stdout.readline().strip()
        for line in self._proc.stdout:
            t0, late = (float(v) for v in line.split())
            self.stalls.append((t0, late))

    def stop(self) -> None:
        self._proc.kill()
        self._proc.wait()
        self._reader.join(timeout=1.0)

    def overlaps(self, start: float, end: float) -> bool:
        """Whether the canary was stalled at some time within [start, end] [monotonic s]."""
        return any(t0 < end and t0 + 0.001 + late > start for t0, late in self.stalls)


def steal_s() -> float:
    """CPU time the hypervisor gave to others while this VM wanted it, all CPUs [s]."""
    fields = Path("/proc/stat").read_text().splitlines()[0].split()
    return int(fields[8]) / os.sysconf("SC_CLK_TCK") if len(fields) > 8 else float("nan")


def start_load(n: int) -> list[subprocess.Popen[bytes]]:
    """N busy processes spinning in pure Python (one core each, if they get it)."""
    return [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(n)]


def ms(values: np.ndarray, q: float) -> str:
    return f"{1e3 * float(np.percentile(values, q)):6.2f}" if len(values) else "   nan"


def report_one(flight: Flight, args: argparse.Namespace, samples: list[tuple[float, float]],
               command_rate: float, data_period_ms: int) -> None:
    """The single-flight report: the vehicle's figures and the daemon's."""
    summary = flight.summary
    p = summary.percentiles()
    print(f"flight: {summary.final_state.name} ({summary.outcome.name}), {summary.ticks} ticks "
          f"in {summary.duration_s:.1f} s ({summary.ticks / summary.duration_s:.1f} Hz), "
          f"{len(summary.transitions)} transitions, "
          f"command rate {command_rate:g} Hz configured")
    print(f"commands sent: {summary.commands_sent} "
          f"({summary.commands_sent / summary.duration_s:.1f}/s over the whole run), "
          f"keep-alive resends {summary.keepalive_resends}")
    print(f"compute  p50 {p['compute'][0] * 1e6:7.0f} us   p99 {p['compute'][1] * 1e6:7.0f} us"
          f"   max {summary.compute.max * 1e6:7.0f} us   (part of the latency below)")
    print(f"jitter   p50 {p['jitter'][0] * 1e3:7.3f} ms   p99 {p['jitter'][1] * 1e3:7.3f} ms"
          f"   max {summary.jitter.max * 1e3:7.3f} ms   (target p99 <= 1 ms)")
    print(f"latency  p50 {p['latency'][0] * 1e3:7.3f} ms   p99 {p['latency'][1] * 1e3:7.3f} ms"
          f"   max {summary.latency.max * 1e3:7.3f} ms   (daemon side; target p99 <= 2 ms)")
    di = summary.data_interval
    print(f"DATA interval p1 {di.percentile(1) * 1e3:6.2f} ms  p50 {di.percentile(50) * 1e3:6.2f} "
          f"ms  p99 {di.percentile(99) * 1e3:6.2f} ms  (the vehicle side; nominal "
          f"{data_period_ms} ms)")
    print(f"tracking RMS {summary.track_rms_m * 100:.1f} cm (estimate vs reference)")
    print(f"process CPU {flight.cpu_s / summary.duration_s * 100:.0f} % of one core")
    if samples:
        mbs = [mb for _, mb in samples]
        settled = [mb for t, mb in samples if t > 30.0] or mbs
        print(f"RSS start {mbs[0]:.1f} MB, peak {max(mbs):.1f} MB, end {mbs[-1]:.1f} MB, "
              f"growth after the first 30 s {settled[-1] - settled[0]:+.1f} MB "
              f"over {samples[-1][0] / 60:.1f} min")


def long_gaps(flight: Flight) -> list[tuple[float, float]]:
    """The flight's vehicle-side COMMAND gaps over :data:`GAP_LIMIT_S`: (start [monotonic
    s], length [s])."""
    first, last = flight.span
    t, mask = flight.wire.command_in, flight.wire.command_mask
    gaps = np.diff(t)
    long = (mask[:-1] != 0) & (t[:-1] >= first) & (t[:-1] <= last) & (gaps > GAP_LIMIT_S)
    return [(float(t0), float(g)) for t0, g in zip(t[:-1][long], gaps[long], strict=True)]


def vehicle_stalled(flight: Flight, start: float, end: float, period: float) -> bool:
    """Whether the virtual vehicle's own DATA stream had a hole of over 2.5 DATA periods
    overlapping [start, end] [monotonic s]: the vehicle process did not run then (it runs
    under the real-time policy above the daemon, so the daemon cannot have held it off),
    and a COMMAND gap it measured is the machine's stall, not the ground station's."""
    out = flight.wire.data_out
    holes = np.flatnonzero(np.diff(out) > 2.5 * period)
    return any(out[k] < end and out[k + 1] > start for k in holes)


def report_wire(flights: list[Flight], load: int, canary: Canary,
                data_period_s: float = 0.01) -> bool:
    """The vehicle-side figures over every flight; True if the targets are met."""
    lat = np.concatenate([f.latencies() for f in flights])
    gaps = np.concatenate([f.gaps() for f in flights])
    over = int(np.sum(gaps > GAP_LIMIT_S))
    long = [(f, t, g) for f in flights for t, g in long_gaps(f)]
    machine = sum(canary.overlaps(t, t + g) for _, t, g in long)
    stalled = sum(vehicle_stalled(f, t, t + g, data_period_s) for f, t, g in long)
    gc_full = max(f.summary.collector.longest_full_s for f in flights)
    gc_young = max(f.summary.collector.longest_young_s for f in flights)
    outcomes = {o: sum(f.summary.outcome.name == o for f in flights)
                for o in sorted({f.summary.outcome.name for f in flights})}
    print(f"vehicle side, {len(flights)} flight(s), load {load}: {len(lat)} COMMANDs in the air")
    print(f"  DATA -> COMMAND latency  p50 {ms(lat, 50)} ms  p90 {ms(lat, 90)} ms  "
          f"p99 {ms(lat, 99)} ms  p99.9 {ms(lat, 99.9)} ms  max {ms(lat, 100)} ms  "
          f"(target p50 <= 2, p99 <= 3 ms quiet)")
    print(f"  COMMAND gap  p50 {ms(gaps, 50)} ms  p99 {ms(gaps, 99)} ms  max {ms(gaps, 100)} ms; "
          f"over {1e3 * GAP_LIMIT_S:.0f} ms: {over} (target 0); watchdog expiries "
          f"(> 100 ms): {int(np.sum(gaps > 0.1))}")
    if long:
        print(f"  gaps over {1e3 * GAP_LIMIT_S:.0f} ms: "
              + ", ".join(f"{1e3 * g:.0f} ms" for _, _, g in long)
              + f"; {stalled} while the virtual vehicle's own DATA stream stopped too (the "
              f"vehicle process did not run: the machine stalled), {machine} while the "
              f"canary process was stalled")
    print(f"  the canary process ({canary.policy} policy) woke up over "
          f"{1e3 * CANARY_THRESHOLD_S:.0f} ms late "
          f"{len(canary.stalls)} times, longest "
          f"{1e3 * max((late for _, late in canary.stalls), default=0.0):.0f} ms")
    print(f"  outcomes {outcomes}; keep-alive resends "
          f"{sum(f.summary.keepalive_resends for f in flights)}; longest collector pause: "
          f"full {1e3 * gc_full:.2f} ms, young {1e3 * gc_young:.2f} ms")
    if len(flights) > 1:
        worst = max(flights, key=lambda f: float(np.max(f.gaps(), initial=0.0)))
        print(f"  worst flight: gap {1e3 * float(np.max(worst.gaps(), initial=0.0)):.1f} ms, "
              f"latency p99 {ms(worst.latencies(), 99)} ms, log {worst.summary.log_dir}")
    quiet_ok = load > 0 or (np.percentile(lat, 50) <= 0.002 and np.percentile(lat, 99) <= 0.003)
    return bool(over == 0 and quiet_ok)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seconds", type=float, default=60.0, help="time on the trajectory")
    parser.add_argument("--minutes", type=float, default=None, help="overrides --seconds")
    parser.add_argument("--flights", type=int, default=1, help="consecutive flights")
    parser.add_argument("--load", type=int, default=0,
                        help="busy processes competing for the cores during the run")
    parser.add_argument("--command-rate", type=float, default=50.0)
    parser.add_argument("--controller", default="lqr-ff")
    parser.add_argument("--cpu-latency-us", default="0",
                        help="realtime.cpu_dma_latency_us while flying; 'none' makes no request")
    args = parser.parse_args()
    seconds = args.minutes * 60.0 if args.minutes else args.seconds
    tmp = Path(tempfile.mkdtemp(prefix="bench_flight_"))
    base = apply_overrides(load_config(REPO / "config" / "sim.yaml"), {
        "trajectory.name": "square",
        "controller.type": args.controller, "serial.command_rate_hz": args.command_rate,
        "telemetry.endpoint": "tcp://127.0.0.1:*", "logging.flight_log_dir": str(tmp),
        "telemetry.control_endpoint": "tcp://127.0.0.1:*",
        "logging.level": "warning",
        # the virtual vehicle stands for hardware, which the PC's load cannot stall:
        # real-time above the daemon, so --load delays only the ground station
        "sim.fifo_priority": 20,
        "realtime.cpu_dma_latency_us":
            None if args.cpu_latency_us == "none" else int(args.cpu_latency_us),
    })
    load = start_load(args.load)
    canary = Canary()
    steal0 = steal_s()
    flights: list[Flight] = []
    samples: list[tuple[float, float]] = []
    load0 = os.getloadavg()[0]
    try:
        for k in range(args.flights):
            flight = fly_once(base, tmp, k, seconds, samples if args.flights == 1 else None)
            flights.append(flight)
            if args.flights > 1:
                gaps, lat = flight.gaps(), flight.latencies()
                print(f"flight {k + 1:2d}: {flight.summary.outcome.name:<9} latency p50/p99 "
                      f"{ms(lat, 50)}/{ms(lat, 99)} ms, longest gap "
                      f"{1e3 * float(np.max(gaps, initial=0.0)):5.1f} ms, load average "
                      f"{os.getloadavg()[0]:.2f}", flush=True)
    finally:
        canary.stop()
        for proc in load:
            proc.kill()
            proc.wait()
    if args.flights == 1:
        report_one(flights[0], args, samples, args.command_rate, base.serial.data_period_ms)
    met = report_wire(flights, args.load, canary, base.serial.data_period_ms / 1000.0)
    print(f"load average at the start {load0:.2f}, at the end {os.getloadavg()[0]:.2f}; "
          f"CPU time stolen by the hypervisor {steal_s() - steal0:.2f} s; flight logs in {tmp}")
    return 0 if met and all(f.summary.success for f in flights) else 1


if __name__ == "__main__":
    raise SystemExit(main())
