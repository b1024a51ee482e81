"""The virtual Vicon Tracker: the plant's pose as UDP object-stream datagrams.

Every ``1 / rate_hz`` the tracker takes the true pose, decides whether the
object is tracked, and encodes one datagram with the project's own codec
(:func:`groundstation.vicon.decoder.encode_datagram`) in exactly the layout of
``docs/vicon-udp.md``; the NED/FRD -> Vicon conversion is the inverse in
:mod:`groundstation.vicon.frames`. The datagram is delivered ``latency`` later.

Tracked means: inside the tracked volume (Table B.1), tilted no more than
``tilt_limit_deg`` from level, and not in a scripted outage. A tracked pose gets
white noise with the Table 6.1 variances (position per NED axis; quaternion per
component, then renormalised). Lost tracking is sent in the selected encoding:

* ``missing``: a datagram with no object item (the frame number still counts);
* ``zero``: the object with all six values exactly 0 (the Vicon SDK's occlusion);
* ``held-identity``: the last tracked translation with rotation exactly (0, 0, 0)
  (the thesis lab, Ch. 7.3.1).

The frame number counts datagrams, +1 each, wrapping at 2**32.

Two more faults for tests of the ground station's input path:

* a **pause** (:meth:`VirtualVicon.add_pause`): nothing is sent at all (Tracker or
  the network stalls); the frame number keeps counting, as Tracker's cameras do, so
  the first datagram after it jumps ahead;
* **foreign datagrams** (:meth:`VirtualVicon.inject`): any bytes delivered at a
  chosen time among the Tracker's own, as a hostile or misconfigured sender on the
  Vicon port would; :func:`foreign_stream` builds a stream of them.
"""

from __future__ import annotations

import heapq
import math
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from groundstation.vicon.decoder import ObjectPose, encode_datagram
from groundstation.vicon.frames import FrameConversion
from sim_device.link import seconds_to_ns
from sim_device.params import LossEncoding, ViconSimParams
from sim_device.plant import Plant


@dataclass(frozen=True, slots=True)
class ViconDatagram:
    """One datagram of the virtual Vicon.

    t : delivery time, simulated [s] (pose instant + latency)
    data : the datagram bytes, exactly as sent over UDP
    frame : its Tracker frame number (a foreign datagram's first 4 bytes, -1 if shorter)
    tracked : True if it carries a measured pose, False if a loss encoding or foreign
    """

    t: float
    data: bytes
    frame: int
    tracked: bool


