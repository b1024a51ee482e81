"""``gs fleet ...`` and ``gs vicon-relay``: a fleet is one file and one command.

=====================================  ===================================================
``gs vicon-relay FLEET``               receive Tracker's stream once, publish every object
``gs fleet check FLEET``               check the fleet file (exit 2 naming each problem)
``gs fleet up FLEET``                  this PC's relay and one daemon per vehicle
``gs fleet fly FLEET VEHICLE``         one vehicle's daemon (the systemd template unit's)
``gs fleet status FLEET``              every vehicle's status, asked at once
``gs fleet land FLEET [--wait]``       land every vehicle, all at once
``gs fleet demo [--vehicles N]``       three virtual vehicles fly figure-eights in phase
=====================================  ===================================================

Exit codes: ``gs fleet fly`` as ``gs fly``; ``gs fleet up`` the most urgent of its
daemons' (:func:`~groundstation.fleetops.manager.fleet_exit_code`); the others 0 done, 1 a
vehicle refused, did not answer or did not land as asked, 2 a bad fleet file or usage.

The fleet file is read by :mod:`groundstation.config.fleetfile`; a vehicle's daemon and
the relay get their parameters from :mod:`groundstation.flight.assembly` (``assemble``,
``relay_params``), as ``gs fly`` does; the processes of ``gs fleet up`` and the demo are
:mod:`groundstation.fleetops`, the Python client :class:`groundstation.client.Fleet`.
"""

from __future__ import annotations

import json
import math
import threading
import time
from pathlib import Path
from typing import Annotated, Any

import typer

from groundstation.cli.options import REPLY_TIMEOUT_S, WAIT_TIMEOUT_S, JsonOption, fail
from groundstation.errors import ConfigError, GroundStationError

fleet_app = typer.Typer(help="Several vehicles on one Vicon: a fleet on Zenoh (README "
                             "'Fleet').", no_args_is_help=True, rich_markup_mode=None)

FleetFileArg = Annotated[Path, typer.Argument(
    metavar="FLEET", help="The fleet file (fleet.yaml: the vehicles over a base configuration).")]
Timeout = Annotated[float, typer.Option(help="Seconds to wait for the vehicles' replies.")]
Identity = Annotated[str | None, typer.Option(
    help="With TLS: this client's certificate name in the fleet's tls_directory (default: "
         "the first operator).")]


def _load(path: Path) -> Any:
    from groundstation.config.fleetfile import load_fleet

    try:
        return load_fleet(path)
    except ConfigError as exc:
        raise fail(str(exc), 2) from exc


def vicon_relay(
    fleet: FleetFileArg,
    seconds: Annotated[float | None, typer.Option(
        "--seconds", min=0.0, help="Stop after this many seconds (default: until Ctrl-C).")]
        = None,
) -> None:
    """Receive the Vicon Tracker's UDP object stream once and publish every object's item
    on Zenoh (key <fleet>/vicon/<object>) for the fleet's daemons (vicon.source: zenoh).

    Binds the base configuration's vicon.bind_address and vicon.port; listens on the fleet
    file's relay.listen endpoint. Exit 1 if the port or the endpoint is taken.
    """
    from groundstation.app.signals import on_stop_signals
    from groundstation.fleet.relay import run_relay
    from groundstation.fleet.session import Membership, open_session
    from groundstation.flight.assembly import relay_params
    from groundstation.logs import configure_logging
    from groundstation.vicon.plausibility import Plausibility

    spec, base = _load(fleet)
    if spec.relay is None:
        raise fail(f"{fleet}: relay: null: this fleet's daemons read the UDP stream "
                   "themselves", 2)
    configure_logging(base.logging.level, base.logging.format)
    params = relay_params(spec, base)  # every vehicle's volume, the relay's endpoint
    stop = threading.Event()
    try:
        session = open_session(params.zenoh, Membership(
            params.fleet, params.vehicles, operators=params.zenoh.operators))
    except GroundStationError as exc:
        raise fail(str(exc), 1) from exc
    timer = threading.Timer(seconds, stop.set) if seconds is not None else None
    try:
        with on_stop_signals(lambda _sig: stop.set()):
            if timer is not None:
                timer.start()
            stats = run_relay(
                session, params.fleet, params.bind_address, params.port,
                Plausibility.create(params.plausible_volume), stop,
                on_ready=lambda r: typer.echo(
                    f"vicon relay: udp://{r.address[0]}:{r.address[1]} -> "
                    f"{spec.fleet}/vicon/<object> on {spec.relay.listen}"))
    except GroundStationError as exc:
        raise fail(str(exc), 1) from exc
    finally:
        if timer is not None:
            timer.cancel()
        session.close()  # type: ignore[no-untyped-call]  # zenoh's stub: unannotated
    typer.echo(f"vicon relay stopped: {stats.datagrams} datagrams, items relayed "
               f"{dict(stats.items)}, {stats.non_finite + stats.implausible} refused")


