"""Per-datagram cost of the Vicon path: decode, and decode + filter + convert to NED.

Datagrams: 10,000 Tracker frames of 3 objects each (the tracked one second),
padded to 1024 bytes, encoded with :func:`encode_datagram`, the followed object
on a smooth seeded random walk so every pose passes the plausibility gate. Prints
microseconds per datagram (best of 3 runs, one core) for :func:`decode_datagram`
and :meth:`PoseFilter.process`. Vicon streams at most 100 Hz (10 ms per frame);
the requirement is < 200 us per datagram through the whole filter (2% of a
100 Hz period), and the script exits with status 1 if it is missed.

Run: ``.venv/bin/python benchmarks/bench_vicon.py``
"""

from __future__ import annotations

import random
import sys
import time
from collections.abc import Callable

from groundstation.vicon.decoder import ObjectPose, decode_datagram, encode_datagram
from groundstation.vicon.posefilter import PoseFilter

N = 10_000
PERIOD = 0.01  # s, 100 Hz
REQUIRED_US = 200.0


def make_datagrams(seed: int = 1) -> list[bytes]:
    """N datagrams; "quad" walks by at most 1 mm and 1 mrad per axis per frame."""
    rng = random.Random(seed)
    t = [0.0, 0.0, 1000.0]
    r = [0.1, -0.1, 0.5]
    out = []
    for frame in range(N):
        t = [v + rng.uniform(-1.0, 1.0) for v in t]
        r = [v + rng.uniform(-1e-3, 1e-3) for v in r]
        objs = [
            ObjectPose("wand", (500.0, 500.0, 0.0), (0.0, 0.0, 0.2)),
            ObjectPose("quad", (t[0], t[1], t[2]), (r[0], r[1], r[2])),
            ObjectPose("box", (-500.0, 0.0, 10.0), (0.0, 0.1, 0.0)),
        ]
        out.append(encode_datagram(frame, objs))
    return out


def best_of_3(fn: Callable[[], None]) -> float:
    """Best wall time of three runs of ``fn``, per datagram [us]."""
    best = float("inf")
    for _ in range(3):
        start = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - start)
    return best / N * 1e6


def main() -> int:
    datagrams = make_datagrams()

    def decode_all() -> None:
        for d in datagrams:
            decode_datagram(d)

    def filter_all() -> None:
        f = PoseFilter("quad")
        for i, d in enumerate(datagrams):
            f.process(d, i * PERIOD)
        expected = N - (f.reanchor_poses - 1)  # the first ones confirm the stream
        assert f.poses == expected, f"only {f.poses} of {expected} poses accepted"

    decode_us = best_of_3(decode_all)
    filter_us = best_of_3(filter_all)
    print(f"decode_datagram:        {decode_us:7.1f} us/datagram")
    print(f"PoseFilter.process:     {filter_us:7.1f} us/datagram (required < {REQUIRED_US:.0f})")
    return 0 if filter_us < REQUIRED_US else 1


if __name__ == "__main__":
    sys.exit(main())
