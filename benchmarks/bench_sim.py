"""Virtual-lab benchmarks (prints numbers; not a test).

1. In-process real-time factor: simulated seconds per wall second of
   ``VirtualLab`` flying a hover with everything on (2 ms plant steps, DATA at
   100 Hz with STATUS+GYRO+ACC+RC, COMMAND bytes at 50 Hz, Vicon at 100 Hz with
   noise, truth log). Target >= 20x on one core.
2. Real-time CPU share: ``run_sim_device`` for ~10 s with a pyserial client in a
   separate process streaming CONFIG/COMMAND and reading DATA; CPU share =
   ``time.process_time`` / wall time of the device process. Target < 25 %.

Run: ``.venv/bin/python benchmarks/bench_sim.py [--seconds 60] [--realtime 10]``
"""

from __future__ import annotations

import argparse
import cProfile
import pstats
import subprocess
import sys
import threading
import time
from pathlib import Path

from groundstation.asctec.decoder import encode_frame
from groundstation.asctec.messages import CommandMsg, ConfigMsg
from groundstation.config import apply_overrides, load_config
from groundstation.types import Sticks
from sim_device import SimDeviceInfo, VirtualLab, run_sim_device

REPO = Path(__file__).resolve().parents[1]
HOVER = 1991  # eq. 3.7 hover stick for 0.60 kg


def _fly(lab: VirtualLab, seconds: float) -> int:
    """Hover with 50 Hz commands (pre-encoded); return the number of DATA frames received."""
    command = encode_frame(CommandMsg(thrust=HOVER, ctrl=0x0F))
    received = 0
    for _ in range(round(seconds * 50)):
        lab.write(command)
        received += len(lab.advance(0.02))
        lab.vicon_datagrams()
    return received


def bench_in_process(seconds: float, profile: bool) -> float:
    """Real-time factor of the in-process lab (simulated s per wall s)."""
    lab = VirtualLab(seed=1)
    lab.set_pilot(Sticks(thrust=HOVER))
    lab.place((0.0, 0.0, -1.0), yaw=0.2)
    lab.send(ConfigMsg(0x17, 10))
    profiler = cProfile.Profile() if profile else None
    start = time.perf_counter()
    if profiler is not None:
        profiler.enable()
    frames = _fly(lab, seconds)
    if profiler is not None:
        profiler.disable()
    wall = time.perf_counter() - start
    rtf = seconds / wall
    stats = lab.stats()
    print(f"in-process: {seconds:.0f} s simulated in {wall:.2f} s wall -> real-time factor "
          f"{rtf:.1f}x (target >= 20x); {frames} DATA frames, {stats.vicon_sent} Vicon "
          f"datagrams, {seconds / lab.dt:.0f} plant steps "
          f"({wall / (seconds / lab.dt) * 1e6:.1f} us per step, all included)")
    if profiler is not None:
        pstats.Stats(profiler).sort_stats("tottime").print_stats(12)
    return rtf


_CLIENT = """
import sys, time, serial
from groundstation.asctec.decoder import StreamDecoder, encode_frame
from groundstation.asctec.messages import CommandMsg, ConfigMsg
port = serial.Serial(sys.argv[1], 57600, timeout=0)
port.write(encode_frame(ConfigMsg(0x17, 10)))
command = encode_frame(CommandMsg(thrust=int(sys.argv[2]), ctrl=0x0F))
decoder, frames, t_next = StreamDecoder(), 0, time.monotonic()
while True:
    frames += len(decoder.feed(port.read(4096)))
    port.write(command)
    t_next += 0.02
    time.sleep(max(0.0, t_next - time.monotonic()))
"""


def bench_realtime(seconds: float) -> float:
    """CPU share of run_sim_device over ~``seconds`` of wall time (client in another process)."""
    config = apply_overrides(load_config(REPO / "config" / "sim.yaml"),
                             {"vicon.port": 51977, "sim.pilot_thrust": HOVER})
    clients: list[subprocess.Popen[bytes]] = []

    def start_client(info: SimDeviceInfo) -> None:
        clients.append(
            subprocess.Popen([sys.executable, "-c", _CLIENT, info.pty_path, str(HOVER)]))

    stop = threading.Event()
    truth = Path("/tmp") / "bench_sim_truth.npz"
    try:
        result = run_sim_device(config, stop, truth_file=truth, on_ready=start_client,
                                announce=None, duration=seconds)
    finally:
        for client in clients:
            client.kill()
            client.wait()
    share = result.cpu_share
    print(f"real-time: {result.wall_s:.1f} s wall, {result.cpu_s:.2f} s CPU -> CPU share "
          f"{100 * share:.1f} % of one core (target < 25 %); {result.stats.data_sent} DATA "
          f"frames, {result.stats.commands} commands, {result.stats.vicon_sent} Vicon "
          f"datagrams, {result.overruns} overruns")
    return share


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=60.0, help="simulated seconds")
    parser.add_argument("--realtime", type=float, default=10.0, help="wall seconds (0 = skip)")
    parser.add_argument("--profile", action="store_true", help="cProfile the in-process run")
    args = parser.parse_args()
    bench_in_process(args.seconds, args.profile)
    if args.realtime > 0:
        bench_realtime(args.realtime)


if __name__ == "__main__":
    main()
