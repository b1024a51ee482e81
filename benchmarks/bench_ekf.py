"""Timing of the EKF hot path: one IMU predict plus one Vicon update (100 Hz each).

Run: ``.venv/bin/python benchmarks/bench_ekf.py``. Prints p50/p99/max in
microseconds for predict+update, predict alone and update alone, over samples
from the tests' truth simulator (``tests/ekf_truth.py``; hover, Table 6.1/6.3 noise).
Target: p99 <= 100 us.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

from groundstation.estimation import Ekf

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from ekf_truth import TruthSimulator, square_reference

N = 5000


def main() -> None:
    sim = TruthSimulator(square_reference(), seed=3)
    imus, poses = [], []
    for _ in range(N + 1):
        imus.append(sim.imu())
        poses.append(sim.pose())
        sim.step()
    ekf = Ekf()
    ekf.initialise(poses[0], [imus[0]])
    both, pred, upd = np.empty(N), np.empty(N), np.empty(N)
    clock = time.perf_counter_ns
    for k in range(1, N + 1):
        t0 = clock()
        ekf.predict(imus[k])
        t1 = clock()
        ekf.update(poses[k])
        t2 = clock()
        pred[k - 1], upd[k - 1], both[k - 1] = t1 - t0, t2 - t1, t2 - t0
    for name, arr in (("predict+update", both), ("predict", pred), ("update", upd)):
        us = arr[N // 10 :] / 1000.0  # skip warm-up
        p50, p99 = np.percentile(us, [50, 99])
        print(f"{name:15s} p50 {p50:7.1f} us   p99 {p99:7.1f} us   max {us.max():8.1f} us")
    print(f"(N = {N}, updates accepted: {ekf.health().updates}, gated: {ekf.health().gated})")


if __name__ == "__main__":
    main()
