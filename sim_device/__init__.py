"""The bundled virtual lab: a simulated AscTec X-3D and a simulated Vicon Tracker.

* :class:`VirtualLab`: plant, firmware, radio and Vicon on a simulated clock,
  exchanging bytes (or messages) in-process: deterministic, faster than real time.
  The vehicle speaks the configuration's ``serial.protocol``: the X-3D dialect
  (:mod:`sim_device.firmware`) or the AscTec LL dialect (:mod:`sim_device.ll_firmware`).
* :func:`run_sim_device`: the same lab in real time on a pseudo-terminal and UDP
  (``gs sim-device``); :class:`SimDeviceThread` runs it in a background thread,
  :class:`SimDeviceProcess` in a child process; :class:`WireRecord` is what the vehicle
  saw of the ground station's timing.
* :class:`LabParams` and its parts: plain parameters, or ``LabParams.from_config``.

Units SI, frames NED/FRD, quaternions scalar first (see :mod:`groundstation`).
"""

from typing import TYPE_CHECKING

from groundstation.lazy import reexports

if TYPE_CHECKING:  # the names, imported from their modules on first use (groundstation.lazy)
    from sim_device.lab import LabStats, VirtualLab
    from sim_device.params import (
        FaultParams,
        ImuParams,
        LabParams,
        LinkParams,
        PilotParams,
        PlantParams,
        ViconSimParams,
    )
    from sim_device.realtime import (
        SimDeviceInfo,
        SimDeviceProcess,
        SimDeviceResult,
        SimDeviceThread,
        run_sim_device,
    )
    from sim_device.truth import TruthLog, TruthState
    from sim_device.vicon import ViconDatagram
    from sim_device.wire import WireRecord

__all__ = [
    "FaultParams",
    "ImuParams",
    "LabParams",
    "LabStats",
    "LinkParams",
    "PilotParams",
    "PlantParams",
    "SimDeviceInfo",
    "SimDeviceProcess",
    "SimDeviceResult",
    "SimDeviceThread",
    "TruthLog",
    "TruthState",
    "ViconDatagram",
    "ViconSimParams",
    "VirtualLab",
    "WireRecord",
    "run_sim_device",
]

if not TYPE_CHECKING:
    __getattr__ = reexports(__name__)
