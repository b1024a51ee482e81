"""``gs goto``, ``gs land``, ``gs hold`` and ``gs status``: the run-time API from the shell.

Each is one request to a daemon flying ``--trajectory none`` (:mod:`groundstation.client`),
in the project's frames: NED metres (1 m above the floor is ``-1``), headings in degrees
from north. Exit codes: 0 done; 1 refused (the daemon's reason on stderr), no daemon
answering, a wait that timed out or ended by a failsafe; 2 a usage error.

Options as everywhere in ``gs`` (:mod:`groundstation.cli.options`): ``--control`` the
daemon's request socket (formerly ``--endpoint``), ``--telemetry`` its publisher,
``--timeout`` the reply's wait (3 s), ``--wait-timeout`` how long ``--wait`` waits.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Annotated, Any

import typer

from groundstation.cli.options import (
    REPLY_TIMEOUT_S,
    WAIT_TIMEOUT_S,
    EndpointAlias,
    aliased,
    fail,
)
from groundstation.client import (
    DEFAULT_CONTROL,
    DEFAULT_TELEMETRY,
    Client,
    ClientError,
    Status,
)
from groundstation.errors import GroundStationError

Control = Annotated[str | None, typer.Option(
    "--control", help=f"The daemon's telemetry.control_endpoint (default {DEFAULT_CONTROL}; "
                      "--endpoint, its former spelling, still works).")]
Timeout = Annotated[float, typer.Option(help="Seconds to wait for the daemon's reply.")]
ServerKey = Annotated[Path | None, typer.Option(
    help="The daemon's public key (server.key) when it authenticates clients (CURVE).")]
ClientKey = Annotated[Path | None, typer.Option(
    help="This client's key pair (.key_secret) whose public half the daemon accepts.")]
Telemetry = Annotated[str, typer.Option(help="The daemon's telemetry.endpoint (for --wait).")]
WaitTimeout = Annotated[float, typer.Option(
    help="How long --wait waits [s] (goto: beyond the move's planned duration).")]

_fail = fail


def _client(control: str | None, endpoint: str | None, timeout: float,
            server_key: Path | None, client_key: Path | None,
            telemetry: str = DEFAULT_TELEMETRY) -> Client:
    """The client of ``--control`` (or its former spelling ``--endpoint``); exit 2 for a
    timeout that is not a positive number or keys that cannot be used."""
    address = aliased(control, endpoint, "--control", "--endpoint", DEFAULT_CONTROL)
    if not (math.isfinite(timeout) and timeout > 0):
        raise _fail(f"--timeout {timeout:g}: must be a positive number of seconds", 2)
    try:
        return Client(address, telemetry=telemetry, timeout_s=timeout,
                      server_key=server_key, client_key=client_key)
    except GroundStationError as exc:
        raise _fail(str(exc), 2) from exc


def _line(status: Status) -> str:
    """One line: state, position, reference, motion."""
    def xyz(v: tuple[float, float, float] | None) -> str:
        return "--" if v is None else f"({v[0]:+.2f}, {v[1]:+.2f}, {v[2]:+.2f}) m"
    motion = status.motion
    what = "no motion yet" if motion is None else \
        f"motion {motion.id} {motion.kind} {motion.state}"
    battery = "" if status.battery_v is None else f"  battery {status.battery_v:.2f} V"
    heading = "" if status.yaw_deg is None else f" heading {status.yaw_deg:+.0f} deg"
    return (f"{status.state}  at {xyz(status.position)}{heading}  reference "
            f"{xyz(status.reference)} heading {status.reference_yaw_deg:+.0f} deg  "
            f"{what}{battery}")


def goto(
    x: Annotated[float, typer.Argument(help="North [m].")],
    y: Annotated[float, typer.Argument(help="East [m].")],
    z: Annotated[float, typer.Argument(help="Down [m] (1 m above the floor is -1).")],
    yaw: Annotated[float | None, typer.Option(help="Heading to turn to [deg from north]; "
                                                   "default: keep it.")] = None,
    duration: Annotated[float | None, typer.Option(
        help="Seconds the move takes; default: sized by the daemon within its limits.")] = None,
    wait: Annotated[bool, typer.Option(help="Return once arrived.")] = False,
    wait_timeout: WaitTimeout = WAIT_TIMEOUT_S,
    control: Control = None, timeout: Timeout = REPLY_TIMEOUT_S,
    server_key: ServerKey = None, client_key: ClientKey = None,
    endpoint: EndpointAlias = None,
) -> None:
    """Move to X Y Z (NED metres in the lab's frame: from Tracker's origin on the floor, not
    from the take-off point) and hold there; refused (exit 1) with the daemon's reason
    when it cannot be flown.

    Example: `gs goto 0.5 0 -1 --yaw 90 --wait`.
    """
    for name, value in (("X", x), ("Y", y), ("Z", z), ("--yaw", yaw), ("--duration", duration)):
        if value is not None and not math.isfinite(value):
            raise _fail(f"{name} {value}: must be a finite number", 2)
    if yaw is not None and not abs(yaw) <= 360.0:
        raise _fail(f"--yaw {yaw:g}: a heading within one turn, [-360, 360] degrees", 2)
    if duration is not None and not duration > 0.0:
        raise _fail(f"--duration {duration:g}: a positive number of seconds", 2)
    if not (math.isfinite(wait_timeout) and wait_timeout > 0.0):
        raise _fail(f"--wait-timeout {wait_timeout:g}: a positive number of seconds", 2)
    client = _client(control, endpoint, timeout, server_key, client_key)
    try:
        motion = client.go_to([x, y, z], yaw_deg=yaw, duration=duration)
        if wait:
            arrived = client.wait_until_arrived(motion, motion.duration_s + wait_timeout)
            motion = arrived.motion or motion
    except ClientError as exc:
        raise _fail(str(exc), 1) from exc
    typer.echo(f"motion {motion.id}: {motion.kind} to ({x:+.2f}, {y:+.2f}, {z:+.2f}) m "
               f"in {motion.duration_s:.1f} s: {motion.state}")


def land(
    wait: Annotated[bool, typer.Option(help="Return once landed and handed back.")] = False,
    wait_timeout: WaitTimeout = WAIT_TIMEOUT_S,
    control: Control = None, telemetry: Telemetry = DEFAULT_TELEMETRY,
    timeout: Timeout = REPLY_TIMEOUT_S,
    server_key: ServerKey = None, client_key: ClientKey = None,
    endpoint: EndpointAlias = None,
) -> None:
    """Land now: the flight ends normally (the daemon exits 0 once handed back). With
    --wait, exit 0 only once it has landed and handed back without a failsafe."""
    if not (math.isfinite(wait_timeout) and wait_timeout > 0.0):
        raise _fail(f"--wait-timeout {wait_timeout:g}: a positive number of seconds", 2)
    client = _client(control, endpoint, timeout, server_key, client_key, telemetry)
    try:
        ended = client.land(wait=wait, timeout=wait_timeout)
    except ClientError as exc:
        raise _fail(str(exc), 1) from exc
    if ended is None:
        typer.echo("landing")
        return
    if ended.outcome != "COMPLETED":
        raise _fail(f"the flight ended in {ended.state} ({ended.outcome}): {ended.reason}", 1)
    typer.echo(f"{ended.state}: {ended.reason}")


def hold(
    control: Control = None, timeout: Timeout = REPLY_TIMEOUT_S,
    server_key: ServerKey = None, client_key: ClientKey = None,
    endpoint: EndpointAlias = None,
) -> None:
    """Stop the motion in progress as soon as the limits allow and hold there."""
    client = _client(control, endpoint, timeout, server_key, client_key)
    try:
        motion = client.hold()
    except ClientError as exc:
        raise _fail(str(exc), 1) from exc
    x, y, z = motion.target
    typer.echo(f"motion {motion.id}: holding at ({x:+.2f}, {y:+.2f}, {z:+.2f}) m")


def status(
    as_json: Annotated[bool, typer.Option(
        "--json", help="The whole reply as JSON (as on the wire: headings in radians).")]
        = False,
    control: Control = None, timeout: Timeout = REPLY_TIMEOUT_S,
    server_key: ServerKey = None, client_key: ClientKey = None,
    endpoint: EndpointAlias = None,
) -> None:
    """The flight now: supervisor state, estimate, reference, motion, battery."""
    client = _client(control, endpoint, timeout, server_key, client_key)
    try:
        now = client.status()
    except ClientError as exc:
        raise _fail(str(exc), 1) from exc
    raw: dict[str, Any] = dict(now.raw)
    typer.echo(json.dumps(raw, indent=2) if as_json else _line(now))


def keys(
    directory: Annotated[Path, typer.Argument(help="Where to write the key pair.")],
    name: Annotated[str, typer.Option(help="Whose keys: 'server' for the daemon, a user's "
                                           "or machine's name for a client.")] = "client",
) -> None:
    """Generate a CURVE key pair (pyzmq's certificate files): NAME.key (public, give it
    away) and NAME.key_secret (keep it). The daemon's pair goes in
    telemetry.control_server_key (the .key_secret); each client's NAME.key goes in the
    directory telemetry.control_client_keys names. Never overwrites a key."""
    import zmq.auth

    if not name or any(c in name for c in "/\\") or name.startswith("."):
        raise _fail(f"--name {name!r}: a plain file name", 2)
    public, secret = directory / f"{name}.key", directory / f"{name}.key_secret"
    existing = [str(p) for p in (public, secret) if p.exists()]
    if existing:
        raise _fail(f"{', '.join(existing)} already there: keys are never overwritten", 2)
    try:
        directory.mkdir(parents=True, exist_ok=True)
        zmq.auth.create_certificates(directory, name)
        secret.chmod(0o600)
    except OSError as exc:
        raise _fail(f"{directory}: {exc.strerror or exc}", 2) from exc
    typer.echo(f"public key: {public}\nsecret key: {secret} (keep it private)")


def register(app: typer.Typer) -> None:
    """Add the commands to ``gs``."""
    # a negative coordinate is an argument, not an unknown option (`gs goto 0.5 0 -1`)
    app.command(context_settings={"ignore_unknown_options": True})(goto)
    for command in (land, hold, status, keys):
        app.command()(command)