class VirtualVicon:
    """Virtual Tracker sending one object (see the module docstring).

    params : stream parameters; rng : the noise generator (seeded by the lab).
    ``loss_encoding``, ``noise`` and the rate (:meth:`set_rate`) may change at run time.
    """

    def __init__(self, params: ViconSimParams, rng: np.random.Generator) -> None:
        self.params = params
        self._rng = rng
        self._conv = FrameConversion.create(np.array(params.world_to_ned),
                                            np.array(params.body_to_object))
        self.loss_encoding: LossEncoding = params.loss_encoding
        self.noise = params.noise
        self.period_ns = 0
        self.set_rate(params.rate_hz)
        self.next_ns = 0
        self._latency_ns = seconds_to_ns(params.latency)
        self._outages: list[tuple[int, int]] = []
        for start, duration in params.outages:
            self.add_outage(start, duration)
        self._cos_tilt = math.cos(math.radians(params.tilt_limit_deg))
        self._pos_sigma = [math.sqrt(v) for v in params.position_variance]
        self._q_sigma = [math.sqrt(v) for v in params.quaternion_variance]
        self._frame = params.first_frame & 0xFFFF_FFFF
        self._held: tuple[float, float, float] = (0.0, 0.0, 0.0)
        self._queue: deque[tuple[int, ViconDatagram]] = deque()
        self._pauses: list[tuple[int, int]] = []
        self._foreign: list[tuple[int, int, ViconDatagram]] = []  # heap: (t_ns, seq, datagram)
        self.sent = 0
        self.lost = 0
        self.paused = 0
        self.injected = 0

    def set_rate(self, rate_hz: float) -> None:
        """Change the datagram rate [Hz] (takes effect after the next datagram)."""
        if not rate_hz > 0:
            raise ValueError(f"Vicon rate must be > 0 Hz, got {rate_hz}")
        self.period_ns = max(1, round(1e9 / rate_hz))

    def add_outage(self, start: float, duration: float) -> None:
        """No tracking from ``start`` for ``duration`` (simulated seconds)."""
        begin = seconds_to_ns(start)
        self._outages.append((begin, begin + seconds_to_ns(duration)))

    def add_pause(self, start: float, duration: float) -> None:
        """Send nothing from ``start`` for ``duration`` (simulated seconds); the frame
        number keeps counting through the pause (counted in :attr:`paused`)."""
        begin = seconds_to_ns(start)
        self._pauses.append((begin, begin + seconds_to_ns(duration)))

    def inject(self, t: float, data: bytes) -> None:
        """Deliver ``data`` (any bytes: a datagram of another sender) at simulated time
        ``t`` [s], in time order with the Tracker's own; ``tracked`` is False for it and
        ``frame`` the uint32 in its first 4 bytes (-1 if shorter)."""
        t_ns = seconds_to_ns(t)
        frame = int.from_bytes(data[:4], "little") if len(data) >= 4 else -1
        heapq.heappush(self._foreign,
                       (t_ns, self.injected, ViconDatagram(t_ns * 1e-9, bytes(data), frame, False)))
        self.injected += 1

    def tracked(self, t_ns: int, plant: Plant) -> bool:
        """The object is tracked at ``t_ns``: in the volume, tilt within limit, no outage."""
        for begin, end in self._outages:
            if begin <= t_ns < end:
                return False
        p = self.params
        return (
            p.volume_x[0] <= plant.px <= p.volume_x[1]
            and p.volume_y[0] <= plant.py <= p.volume_y[1]
            and p.volume_z[0] <= plant.pz <= p.volume_z[1]
            and plant.tilt_cos() >= self._cos_tilt
        )

    def sample(self, t_ns: int, plant: Plant) -> None:
        """Produce the datagram due at ``t_ns`` from the plant's true pose."""
        self.next_ns += self.period_ns
        if self.next_ns <= t_ns:
            self.next_ns = t_ns + self.period_ns
        if any(begin <= t_ns < end for begin, end in self._pauses):
            self._frame = (self._frame + 1) & 0xFFFF_FFFF
            self.paused += 1
            return
        tracked = self.tracked(t_ns, plant)
        objects: list[ObjectPose] = []
        name = self.params.object_name
        if tracked:
            translation, rotation = self._measure(plant)
            self._held = translation
            objects.append(ObjectPose(name, translation, rotation))
        else:
            self.lost += 1
            if self.loss_encoding == "zero":
                objects.append(ObjectPose(name, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0)))
            elif self.loss_encoding == "held-identity":
                objects.append(ObjectPose(name, self._held, (0.0, 0.0, 0.0)))
        data = encode_datagram(self._frame, objects, self.params.pad_to)
        deliver_ns = t_ns + self._latency_ns
        self._queue.append((deliver_ns, ViconDatagram(deliver_ns * 1e-9, data, self._frame,
                                                      tracked)))
        self._frame = (self._frame + 1) & 0xFFFF_FFFF
        self.sent += 1

    def _measure(self, plant: Plant) -> tuple[tuple[float, float, float],
                                              tuple[float, float, float]]:
        """Noisy true pose in Vicon units: (translation [mm], Euler XYZ [rad])."""
        pos = [plant.px, plant.py, plant.pz]
        q = [plant.q0, plant.q1, plant.q2, plant.q3]
        if self.noise:
            n = self._rng.standard_normal(7)
            pos = [pos[i] + self._pos_sigma[i] * n[i] for i in range(3)]
            if self.params.angle_noise:
                q = [q[i] + self._q_sigma[i] * n[3 + i] for i in range(4)]
        return self._conv.to_vicon(pos, q)

    @property
    def next_due_ns(self) -> int | None:
        """Delivery time of the oldest datagram in flight [ns], or None."""
        due = [t for t in (self._queue[0][0] if self._queue else None,
                           self._foreign[0][0] if self._foreign else None) if t is not None]
        return min(due) if due else None

    def pop_due(self, t_ns: int) -> list[ViconDatagram]:
        """Datagrams delivered by simulated time ``t_ns`` [ns], in order (at equal times
        the Tracker's own first)."""
        q, foreign = self._queue, self._foreign
        out: list[ViconDatagram] = []
        while True:
            own = q[0][0] if q and q[0][0] <= t_ns else None
            other = foreign[0][0] if foreign and foreign[0][0] <= t_ns else None
            if own is None and other is None:
                return out
            if other is None or (own is not None and own <= other):
                out.append(q.popleft()[1])
            else:
                out.append(heapq.heappop(foreign)[2])


def foreign_stream(start: float, duration: float, rate_hz: float,
                   make: Callable[[int, float], bytes]) -> list[tuple[float, bytes]]:
    """``(t [s], datagram)`` pairs of a foreign sender at ``rate_hz`` from ``start`` for
    ``duration``: ``make(k, t)`` builds the k-th datagram (k = 0, 1, ...), e.g. with
    :func:`groundstation.vicon.decoder.encode_datagram`. Feed them to
    :meth:`VirtualVicon.inject` (or :meth:`sim_device.lab.VirtualLab.inject_vicon`)."""
    n = math.floor(duration * rate_hz + 1e-9)
    return [(start + k / rate_hz, make(k, start + k / rate_hz)) for k in range(n)]
