"""The flight's parameters: one frozen bundle of the packages' plain records.

:func:`groundstation.flight.assembly.assemble` builds a :class:`FlightParams` from the
configuration, once; the flight core, the real-time daemon and the in-process runner
take it, and nothing they call sees the configuration. A parameter's way from the YAML
file to its use is one hop: the key, its line in the assembly, the record field below
it becomes (each field names the section it comes from).

The records of the packages that stand above the flight are declared here, where the
assembly can build them without importing upwards: the daemon's :class:`DaemonParams`
and a fleet's :class:`FleetParams` (in the bundle), :class:`ZenohParams` and the Vicon
relay's :class:`RelayParams` (:mod:`groundstation.fleet`).
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
from groundstation.vicon.plausibility import Box
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
class ZenohParams:
    """How a process joins its fleet's Zenoh network (``fleet.zenoh``; README "Fleet").

    listen : endpoints it accepts the others' links on, ``PROTOCOL/HOST:PORT``
    connect : the others' listen endpoints (retried while absent)
    tls_root_ca, tls_certificate, tls_private_key : PEM files of the lab's CA, this
        process's certificate and its key: mutual TLS and the fleet's access rules (all
        None: loopback only, no TLS)
    operators : certificate common names, besides the vehicles, allowed to send requests
    """

    listen: tuple[str, ...]
    connect: tuple[str, ...]
    tls_root_ca: Path | None
    tls_certificate: Path | None
    tls_private_key: Path | None
    operators: tuple[str, ...]


@dataclass(frozen=True, slots=True)
class FleetParams:
    """This vehicle in a fleet (``fleet``; :mod:`groundstation.fleet`).

    name : the fleet's key prefix; vehicle : this vehicle's name; peers : the others'
    separation_m : least distance to a peer kept at planning [m] (None: off; the
        supervisor's in-flight rule is in :class:`SupervisorLimits`)
    peer_timeout_s : a peer whose pose is older than this is silent [s]
    pose_rate_hz : this vehicle's estimated pose published for its peers [Hz]
    zenoh : how it joins the fleet's network
    """

    name: str
    vehicle: str
    peers: tuple[str, ...]
    separation_m: float | None
    peer_timeout_s: float
    pose_rate_hz: float
    zenoh: ZenohParams


@dataclass(frozen=True, slots=True)
class RelayParams:
    """``gs vicon-relay`` of a fleet file (:mod:`groundstation.fleet.relay`).

    fleet : the key prefix; vehicles : the fleet's vehicles (its members by name)
    bind_address, port : where Tracker's UDP stream arrives (the base's ``vicon``)
    plausible_volume : where an object can be, NED [m]: every vehicle's volume together,
        grown by ``vicon.plausibility_margin_m``
    zenoh : how the relay joins the fleet's network
    """

    fleet: str
    vehicles: tuple[str, ...]
    bind_address: str
    port: int
    plausible_volume: Box
    zenoh: ZenohParams


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
    fleet : this vehicle in a fleet (``fleet``), None alone
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
    fleet: FleetParams | None
    source: GroundStationConfig

    @property
    def commanded(self) -> bool:
        """The flight is flown by run-time commands (``trajectory.name: none``)."""
        return self.trajectory.name == "none"
