"""Cost of FlightRecorder.append per control tick, flushes included.

Run: ``.venv/bin/python benchmarks/bench_recorder.py [ticks]``. Prints the mean and
the 99th-percentile cost of one append (a full tick: IMU, pose, estimate, reference,
command, timing) and the cost of the once-a-second flush of 100 rows.
"""

from __future__ import annotations

import sys
import tempfile
import time

import numpy as np

from groundstation.app.recorder import FlightRecorder
from groundstation.asctec.messages import CommandMsg
from groundstation.model.quadrotor import QuadrotorParams
from groundstation.types import ImuSample, Pose, Reference, StateEstimate, Sticks


def main(ticks: int = 20_000) -> None:
    """Append ``ticks`` rows at a simulated 100 Hz and print per-tick costs in microseconds."""
    imu = ImuSample(0.0, np.array([0.01, -0.02, 0.0]),
                    np.array([0.0, 0.0, -QuadrotorParams().g]), 1)
    pose = Pose(0.0, np.array([0.0, 0.0, -1.0]), np.array([1.0, 0.0, 0.0, 0.0]), 1)
    est = StateEstimate(0.0, np.zeros(3), np.array([1.0, 0.0, 0.0, 0.0]), np.zeros(3),
                        np.zeros(3), np.zeros(3), np.zeros(3), np.full(16, 1e-4))
    ref = Reference(0.0, np.array([0.0, 0.0, -1.0]), np.zeros(3))
    sticks = Sticks(10, -10, 0, 2000)
    command = CommandMsg(pitch=-10, roll=10, yaw=0, thrust=2000, ctrl=15)
    cost = np.empty(ticks)
    with tempfile.TemporaryDirectory() as tmp:
        with FlightRecorder.create(tmp, "bench: true\n") as rec:
            for k in range(ticks):
                start = time.perf_counter()
                rec.append(t=0.01 * k, imu=imu, gyro_counts=(2048, 2048, 2048),
                           acc_counts=(2048, 2048, 3190), pose=pose if k % 2 else None,
                           estimate=est, reference=ref, command=command, controller=sticks,
                           sent=True, state=2, compute_time=1e-3, jitter=1e-4, latency=5e-3)
                cost[k] = time.perf_counter() - start
        flushes = cost[::100]  # every 100th tick (1 s at 100 Hz) also flushed
        plain = np.delete(cost, np.s_[::100])
    print(f"append, no flush: mean {plain.mean() * 1e6:.1f} us, "
          f"p99 {np.percentile(plain, 99) * 1e6:.1f} us")
    print(f"append with flush of 100 rows: mean {flushes.mean() * 1e6:.1f} us, "
          f"max {flushes.max() * 1e6:.1f} us")
    print(f"mean over all ticks: {cost.mean() * 1e6:.1f} us")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 20_000)