@fleet_app.command("check")
def check(fleet: FleetFileArg) -> None:
    """Check a fleet file: unique names, serial ports, Vicon objects and endpoints; homes
    inside their volumes and the separation apart; volumes that overlap only with the
    separation on; every vehicle's configuration valid. Exit 2 naming each problem."""
    spec, base = _load(fleet)
    for name in spec.names:
        cfg = spec.vehicle_config(base, name)
        assert cfg.fleet is not None
        typer.echo(f"{name}: {cfg.serial.port}, Vicon object {cfg.vicon.object_name} "
                   f"({cfg.vicon.source}), home {cfg.trajectory.center[:2]}, keys "
                   f"{spec.fleet}/{name}/..., Zenoh {cfg.fleet.zenoh.listen[0]}")
    sep = "off" if spec.separation_m is None else f"{spec.separation_m:g} m"
    typer.echo(f"{fleet}: valid: {len(spec.names)} vehicles, separation {sep}")


@fleet_app.command("fly")
def fly(
    fleet: FleetFileArg,
    vehicle: Annotated[str, typer.Argument(help="The vehicle's name in the fleet file.")],
    serial_port: Annotated[str | None, typer.Option(help="Serial device or URL.")] = None,
) -> None:
    """Fly one vehicle of the fleet: its daemon, as `gs fly --trajectory none` with the
    configuration the fleet file gives it (the systemd unit groundstation@VEHICLE runs
    this). Exit codes as gs fly."""
    from groundstation.app.fly import EXIT_USAGE, fly_command
    from groundstation.config import apply_overrides
    from groundstation.flight.assembly import assemble, check_config
    from groundstation.logs import configure_logging

    spec, base = _load(fleet)
    try:
        cfg = spec.vehicle_config(base, vehicle)
        if serial_port is not None:
            cfg = apply_overrides(cfg, {"serial.port": serial_port})
        cfg = check_config(cfg, f"{fleet}: {vehicle}")
    except ConfigError as exc:
        raise fail(str(exc), 2) from exc
    configure_logging(cfg.logging.level, cfg.logging.format)
    try:
        params = assemble(cfg)
    except (GroundStationError, ValueError) as exc:
        raise fail(str(exc), EXIT_USAGE) from exc
    raise typer.Exit(fly_command(params))


@fleet_app.command("up")
def up(
    fleet: FleetFileArg,
    vehicle: Annotated[list[str] | None, typer.Option(
        help="Fly only this vehicle (repeatable; default: every vehicle whose host is this "
             "PC or unset).")] = None,
    no_relay: Annotated[bool, typer.Option(
        "--no-relay", help="Do not start the relay (by default it starts here if the "
                           "fleet has one and its host is this PC).")] = False,
) -> None:
    """Start this PC's part of the fleet: the relay, then one daemon per vehicle, each a
    process of its own; their lines are echoed with their names. Ctrl-C (SIGINT,
    SIGTERM) lands every vehicle, a second one at least 0.5 s later hands them back; the
    relay stops once every daemon has ended.

    Exit 0 when every daemon exited 0, else the most urgent of their codes: 1, 5, 3, 2,
    4 (gs fly's).
    """
    from groundstation.app.signals import on_stop_signals
    from groundstation.config.fleetfile import on_this_host
    from groundstation.fleetops.manager import FleetProcesses, fleet_exit_code

    spec, _base = _load(fleet)
    names = vehicle or [v.name for v in spec.vehicles if on_this_host(v.host)]
    for name in names:
        if name not in spec.names:
            raise fail(f"--vehicle {name}: not in the fleet ({', '.join(spec.names)})", 2)
    start_relay = not no_relay and spec.relay is not None and on_this_host(spec.relay.host)
    if not names and not start_relay:
        raise fail(f"{fleet}: nothing of the fleet runs on this host", 2)
    processes = FleetProcesses(fleet, names, relay=start_relay, echo=typer.echo)
    with on_stop_signals(processes.signal_daemons):
        processes.start()
        codes = processes.wait()
    for name, code in codes.items():
        typer.echo(f"{name}: exit {code}")
    raise typer.Exit(fleet_exit_code(codes))


