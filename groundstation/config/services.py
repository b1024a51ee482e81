"""What runs beside the flight: the ``telemetry`` section (the publisher and the request
socket), ``logging`` (the console and the flight recorder), ``realtime`` (what the daemon
asks of the OS) and ``api`` (motions commanded at run time)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Literal

from pydantic import ValidationInfo, field_validator

from groundstation.config.base import ConfigModel
from groundstation.config.ranges import (
    FLIGHT_MAX_S,
    DirectoryPath,
    FifoPriority,
    FilePath,
    LabLength,
    Speed,
    ZmqEndpoint,
    within,
)
from groundstation.endpoints import local_endpoint, zmq_endpoint


class TelemetryConfig(ConfigModel):
    """The pyzmq PUB socket, and the request socket ``gs channels`` talks to.

    The request socket changes what flies, so it binds to loopback unless it
    authenticates its clients with CURVE (:mod:`groundstation.telemetry.curve`):
    ``control_server_key`` and ``control_client_keys`` together turn CURVE on, and an
    endpoint beyond loopback is refused without them.
    """

    enabled: bool = True
    endpoint: ZmqEndpoint = "tcp://127.0.0.1:5556"
    # loopback by default; bind to * to serve the lab
    rate_hz: Annotated[float, within(
        0.0, 100.0, "Hz: at most one message per IMU sample (100 Hz)",
        lo_open=True)] = 20.0  # enough for a live view, light on the loop
    # (the two key fields come before control_endpoint so its check can see them)
    control_server_key: FilePath | None = None
    # the daemon's CURVE key pair: a `.key_secret` file of zmq.auth.create_certificates
    control_client_keys: DirectoryPath | None = None
    # directory of the public keys (`*.key`) of the clients allowed to connect
    control_endpoint: str | None = "tcp://127.0.0.1:5557"
    # REP socket for run-time requests (`gs channels`); loopback only by default, null disables

    @field_validator("control_client_keys")
    @classmethod
    def _keys_in_pairs(cls, value: Path | None, info: ValidationInfo) -> Path | None:
        if (value is None) != (info.data.get("control_server_key") is None):
            raise ValueError("control_server_key and control_client_keys go together: "
                             "set both to authenticate clients with CURVE, or neither")
        return value

    @field_validator("control_endpoint")
    @classmethod
    def _control_bind(cls, value: str | None, info: ValidationInfo) -> str | None:
        if value is None:
            return value
        zmq_endpoint(value)
        if not local_endpoint(value) and info.data.get("control_server_key") is None:
            raise ValueError("reaches beyond loopback without authentication: set "
                             "telemetry.control_server_key and telemetry.control_client_keys "
                             "(CURVE), or bind tcp://127.0.0.1:PORT")
        return value


class LoggingConfig(ConfigModel):
    """Console/JSON logging and the flight recorder."""

    level: Literal["debug", "info", "warning", "error"] = "info"
    format: Literal["auto", "console", "json"] = "auto"  # auto: console on a TTY, else JSON
    flight_log_dir: DirectoryPath = Path("flightlogs")
    # a directory, or one the recorder can make (with its parents)
    mcap: bool = False
    # gs fly also writes the flight as flight.mcap (gs export --format mcap) beside flight.npy
    # when the daemon closes its log (needs the analysis extra; the loop never waits)


class RealtimeConfig(ConfigModel):
    """What the daemon asks of the OS while it flies (see groundstation/app/realtime.py)."""

    cpu_dma_latency_us: Annotated[int, within(
        0, 10_000, "us: a wake-up latency longer than the 10 ms IMU period protects no "
        "tick (null asks nothing)")] | None = 0
    # PM QoS wake-up latency bound held while flying; 0 keeps the CPUs out of idle
    # states (measured: 3-6x cheaper ticks on a VM). null leaves the idle states alone
    fifo_priority: FifoPriority | None = 10
    # SCHED_FIFO priority of the flight loop and its threads while flying (needs
    # CAP_SYS_NICE or LimitRTPRIO; without, a warning and the normal policy). Under two
    # busy processes the normal policy let COMMAND gaps reach 114 ms; null
    # asks for nothing
    switch_interval_ms: Annotated[float, within(
        0.0, 5.0, "ms: the longest a reader thread may delay a 10 ms tick; Python's own "
        "default is 5 ms", lo_open=True)] = 0.5
    # GIL switch interval while flying: the longest a reader thread can delay a tick
    paced_gc: bool = True
    # freeze the start-up objects and run full garbage collections only right after a
    # COMMAND went out (realtime.CollectorPacer): the interpreter's own full collection
    # walked all ~93,000 objects in ~64 ms and the vehicle's 100 ms watchdog expired in
    # the air. false: the interpreter's own collector


class ApiConfig(ConfigModel):
    """Motions commanded at run time (``trajectory.name: none``; ``groundstation.client``,
    ``gs goto``): the flight takes off to ``trajectory.center`` and holds there until a
    client asks for a motion; each is checked against the safety limits and volume."""

    idle_land_s: Annotated[float, within(
        0.0, FLIGHT_MAX_S, "s: an hour of hovering outlasts any battery of the class",
        lo_open=True)] = 60.0
    # land after holding this long without a motion command [s]; tuned for experiments
    # driven from a notebook (a minute to type the next command)
    speed_m_s: Speed = 0.5
    # mean speed of a go-to without a duration [m/s]; the take-off's climb speed
    arrival_tolerance_m: LabLength = 0.05
    # a motion has arrived once its reference is at rest and the estimate this close [m]
    plan_timeout_s: Annotated[float, within(
        0.0, 60.0, "s: the longest motion plans in about 2 s; a minute's wait is a hung "
        "planner", lo_open=True)] = 5.0
    # longest a motion request may take to plan [s] (in the planner process, off the
    # flight loop): a plan not made by then is refused and the planner restarted. The
    # longest motion (600 s) takes about 2 s on the project's VM
    start_horizon_s: Annotated[float, within(
        0.0, FLIGHT_MAX_S, "s: a start beyond an hour outlasts any battery of the class",
        lo_open=True)] = 300.0
    # how far from now a follow's start_at may be [s]; a few minutes to line up clients


