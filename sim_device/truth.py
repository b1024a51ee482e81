"""Ground truth of the virtual lab: current state snapshots and a log written as ``.npz``.

File format (``numpy.savez_compressed``; load with ``numpy.load(path)``), N rows:

==================  =========  ==============================================================
key                 shape      meaning
==================  =========  ==============================================================
``t``               (N,)       simulated time [s] (real-time mode: seconds since start)
``position``        (N, 3)     NED [m] (z = 0 is the floor, flying is z < 0)
``velocity``        (N, 3)     velocity relative to earth, NED axes [m/s]
``velocity_body``   (N, 3)     the same in body FRD axes [m/s]
``quaternion``      (N, 4)     attitude, scalar first [q0, q1, q2, q3], R(q) = eCb
``omega``           (N, 3)     body rates, FRD [rad/s]
``sticks``          (N, 4)     applied sticks [roll, pitch, yaw, thrust] in RC units
``ctrl_mask``       (N,)       applied ctrl mask: a set bit (bit0 pitch, bit1 roll, bit2 yaw,
                               bit3 thrust) = that channel is the ground station's
``serial_active``   (N,)       bool, the ground station controls at least one channel
``on_ground``       (N,)       bool, resting on the floor
``lift``            (N,)       rotor force along body z with droop and ground effect [N]
``columns``         ()         this table as text
==================  =========  ==============================================================

"Who is in control" per channel is ``ctrl_mask``: the pilot has every channel whose bit is clear.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from groundstation.types import FloatArray, Sticks
from sim_device.plant import Plant

_COLS = 25
_CHUNK = 4096
COLUMNS_DOC = __doc__.split("====\n", 2)[-1] if __doc__ else ""


@dataclass(frozen=True, slots=True)
class TruthState:
    """The vehicle's true state at one instant.

    t : simulated time [s]; position : (3,) NED [m]; velocity : (3,) NED [m/s];
    velocity_body : (3,) FRD [m/s]; quaternion : (4,) scalar first, R(q) = eCb;
    omega : (3,) body rates FRD [rad/s]; specific_force : (3,) FRD [m/s^2] (what an
    ideal accelerometer reads); lift : body-z rotor force [N]; on_ground : resting on
    the floor; sticks : applied sticks; ctrl_mask : applied ctrl mask (ground station's
    channels); serial_active : ctrl_mask != 0.
    """

    t: float
    position: FloatArray
    velocity: FloatArray
    velocity_body: FloatArray
    quaternion: FloatArray
    omega: FloatArray
    specific_force: FloatArray
    lift: float
    on_ground: bool
    sticks: Sticks
    ctrl_mask: int
    serial_active: bool


def snapshot(plant: Plant, sticks: Sticks, ctrl_mask: int) -> TruthState:
    """The current true state of ``plant`` with the applied ``sticks`` and ``ctrl_mask``."""
    return TruthState(
        t=plant.t,
        position=np.array([plant.px, plant.py, plant.pz]),
        velocity=np.array(plant.velocity_ned()),
        velocity_body=np.array([plant.vx, plant.vy, plant.vz]),
        quaternion=np.array([plant.q0, plant.q1, plant.q2, plant.q3]),
        omega=np.array([plant.wx, plant.wy, plant.wz]),
        specific_force=np.array(plant.specific_force()),
        lift=plant.lift_factor() * plant.lift,
        on_ground=plant.on_ground,
        sticks=sticks,
        ctrl_mask=ctrl_mask,
        serial_active=ctrl_mask != 0,
    )


class TruthLog:
    """Append-only log of the true state, grown in chunks (no per-row allocation)."""

    def __init__(self) -> None:
        self._chunks: list[FloatArray] = [np.empty((_CHUNK, _COLS))]
        self._n = 0  # rows used in the last chunk

    def __len__(self) -> int:
        return (len(self._chunks) - 1) * _CHUNK + self._n

    def record(self, plant: Plant, sticks: Sticks, ctrl_mask: int) -> None:
        """Append the plant's current state with the applied sticks and ctrl mask."""
        if self._n == _CHUNK:
            self._chunks.append(np.empty((_CHUNK, _COLS)))
            self._n = 0
        vn, ve, vd = plant.velocity_ned()
        self._chunks[-1][self._n] = (
            plant.t, plant.px, plant.py, plant.pz, vn, ve, vd, plant.vx, plant.vy, plant.vz,
            plant.q0, plant.q1, plant.q2, plant.q3, plant.wx, plant.wy, plant.wz,
            sticks.roll, sticks.pitch, sticks.yaw, sticks.thrust, ctrl_mask,
            ctrl_mask != 0, plant.on_ground, plant.lift_factor() * plant.lift,
        )
        self._n += 1

    def arrays(self) -> dict[str, npt.NDArray[Any]]:
        """The log as named arrays (keys and shapes as in the module docstring)."""
        rows = np.concatenate(self._chunks)[: len(self)]
        return {
            "t": rows[:, 0],
            "position": rows[:, 1:4],
            "velocity": rows[:, 4:7],
            "velocity_body": rows[:, 7:10],
            "quaternion": rows[:, 10:14],
            "omega": rows[:, 14:17],
            "sticks": rows[:, 17:21].astype(np.int64),
            "ctrl_mask": rows[:, 21].astype(np.uint8),
            "serial_active": rows[:, 22].astype(bool),
            "on_ground": rows[:, 23].astype(bool),
            "lift": rows[:, 24],
        }

    def save(self, path: str | Path) -> Path:
        """Write the log as a compressed ``.npz`` (see the module docstring); return the path."""
        path = Path(path)
        if path.suffix != ".npz":
            path = path.with_suffix(".npz")
        path.parent.mkdir(parents=True, exist_ok=True)
        contents: dict[str, Any] = {"columns": np.array(COLUMNS_DOC), **self.arrays()}
        np.savez_compressed(path, **contents)
        return path
