"""One flight-log row per tick, shared by the real-time daemon and the in-process runner.

Both loops log identically, so ``gs replay`` and ``gs report`` read a simulated
flight exactly like a real one.
"""

from __future__ import annotations

import math

from groundstation.app.recorder import FlightRecorder
from groundstation.asctec.blocks import RcBlock, StatusBlock
from groundstation.asctec.messages import DataMsg
from groundstation.flight.core import TickResult
from groundstation.types import ImuSample, Pose


class TickLogger:
    """Writes each tick to a :class:`FlightRecorder`, carrying the last IMU sample over
    ticks without one (a stalled stream keeps its last sample and counter, so a replay
    sees a repeat, not new information), and the last STATUS and RC blocks likewise (the
    vehicle's battery, flags and applied mask, the pilot's switch). Nothing is written
    before the first DATA frame.
    """

    def __init__(self, recorder: FlightRecorder) -> None:
        self.recorder = recorder
        self._raw: DataMsg | None = None
        self._imu: ImuSample | None = None
        self._status: StatusBlock | None = None
        self._rc: RcBlock | None = None

    def record(self, t: float, raw: DataMsg | None, imu: ImuSample | None,
               poses: list[Pose], result: TickResult, *, compute: float,
               jitter: float, latency: float) -> None:
        """Append the tick at monotonic time ``t`` [s] (see the recorder's field list)."""
        if raw is not None:
            self._status = raw.status if raw.status is not None else self._status
            self._rc = raw.rc if raw.rc is not None else self._rc
        if raw is not None and raw.gyro is not None and raw.acc is not None:
            self._raw = raw
        if imu is not None:
            self._imu = imu
        raw, last = self._raw, self._imu
        if raw is None or last is None or raw.gyro is None or raw.acc is None:
            return
        status, rc = self._status, self._rc
        self.recorder.append(
            t=t, imu=last, gyro_counts=(raw.gyro.x, raw.gyro.y, raw.gyro.z),
            acc_counts=(raw.acc.x, raw.acc.y, raw.acc.z),
            pose=poses[-1] if poses else None, estimate=result.estimate,
            reference=result.reference, command=result.command, controller=result.sticks,
            sent=result.due, state=int(result.state), compute_time=compute, jitter=jitter,
            latency=latency, preview=result.preview, automatic=result.automatic,
            battery_v=1e-3 * status.battery_mv if status is not None else math.nan,
            vehicle_flags=status.flags if status is not None else 0,
            vehicle_mask=status.ctrl_mask if status is not None else 0,
            pilot_enabled=rc.serial_enabled if rc is not None else True,
            pilot=rc.sticks() if rc is not None else None,
            vicon_nis=result.vicon_nis, vicon_refused=result.vicon_refused,
        )
