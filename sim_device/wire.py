"""When frames crossed the virtual X-3D's serial port, seen from the vehicle's side.

The real-time runner (:mod:`sim_device.realtime`) stamps, on the monotonic clock,
the instant each DATA frame's last byte leaves the virtual vehicle (written to the
pty) and the instant each COMMAND (and CONFIG) frame arrives (read from the pty and
decoded). From
those two streams, as an independent lab measures a ground station from the
vehicle's side:

* **latency**: for each COMMAND, its arrival minus the last DATA frame sent before
  it (the ground station's DATA -> COMMAND turnaround, wire and scheduling included);
* **command gap**: the time from a COMMAND with a non-zero ctrl mask to the next
  COMMAND. The vehicle's watchdog hands every channel to the pilot when this
  exceeds 100 ms (spec section 4).

In the AscTec LL dialect the IMU_RAWDATA answers stand for DATA and the ``>*>di``
commands for COMMAND (:class:`WireTiming`'s ``protocol``); its watchdog is
``serial.ll.fallback_ms``.

:class:`WireTiming` records (cheaply: two appends per frame) and saves its arrays
into the ground-truth ``.npz`` (keys :data:`KEYS`); :class:`WireRecord` reads them
back and computes the figures.
"""

from __future__ import annotations

from array import array
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt

from groundstation.asctec.decoder import START_MARKER, StreamDecoder
from groundstation.asctec.ll import LlRequestDecoder
from groundstation.asctec.messages import DESCRIPTOR_DATA, CommandMsg, ConfigMsg

KEYS = ("wire_data_out", "wire_command_in", "wire_command_mask", "wire_config_in")
"""Truth-file keys: DATA last-byte-out times [s], COMMAND arrival times [s], their masks,
CONFIG arrival times [s]."""

FloatArray = npt.NDArray[np.float64]


class WireTiming:
    """Records DATA-out and COMMAND-in instants at the virtual vehicle's port.

    profile : CRC profile of the link (COMMAND frames are decoded to find their end).
    protocol : the link's dialect. In the AscTec LL dialect the IMU_RAWDATA answers
    (descriptor 0x01, as the X-3D's DATA) count as DATA out and the ``>*>di`` commands
    as COMMANDs in; there is no CONFIG.
    """

    def __init__(self, profile: str, protocol: str = "x3d") -> None:
        self._decoder = StreamDecoder(profile)
        self._ll_decoder = LlRequestDecoder() if protocol == "asctec-ll" else None
        self.data_out = array("d")
        self.command_in = array("d")
        self.command_mask = array("H")
        self.config_in = array("d")

    def data_sent(self, t: float) -> None:
        """A DATA frame's last byte left the vehicle at ``t`` [s]."""
        self.data_out.append(t)

    def frame_sent(self, t: float, frame: bytes) -> None:
        """``frame``'s last byte left the vehicle at ``t`` [s]: stamped if it is a DATA
        frame (X-3D: every frame; LL: IMU_RAWDATA, not the other answers and acks)."""
        if self._ll_decoder is None or (frame[:3] == START_MARKER and len(frame) > 5
                                        and frame[5] == DESCRIPTOR_DATA):
            self.data_out.append(t)

    def received(self, t: float, data: bytes) -> None:
        """``data`` from the ground station was read at ``t`` [s]; stamp each COMMAND and
        CONFIG in it."""
        if self._ll_decoder is not None:
            for request in self._ll_decoder.feed(data):
                if isinstance(request, CommandMsg):
                    self.command_in.append(t)
                    self.command_mask.append(request.ctrl)
            return
        for item in self._decoder.feed(data):
            if isinstance(item, CommandMsg):
                self.command_in.append(t)
                self.command_mask.append(item.ctrl)
            elif isinstance(item, ConfigMsg):
                self.config_in.append(t)

    def arrays(self) -> dict[str, npt.NDArray[np.generic]]:
        """The records as numpy arrays under :data:`KEYS`."""
        return {
            "wire_data_out": np.frombuffer(self.data_out, dtype=np.float64).copy(),
            "wire_command_in": np.frombuffer(self.command_in, dtype=np.float64).copy(),
            "wire_command_mask": np.frombuffer(self.command_mask, dtype=np.uint16).copy(),
            "wire_config_in": np.frombuffer(self.config_in, dtype=np.float64).copy(),
        }

    def record(self) -> WireRecord:
        """A :class:`WireRecord` of what was recorded so far."""
        a = self.arrays()
        return WireRecord(a["wire_data_out"].astype(float), a["wire_command_in"].astype(float),
                          a["wire_command_mask"].astype(int), a["wire_config_in"].astype(float))


@dataclass(frozen=True)
class WireRecord:
    """The vehicle-side record of one run.

    data_out : (N,) monotonic times DATA frames left the vehicle [s]
    command_in : (M,) monotonic arrival times of COMMAND frames [s]
    command_mask : (M,) their ctrl masks
    config_in : (K,) monotonic arrival times of CONFIG frames [s]
    """

    data_out: FloatArray
    command_in: FloatArray
    command_mask: npt.NDArray[np.int_]
    config_in: FloatArray

    @classmethod
    def load(cls, truth_file: str | Path) -> WireRecord:
        """Read the record from a ground-truth ``.npz`` written by the real-time runner."""
        with np.load(truth_file) as npz:
            return cls(np.asarray(npz["wire_data_out"], dtype=float),
                       np.asarray(npz["wire_command_in"], dtype=float),
                       np.asarray(npz["wire_command_mask"], dtype=int),
                       np.asarray(npz["wire_config_in"], dtype=float))

    def latencies(self, start: float = -np.inf, end: float = np.inf) -> FloatArray:
        """For each COMMAND arriving in [start, end]: arrival minus the last DATA frame out
        before it [s] (COMMANDs before the first DATA frame are skipped)."""
        t = self.command_in[(self.command_in >= start) & (self.command_in <= end)]
        k = np.searchsorted(self.data_out, t, side="right") - 1
        ok = k >= 0
        return np.asarray(t[ok] - self.data_out[k[ok]], dtype=float)

    def command_gaps(self, start: float = -np.inf, end: float = np.inf) -> FloatArray:
        """Time from each COMMAND with a non-zero ctrl mask arriving in [start, end] to the
        next COMMAND [s]: what the vehicle's 100 ms watchdog measures."""
        t, mask = self.command_in, self.command_mask
        if len(t) < 2:
            return np.zeros(0)
        gaps = np.diff(t)
        armed = (mask[:-1] != 0) & (t[:-1] >= start) & (t[:-1] <= end)
        return np.asarray(gaps[armed], dtype=float)

    def commanding_span(self) -> tuple[float, float]:
        """Arrival times of the first and the last COMMAND with a non-zero mask [s]
        ((nan, nan) if none)."""
        flying = self.command_in[self.command_mask != 0]
        if len(flying) == 0:
            return (float("nan"), float("nan"))
        return (float(flying[0]), float(flying[-1]))