def _client(fleet: Path, identity: str | None, timeout: float) -> Any:
    from groundstation.client import Fleet

    if not (math.isfinite(timeout) and timeout > 0):
        raise fail(f"--timeout {timeout:g}: must be a positive number of seconds", 2)
    try:
        return Fleet(fleet, identity=identity, timeout_s=timeout)
    except ConfigError as exc:
        raise fail(str(exc), 2) from exc
    except GroundStationError as exc:
        raise fail(str(exc), 1) from exc


@fleet_app.command("status")
def status(fleet: FleetFileArg, json_output: JsonOption = False,
           timeout: Timeout = REPLY_TIMEOUT_S, identity: Identity = None) -> None:
    """Every vehicle's status, asked of all at once: state, position, reference, motion,
    battery. Exit 1 if a vehicle does not answer."""
    from groundstation.cli.api import _line
    from groundstation.client import Status

    with _client(fleet, identity, timeout) as client:
        replies = client.status()
    missing = 0
    for name, reply in replies.items():
        if isinstance(reply, Status):
            typer.echo(json.dumps({"vehicle": name, **reply.raw}) if json_output
                       else f"{name}: {_line(reply)}")
        else:
            missing += 1
            typer.echo(json.dumps({"vehicle": name, "error": str(reply)}) if json_output
                       else f"{name}: no answer: {reply}")
    raise typer.Exit(1 if missing else 0)


@fleet_app.command("land")
def land(
    fleet: FleetFileArg,
    wait: Annotated[bool, typer.Option(
        help="Wait until every vehicle has landed and been handed back.")] = False,
    wait_timeout: Annotated[float, typer.Option(help="How long --wait waits [s].")]
        = WAIT_TIMEOUT_S,
    timeout: Timeout = REPLY_TIMEOUT_S, identity: Identity = None,
) -> None:
    """Land every vehicle of the fleet, all at once (one query to all). Exit 0 when every
    vehicle accepted (with --wait: landed and handed back, no failsafe), else 1 naming
    the ones that did not."""
    from groundstation.client import Ended

    with _client(fleet, identity, timeout) as client:
        results = client.land(wait=wait, timeout=wait_timeout)
    bad = 0
    for name, result in results.items():
        if isinstance(result, Ended):
            good = result.state == "DONE" and result.outcome == "COMPLETED"
            typer.echo(f"{name}: ended {result.state} ({result.outcome}): {result.reason}")
        elif isinstance(result, dict) and result.get("ok"):
            good = True
            typer.echo(f"{name}: landing (from {result.get('state')})")
        else:
            good = False
            why = result.get("error") if isinstance(result, dict) else result
            typer.echo(f"{name}: {why}")
        bad += not good
    raise typer.Exit(1 if bad else 0)


@fleet_app.command("demo")
def demo(
    vehicles: Annotated[int, typer.Option(min=1, max=3, help="How many virtual vehicles "
                                                            "(the lab's volume holds three "
                                                            "eights).")] = 3,
    config: Annotated[Path, typer.Option(
        "--config", "-c", help="YAML configuration file with a sim: section (the base).")]
        = Path("config/sim.yaml"),
    out_dir: Annotated[Path | None, typer.Option(
        "--out-dir", help="Directory for the fleet files, logs and truths (default: a new "
                          "one under flightlogs/).")] = None,
) -> None:
    """Fly a virtual fleet through the relay: the virtual lab with N vehicles and one
    Vicon stream, gs vicon-relay, one daemon per vehicle; the vehicles take off, fly one
    figure-eight each, in phase, and land; each one's tracking is judged against the
    virtual lab's ground truth. Exit as gs fleet up."""
    from groundstation.app.signals import on_stop_signals
    from groundstation.fleetops.demo import run_demo
    from groundstation.fleetops.manager import fleet_exit_code

    stop = threading.Event()
    workdir = out_dir or Path("flightlogs") / time.strftime("fleet-demo-%Y%m%dT%H%M%S")
    try:
        with on_stop_signals(lambda _sig: stop.set()):
            codes = run_demo(config, vehicles, workdir, echo=typer.echo, stop=stop)
    except ConfigError as exc:
        raise fail(str(exc), 2) from exc
    except GroundStationError as exc:
        raise fail(str(exc), 1) from exc
    raise typer.Exit(fleet_exit_code(codes))


def register(app: typer.Typer) -> None:
    """Add ``gs fleet ...`` and ``gs vicon-relay`` to ``app``."""
    app.add_typer(fleet_app, name="fleet")
    app.command("vicon-relay")(vicon_relay)

