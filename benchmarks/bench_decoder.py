"""Throughput of the X-3D stream decoder on a recorded-style DATA stream.

Stream: 20,000 STATUS+GYRO+ACC DATA frames (31 bytes each, spec section 6) with
random gyro/acc counts, about 0.1% of the bytes corrupted (seeded), fed to one
:class:`~groundstation.asctec.decoder.StreamDecoder` in chunks of a fixed size,
as a serial reader would hand them over. Prints frames/s and bytes/s per chunk
size (best of 3 runs, one core) and the factor over the 57600-baud line rate
(5760 B/s). The requirement is >= 100x the line rate (576,000 B/s) at
every chunk size, down to one frame per read; the script exits with status 1 if it is missed.

Run: ``.venv/bin/python benchmarks/bench_decoder.py``
"""

from __future__ import annotations

import random
import sys
import time

from groundstation.asctec.blocks import AxisCounts, StatusBlock
from groundstation.asctec.decoder import StreamDecoder, encode_frame
from groundstation.asctec.messages import DataMsg

LINE_RATE = 57600 / 10  # bytes/s: 8N1 is 10 bits per byte
REQUIRED = 100 * LINE_RATE
N_FRAMES = 20_000
CORRUPTION = 0.001
CHUNK_SIZES = (31, 64, 256, 4096)


def make_stream(seed: int = 1) -> bytes:
    """N_FRAMES DATA frames with about CORRUPTION of their bytes XORed at random."""
    rng = random.Random(seed)
    frames = [
        encode_frame(
            DataMsg(
                i & 0xFFFF,
                StatusBlock(11800 - i % 500, 0b111, 0x0F),
                AxisCounts(*(2048 + rng.randrange(-200, 200) for _ in range(3))),
                AxisCounts(2048 + rng.randrange(-50, 50), 2048, 1163 + rng.randrange(-50, 50)),
            )
        )
        for i in range(N_FRAMES)
    ]
    stream = bytearray(b"".join(frames))
    for p in rng.sample(range(len(stream)), int(len(stream) * CORRUPTION)):
        stream[p] ^= rng.randrange(1, 256)
    return bytes(stream)


def run(stream: bytes, chunk: int) -> tuple[float, int, int]:
    """Decode ``stream`` in ``chunk``-byte pieces; (seconds, messages, rejections)."""
    decoder = StreamDecoder()
    feed = decoder.feed
    chunks = [stream[i : i + chunk] for i in range(0, len(stream), chunk)]
    t0 = time.perf_counter()
    for piece in chunks:
        feed(piece)
    elapsed = time.perf_counter() - t0
    counts = decoder.counts()
    return elapsed, counts.frames["data"], counts.rejected_total


def main() -> int:
    """Print the throughput table; return 1 if the requirement is missed."""
    stream = make_stream()
    print(f"stream: {N_FRAMES} DATA frames, {len(stream)} bytes, {CORRUPTION:.1%} bytes corrupted")
    header = f"{'chunk [B]':>9} {'frames/s':>12} {'bytes/s':>13} {'x line rate':>11}"
    print(header + "  accepted rejected")
    worst = float("inf")
    for chunk in CHUNK_SIZES:
        elapsed, accepted, rejected = min(run(stream, chunk) for _ in range(3))
        rate = len(stream) / elapsed
        worst = min(worst, rate)
        print(
            f"{chunk:>9} {accepted / elapsed:>12,.0f} {rate:>13,.0f} {rate / LINE_RATE:>11,.0f}"
            f"  {accepted:>8} {rejected:>8}"
        )
    verdict = "OK" if worst >= REQUIRED else "TOO SLOW"
    print(f"slowest: {worst:,.0f} B/s; required {REQUIRED:,.0f} B/s (100x 57600 baud): {verdict}")
    return 0 if worst >= REQUIRED else 1


if __name__ == "__main__":
    sys.exit(main())
