"""What the ``gs`` commands share: one name per meaning, the choices, the former spellings.

One option name means one thing across the whole command set:

==================  ==========================================================================
``--config/-c F``   the configuration a command reads (``gs check-config F`` keeps the
                    positional form)
``--control E``     the daemon's request socket, ``telemetry.control_endpoint``
                    (goto, hold, land, status, channels); formerly ``--endpoint``
``--telemetry E``   the daemon's telemetry publisher, ``telemetry.endpoint`` (monitor,
                    foxglove, ``land --wait``); formerly ``--endpoint`` on monitor and foxglove
``--timeout S``     how long a request waits for the daemon's reply, 3 s everywhere
``--wait-timeout S``  how long ``--wait`` waits (goto, land, fleet land), 60 s; for goto beyond the
                    move's planned time
``--duration S``    how long the vehicle's motion lasts (``gs fly``: on the trajectory;
                    ``gs goto``: the move)
``--seconds S``     how long a command runs or measures (monitor, foxglove, sim-device,
                    calibrate); formerly ``--duration`` on monitor, foxglove and sim-device
``--out F``         a file the command writes (export, synth hinf)
``--out-dir D``     a directory the command writes into (report, eval, calibrate, identify,
                    verify-model); formerly ``--out``
==================  ==========================================================================

The former spellings still work (a user's scripts may use them); they are hidden options
that feed the same value, and each option's help names its former spelling.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Literal, TypeVar

import typer

from groundstation.config import ControllerType
from groundstation.control.trajectories import TRAJECTORY_NAMES
from groundstation.types import Dialect as SerialDialect

T = TypeVar("T")

REPLY_TIMEOUT_S = 3.0
"""``--timeout``: how long a request waits for the daemon's reply [s] (every command that
talks to the request socket)."""
WAIT_TIMEOUT_S = 60.0
"""``--wait-timeout``: how long ``gs land --wait`` waits, and ``gs goto --wait`` beyond the
move's planned duration [s]."""

Controller = ControllerType
"""``--controller``: the values of ``controller.type``."""
Dialect = SerialDialect
"""``--protocol``: the values of ``serial.protocol``."""
ExportFormat = Literal["csv", "parquet", "mcap"]
MotorAction = Literal["start", "stop"]
ScaleAxis = Literal["gyro_x", "gyro_y", "gyro_z", "acc_x", "acc_y", "acc_z"]
"""``gs identify scales --axis``: the identification's SCALE_AXES (a test checks)."""

TRAJECTORY_CHOICES = (*TRAJECTORY_NAMES, "none")
"""What ``--trajectory`` takes besides a file: every built-in name and ``none``."""
TRAJECTORY_HELP = (
    f"A built-in trajectory: {', '.join(TRAJECTORY_CHOICES)} (none: take off, hold, and "
    "fly what gs goto and the Python client ask for; waypoints: the file "
    "trajectory.file names); or a trajectory file: a waypoint CSV (t,x,y,z[,yaw_deg]) "
    "or a uav_trajectories / Crazyswarm polynomial CSV (see gs trajectory).")

ConfigOption = Annotated[Path, typer.Option("--config", "-c", help="YAML configuration file.")]
JsonOption = Annotated[bool, typer.Option(
    "--json", help="Print one JSON object keyed by the configuration's field names.")]
ProtocolOption = Annotated[Dialect | None, typer.Option(
    "--protocol", help="The vehicle's serial dialect (serial.protocol).")]

# the former spellings: hidden, each option's help names them
OutAlias = Annotated[Path | None, typer.Option("--out", hidden=True)]
DurationAlias = Annotated[float | None, typer.Option("--duration", hidden=True)]
EndpointAlias = Annotated[str | None, typer.Option("--endpoint", hidden=True)]


def fail(message: str, code: int) -> typer.Exit:
    """``raise fail(message, code)``: print ``error: message`` (every line of it so
    prefixed) on stderr and exit with ``code``."""
    for line in message.splitlines() or [""]:
        typer.echo(f"error: {line}", err=True)
    return typer.Exit(code)


def aliased(value: T | None, former: T | None, name: str, former_name: str,
            default: T) -> T:
    """The value of an option given as ``name`` or under its former spelling
    ``former_name`` (exit 2 if both are given and differ), else ``default``."""
    if value is not None and former is not None and value != former:
        raise fail(f"{name} and {former_name} (its former spelling) give different values", 2)
    chosen = value if value is not None else former
    return default if chosen is None else chosen
