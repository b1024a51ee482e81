"""The serial radio between ground station and vehicle, both directions.

Time is integer nanoseconds of simulated time (exact, no drift).

* **Pacing.** A byte takes 10 bit times (8N1) at the configured baud. The
  vehicle's UART sends one frame at a time (:meth:`Downlink.busy`); the ground
  station's bytes reach the vehicle no faster than the baud either.
* **Delay.** Ground -> vehicle bytes arrive ``command_delay`` after their last
  bit (the command link's transport delay, Ch. 3.3.1). Vehicle -> ground frames
  can get a constant extra delay and/or be held and released in bursts.
* **Faults.** Per-byte bit flips (both directions), whole DATA frames lost.

Delivery queues are FIFO and deliveries are monotonic in time, so popping the
due items is O(items).
"""

from __future__ import annotations

from collections import deque

import numpy as np

NS = 1_000_000_000


def seconds_to_ns(seconds: float) -> int:
    """Seconds -> integer nanoseconds (rounded)."""
    return round(seconds * NS)


class ByteCorrupter:
    """Flips one random bit in each byte hit, with probability ``rate`` per byte.

    The distance to the next hit is drawn from a geometric distribution, so a
    clean stream costs one comparison per chunk, not one draw per byte.
    """

    def __init__(self, rate: float, rng: np.random.Generator) -> None:
        self._rng = rng
        self.flipped = 0
        self.rate = 0.0
        self._gap = 0
        self.set_rate(rate)

    def set_rate(self, rate: float) -> None:
        """Change the per-byte probability (0 disables)."""
        self.rate = rate
        self._gap = self._draw_gap()

    def _draw_gap(self) -> int:
        """Bytes before the next hit (0 = the next byte); a huge number when off."""
        if self.rate <= 0.0:
            return 1 << 62
        return int(self._rng.geometric(self.rate)) - 1

    def apply(self, data: bytes) -> bytes:
        """``data`` with the scheduled bytes corrupted (returns ``data`` itself if none)."""
        n = len(data)
        if self._gap >= n:
            self._gap -= n
            return data
        out = bytearray(data)
        pos = self._gap
        while pos < n:
            out[pos] ^= 1 << int(self._rng.integers(8))
            self.flipped += 1
            pos += 1 + self._draw_gap()
        self._gap = pos - n
        return bytes(out)


class Uplink:
    """Ground station -> vehicle: baud pacing, transport delay, corruption.

    baud : [bit/s]; delay_ns : transport delay [ns]; corrupter : shared fault source.
    """

    def __init__(self, baud: int, delay_ns: int, corrupter: ByteCorrupter) -> None:
        self._byte_ns = 10 * NS / baud
        self._delay_ns = delay_ns
        self._corrupter = corrupter
        self._free_ns = 0
        self._queue: deque[tuple[int, bytes]] = deque()
        self.bytes_in = 0

    def write(self, t_ns: int, data: bytes) -> None:
        """Bytes handed to the ground station's radio at ``t_ns``."""
        if not data:
            return
        self.bytes_in += len(data)
        end = max(t_ns, self._free_ns) + round(len(data) * self._byte_ns)
        self._free_ns = end
        self._queue.append((end + self._delay_ns, self._corrupter.apply(bytes(data))))

    @property
    def next_due_ns(self) -> int | None:
        """Arrival time of the oldest bytes in flight, or None."""
        return self._queue[0][0] if self._queue else None

    def pop_due(self, t_ns: int) -> bytes:
        """All bytes that have reached the vehicle by ``t_ns``, in order."""
        q = self._queue
        if not q or q[0][0] > t_ns:
            return b""
        parts = []
        while q and q[0][0] <= t_ns:
            parts.append(q.popleft()[1])
        return b"".join(parts)


class Downlink:
    """Vehicle -> ground station: one frame at a time at the baud, then radio faults.

    baud : [bit/s]; corrupter : bit flips; rng : draws for frame loss.
    Fault settings are plain attributes and may be changed at run time:
    ``drop_rate`` (probability per frame), ``delay_ns`` (constant extra delay),
    ``burst_ns`` (release held frames on multiples of this; 0 = off).
    """

    def __init__(self, baud: int, corrupter: ByteCorrupter, rng: np.random.Generator) -> None:
        self._byte_ns = 10 * NS / baud
        self._corrupter = corrupter
        self._rng = rng
        self._free_ns = 0
        self._queue: deque[tuple[int, bytes]] = deque()
        self.drop_rate = 0.0
        self.delay_ns = 0
        self.burst_ns = 0
        self.frames_sent = 0
        self.frames_dropped = 0
        self.bytes_sent = 0

    def frame_ns(self, size: int) -> int:
        """Time to transmit ``size`` bytes [ns]."""
        return round(size * self._byte_ns)

    def busy(self, t_ns: int) -> bool:
        """The UART is still sending an earlier frame at ``t_ns``."""
        return self._free_ns > t_ns

    def backlog_ns(self, t_ns: int) -> int:
        """Time the UART still needs at ``t_ns`` for the bytes queued before [ns] (0 = idle)."""
        return max(0, self._free_ns - t_ns)

    def send(self, t_ns: int, frame: bytes) -> None:
        """Start sending ``frame`` at ``t_ns``, or right after the frames queued before it
        (the X-3D firmware checks :meth:`busy` first and sends one frame at a time)."""
        end = max(t_ns, self._free_ns) + self.frame_ns(len(frame))
        self._free_ns = end
        self.frames_sent += 1
        self.bytes_sent += len(frame)
        if self.drop_rate > 0.0 and self._rng.random() < self.drop_rate:
            self.frames_dropped += 1
            return
        deliver = end + self.delay_ns
        if self.burst_ns > 0:
            deliver = -(-deliver // self.burst_ns) * self.burst_ns
        if self._queue and deliver < self._queue[-1][0]:
            deliver = self._queue[-1][0]  # a fault change never reorders the stream
        self._queue.append((deliver, self._corrupter.apply(frame)))

    @property
    def next_due_ns(self) -> int | None:
        """Delivery time of the oldest frame in flight, or None."""
        return self._queue[0][0] if self._queue else None

    def pop_due(self, t_ns: int) -> list[tuple[int, bytes]]:
        """Frames delivered by ``t_ns``: (delivery time [ns], bytes), in order."""
        q = self._queue
        out: list[tuple[int, bytes]] = []
        while q and q[0][0] <= t_ns:
            out.append(q.popleft())
        return out
