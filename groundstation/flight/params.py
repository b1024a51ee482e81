"""The flight's parameters: one frozen bundle of the packages' plain records.

:func:`groundstation.flight.assembly.assemble` builds a :class:`FlightParams` from the
configuration, once; the flight core, the real-time daemon and the in-process runner
take it, and nothing they call sees the configuration. A parameter's way from the YAML
file to its use is one hop: the key, its line in the assembly, the record field below
it becomes (each field names the section it comes from).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Literal

from groundstation.asctec.params import LinkParams
from groundstation.control.feasibility import FlightLimits, Volume
from groundstation.control.params import ControllerParams
from groundstation.control.trajectories import TrajectorySpec
from groundstation.estimation.records import EkfParams
from groundstation.flight.commander import CommanderParams
from groundstation.flight.mission import MissionParams
from groundstation.flight.planner import PlannerSettings
from groundstation.flight.supervisor import SupervisorLimits
from groundstation.model.quadrotor import QuadrotorParams
from groundstation.model.sensors import ImuScaling
from groundstation.telemetry.publisher import PublisherParams
from groundstation.telemetry.requests import RequestServerParams
from groundstation.types import Channel
from groundstation.vicon.receiver import ViconParams

if TYPE_CHECKING:
    from groundstation.config import GroundStationConfig


@dataclass(frozen=True, slots=True)
class DaemonParams:
    """What the real-time daemon does beside the flight (:mod:`groundstation.app`).

    log_dir : the flight-log directory (``logging.flight_log_dir``)
    mcap : ``gs fly`` also writes the flight as MCAP (``logging.mcap``)
    fifo_priority : SCHED_FIFO priority while flying, None: ask for none
        (``realtime.fifo_priority``)
    cpu_dma_latency_us : PM QoS wake-up latency bound [us], None: leave the idle states
        alone (``realtime.cpu_dma_latency_us``)
    switch_interval_s : the interpreter's thread switch interval while flying [s]
        (``realtime.switch_interval_ms``)
    paced_gc : full garbage collections only right after a COMMAND (``realtime.paced_gc``)
    second_signal_after_s : a second stop signal hands back only this long after the first
        [s] (``safety.second_signal_after_s``)
    plan_timeout_s : longest a motion may take to plan [s] (``api.plan_timeout_s``)
    start_horizon_s : how far ahead a follow's start may be [s] (``api.start_horizon_s``)
    """

    log_dir: Path
    mcap: bool
    fifo_priority: int | None
    cpu_dma_latency_us: int | None
    switch_interval_s: float
    paced_gc: bool
    second_signal_after_s: float
    plan_timeout_s: float
    start_horizon_s: float


@dataclass(frozen=True, slots=True)
class FlightParams:
    """Everything a flight is configured to be, in the packages' own records.

    link : the serial link (``serial``); vicon : the Vicon stream and its pose filter
        (``vicon``, with the volume of ``safety``)
    imu : the IMU's scales and zeros (``vehicle``); vehicle : the vehicle model (``vehicle``,
        its input delay with the frames' time on the wire of ``serial``)
    ekf : the estimator (``vehicle``, ``estimator``, ``vicon``, ``safety``, ``serial``);
        settle_time_s : on the ground before take-off [s] (``estimator.settle_time_s``)
    controller : which controller and its tuning (``controller``); controller_type : its
        name (``controller.type``), for logs; command_period_s : the period every
        controller is designed at and steps with [s] (``serial.command_rate_hz``)
    trajectory : what is flown (``trajectory``; name ``none``: run-time commands);
        shaping : ``trajectory.shaping``
    limits, volume : what a reference may ask of the vehicle, and where (``safety``,
        ``vehicle``)
    mission : the phases around the trajectory (``safety``, ``serial``); commander : the
        commanded flight (``trajectory``, ``api``); planner : how motions are planned
        (``trajectory``, ``api``, the limits)
    supervisor : the supervisor's limits and failsafes (``safety``, ``serial``, ``vicon``)
    channels : the channels the ground station flies (``channels.auto``); handover_blend_s :
        [s] (``serial.handover_blend_s``)
    telemetry : the publisher (``telemetry``); requests : the request socket
        (``telemetry.control_*``)
    daemon : what the real-time daemon does beside the flight
    source : the validated configuration it was assembled from, for the two that need
        the file itself: the flight log's copy of it and a virtual lab (a plugin that
        reads its own ``sim:`` section). The flight never reads it.
    """

    link: LinkParams
    vicon: ViconParams
    imu: ImuScaling
    vehicle: QuadrotorParams
    ekf: EkfParams
    settle_time_s: float
    controller: ControllerParams
    controller_type: str
    command_period_s: float
    trajectory: TrajectorySpec
    shaping: Literal["min-jerk", "none"]
    limits: FlightLimits
    volume: Volume
    mission: MissionParams
    commander: CommanderParams
    planner: PlannerSettings
    supervisor: SupervisorLimits
    channels: tuple[Channel, ...]
    handover_blend_s: float
    telemetry: PublisherParams
    requests: RequestServerParams
    daemon: DaemonParams
    source: GroundStationConfig

    @property
    def commanded(self) -> bool:
        """The flight is flown by run-time commands (``trajectory.name: none``)."""
        return self.trajectory.name == "none"
