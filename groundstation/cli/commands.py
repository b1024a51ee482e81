"""The `gs` commands (their options: :mod:`groundstation.cli.options`; the run-time API's:
:mod:`groundstation.cli.api`).

Each command is a thin shell: parse options, load the configuration, call the
package. :func:`main` (the console entry point) is the one error boundary around
all of them: a one-line ``error: ...`` and a documented exit code, never a
traceback, for a user's mistake. Exit codes: 0 success; 1 runtime failure (also a
missing optional package); 2 bad configuration, usage, or a file that cannot be
used; `gs fly` adds 3 (could not start), 4 (stopped on request) and 5 (flight log
incomplete), see its help;
130 Ctrl-C; 141 the reader of the output went away (``gs export LOG | head``).

Option names mean one thing across the commands (:mod:`groundstation.cli.options`), and
help is plain text (no rich markup: it would eat ``[hinf]`` and ``[m]``); help texts use
single backquotes, never reST's double ones.
"""

from __future__ import annotations

import math
import os
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, Literal, NoReturn, get_args

import typer

from groundstation import __version__
from groundstation.cli.options import (
    REPLY_TIMEOUT_S,
    TRAJECTORY_CHOICES,
    TRAJECTORY_HELP,
    Controller,
    Dialect,
    DurationAlias,
    EndpointAlias,
    ExportFormat,
    JsonOption,
    MotorAction,
    OutAlias,
    ScaleAxis,
    aliased,
    fail,
)
from groundstation.cli.options import ConfigOption as ConfigOption
from groundstation.cli.options import ProtocolOption as ProtocolOption
from groundstation.client import DEFAULT_CONTROL, DEFAULT_TELEMETRY
from groundstation.config import (
    GroundStationConfig,
    VehicleConfig,
    apply_overrides,
    dump_config,
    key_lines,
    load_config,
)
from groundstation.errors import (
    ConfigError,
    GroundStationError,
    IdentificationError,
    RecorderError,
)
from groundstation.logs import configure_logging
from groundstation.types import Channel as ChannelName

if TYPE_CHECKING:
    from groundstation.flight.params import FlightParams

# plain help (rich_markup_mode None): rich markup would eat "[hinf]", "[m]" and "[deg]"
app = typer.Typer(
    name="gs",
    help="Ground station for the AscTec X-3D in a Vicon lab.",
    no_args_is_help=True,
    add_completion=False,
    rich_markup_mode=None,
)
identify_app = typer.Typer(help="Identify model parameters from measurements and flight logs.",
                           no_args_is_help=True, rich_markup_mode=None)
app.add_typer(identify_app, name="identify")
synth_app = typer.Typer(help="Synthesise controller gains.", no_args_is_help=True,
                        rich_markup_mode=None)
app.add_typer(synth_app, name="synth")
calibrate_app = typer.Typer(help="Calibrate a vehicle at rest: IMU zeros and noise, Vicon.",
                            no_args_is_help=True, rich_markup_mode=None)
app.add_typer(calibrate_app, name="calibrate")

_fail = fail
"""``raise _fail(message, code)``: ``error: message`` on stderr, exit ``code``
(:func:`groundstation.cli.options.fail`)."""


def _checked_config(path: Path, overrides: dict[str, Any] | None = None) -> GroundStationConfig:
    """The configuration a command runs with: the file, the CLI overrides, and what the
    assembly checks (the files it names: waypoints, gain, CURVE keys; the virtual lab's
    section). ConfigError naming each problem."""
    from groundstation.flight.assembly import check_config

    config = load_config(path)
    if overrides:
        config = apply_overrides(config, overrides)
    return check_config(config, str(path), key_lines(path))


def load(path: Path, overrides: dict[str, Any] | None = None) -> GroundStationConfig:
    """Load the configuration and apply CLI overrides; exit 2 with the errors if invalid."""
    try:
        config = _checked_config(path, overrides)
    except ConfigError as exc:
        raise _fail(str(exc), 2) from exc
    configure_logging(config.logging.level, config.logging.format)
    return config


@app.command()
def version() -> None:
    """Print the version."""
    typer.echo(__version__)


@app.command("check-config")
def check_config(
    file: Annotated[Path | None, typer.Argument(
        help="The configuration file, as --config gives it (this positional form is kept "
             "for scripts that use it).", show_default=False)] = None,
    config: Annotated[Path | None, typer.Option(
        "--config", "-c", help="YAML configuration file.")] = None,
    show: Annotated[bool, typer.Option(
        "--show", help="Also print the configuration with every default filled in, and the "
                       "trajectory's check as YAML comments.")] = False,
) -> None:
    """Validate a configuration: exit 0 and one verdict line if `gs fly` would start with
    it, else one line per problem (the field, its line in the file, the reason), a
    verdict line with the count, and exit 2.

    Runs the checks `gs fly` runs before connecting to anything: the file, the files it
    names (waypoint CSV, H-infinity gain, CURVE keys), and the flight built from it
    (estimator, controller, the trajectory shaped and checked against the limits and
    the volume).
    """
    from groundstation.flight.assembly import assemble
    from groundstation.flight.core import FlightCore

    if file is not None and config is not None and file != config:
        raise _fail(f"two configurations given ({file} and --config {config}): check one "
                    "at a time", 2)
    path = config if config is not None else file
    if path is None:
        raise _fail("check-config needs the configuration: gs check-config --config FILE", 2)
    configure_logging("warning")  # the verdict says what the flight's info lines would
    try:
        cfg = _checked_config(path)
        params = assemble(cfg)
        FlightCore(params)
        lines = _trajectory_check(params)[0] if not params.commanded else []
    except (GroundStationError, ValueError, ArithmeticError) as exc:
        lines = [line for line in str(exc).splitlines() if line.strip()]
        # a ConfigError: one line per problem; a refused trajectory: a title, then one
        # indented line per broken limit
        count = len(lines) if isinstance(exc, ConfigError) else \
            max(1, sum(line.startswith(" ") for line in lines))
        _fail("\n".join(lines), 2)
        typer.echo(f"{path}: invalid, {count} problem{'s' if count > 1 else ''}", err=True)
        raise typer.Exit(2) from exc
    verdict = f"{path}: valid: {_config_summary(cfg, lines)}"
    if not show:
        typer.echo(verdict)
        return
    typer.echo(dump_config(cfg), nl=False)
    for line in [*lines, verdict]:  # YAML comments: the output stays a configuration file
        typer.echo(f"# {line}")


def _config_summary(config: GroundStationConfig, check: list[str]) -> str:
    """What a valid configuration flies, in a few words (the verdict line's tail)."""
    t = config.trajectory
    what = "trajectory none (run-time commands)" if t.name == "none" else \
        f"trajectory {t.name}" + (f" ({t.file})" if t.file is not None else "")
    verdict = next((line.split("verdict: ", 1)[1] for line in check if "verdict: " in line),
                   None)
    lab = ", virtual lab (sim)" if config.sim is not None else ""
    return (f"{what}{': ' + verdict if verdict else ''}; controller {config.controller.type}, "
            f"serial {config.serial.protocol}{lab}")


def _trajectory_overrides(target: str) -> dict[str, Any]:
    """``trajectory.*`` overrides for a ``--trajectory`` value: a ``.csv`` (or an existing
    file) is a trajectory file (waypoints or polynomial segments), anything else a name."""
    if Path(target).suffix.lower() == ".csv" or Path(target).is_file():
        return {"trajectory.name": "waypoints", "trajectory.file": target}
    return {"trajectory.name": target}


def _trajectory_check(params: FlightParams) -> tuple[list[str], Any]:
    """The lines of the flight's trajectory check (:mod:`groundstation.control.summary`)
    and the prepared trajectory; TrajectoryError if it cannot be built."""
    from groundstation.control.summary import check_lines
    from groundstation.flight.prepare import prepare_trajectory

    prepared = prepare_trajectory(params)
    lines = check_lines(prepared.trajectory.name, prepared.description, prepared.duration_s,
                        prepared.report, params.limits, params.volume)
    return lines, prepared


@app.command("trajectory")
def trajectory_command(
    target: Annotated[str, typer.Argument(
        help="A trajectory file (waypoint CSV t,x,y,z[,yaw_deg] or a uav_trajectories / "
             "Crazyswarm polynomial CSV) or a built-in trajectory: "
             f"{', '.join(n for n in TRAJECTORY_CHOICES if n != 'none')}.")],
    config: Annotated[Path | None, typer.Option(
        "--config", "-c", help="YAML configuration (limits, volume, centre); default: the "
        "built-in defaults.")] = None,
    plot: Annotated[Path | None, typer.Option(
        help="Draw it into this PNG: top view, speed and tilt over time with the limits.")]
        = None,
) -> None:
    """Check a trajectory as `gs fly` would fly it, without flying: what it was taken to be
    (dense samples fitted with a curve, corners, polynomial segments), its peaks (speed,
    acceleration, jerk, tilt, tilt rate, yaw rate, lift, extent) against the limits, and
    the verdict. Exit 0 if it is flyable, 2 if it is refused or cannot be read."""
    from groundstation.config import validate_config
    from groundstation.flight.assembly import assemble

    if target == "none":
        raise _fail("trajectory none: flown by run-time commands (gs goto ...), each "
                    "checked when it is asked for", 2)
    overrides = _trajectory_overrides(target)
    try:
        cfg = _checked_config(config, overrides) if config is not None else \
            apply_overrides(validate_config({}), overrides)
        if config is None:
            from groundstation.flight.assembly import check_config

            cfg = check_config(cfg, "<defaults>")
        params = assemble(cfg)
        lines, prepared = _trajectory_check(params)
    except (GroundStationError, ValueError, ArithmeticError) as exc:
        raise _fail(str(exc), 2) from exc
    for line in lines:
        typer.echo(line)
    if plot is not None:
        from groundstation.evaluation.trajectory_figure import trajectory_figure

        try:
            trajectory_figure(prepared.trajectory, prepared.duration_s,
                              params.limits, params.volume, plot,
                              title=f"{target}: top view")
            typer.echo(f"figure: {plot}")
        except GroundStationError as exc:  # matplotlib missing: the check still counts
            typer.echo(f"no figure: {exc}", err=True)
        except OSError as exc:
            raise _fail(f"{plot}: cannot write the figure: {exc.strerror}", 2) from exc
    if not prepared.report.feasible:
        raise typer.Exit(2)


@app.command()
def fly(
    config: ConfigOption,
    serial_port: Annotated[str | None, typer.Option(help="Serial device or URL.")] = None,
    vicon_port: Annotated[int | None, typer.Option(help="Vicon UDP port.")] = None,
    vicon_object: Annotated[str | None, typer.Option(help="Vicon object name.")] = None,
    trajectory: Annotated[str | None, typer.Option(
        metavar="NAME|FILE", help=TRAJECTORY_HELP)] = None,
    controller: Annotated[Controller | None, typer.Option(
        help="The controller (controller.type).")] = None,
    duration: Annotated[float | None, typer.Option(
        help="Seconds on the trajectory before landing [s] (default: one period).")] = None,
    log_dir: Annotated[Path | None, typer.Option(help="Flight-log directory.")] = None,
    demo: Annotated[bool, typer.Option(
        help="Start the virtual lab (needs a `sim:` section) and fly it.")] = False,
    protocol: ProtocolOption = None,
) -> None:
    """Fly: preflight, take off, track the trajectory, land, hand back to the pilot.

    SIGINT, SIGTERM, SIGHUP (the terminal went away) and SIGQUIT land; a
    second one (not SIGHUP) at least safety.second_signal_after_s (0.5 s) after
    the first hands back at once.

    \b
    Exit codes:
    0  mission completed: landed and handed back, no failsafe
    1  failsafe or abort: failsafe landing or handback (Vicon lost, volume,
       tilt, low battery, take-off timeout), pilot takeover, the vehicle's
       watchdog expired in the air, link lost, preflight failed, internal error
    2  configuration or usage error, or a trajectory refused before flight
    3  could not start: serial port absent or in use by another flight, Vicon
       or telemetry port taken, no flight-log directory writable (nothing was
       sent to the vehicle)
    4  stopped on request (SIGINT/SIGTERM, SIGHUP, SIGQUIT): landed, or handed
       back at a second request
    5  flight log incomplete: flown without a failsafe, but rows were lost (disk
       full, I/O error) or meta.json not written; before 0 and 4, never before 1
    """
    overrides: dict[str, Any] = {
        "serial.port": serial_port, "vicon.port": vicon_port, "vicon.object_name": vicon_object,
        "controller.type": controller, "serial.protocol": protocol,
        "logging.flight_log_dir": str(log_dir) if log_dir else None,
    }
    overrides.update(_trajectory_overrides(trajectory) if trajectory is not None
                     else {"trajectory.name": None})
    cfg = load(config, overrides)
    from groundstation.app.fly import EXIT_USAGE, AfterFlight, fly_command
    from groundstation.flight.assembly import assemble

    try:
        params = assemble(cfg)
    except (GroundStationError, ValueError) as exc:
        raise _fail(str(exc), EXIT_USAGE) from exc
    after: list[AfterFlight] = []  # once the log is closed and the vehicle the pilot's
    if params.daemon.mcap:
        from groundstation.export import mcap_after_flight

        after.append(mcap_after_flight)
    if demo:
        from groundstation.evaluation.report import report_after_flight

        after.append(report_after_flight)
    raise typer.Exit(fly_command(params, duration_s=duration, demo=demo,  # never blocking
                                 after_flight=after))


@app.command()
def motors(
    action: Annotated[str, typer.Argument(help="start or stop: what to do with the motors.")],
    config: ConfigOption,
    serial_port: Annotated[str | None, typer.Option(help="Serial device or URL.")] = None,
    protocol: Annotated[Dialect | None, typer.Option(
        help="The vehicle's serial dialect (serial.protocol); the gesture is asctec-ll's.")
    ] = None,
) -> None:
    """Start or stop the motors with the AscTec LL stick gesture, on this request only.

    Refused while a flight holds the serial port or while the vehicle reports it is
    flying; the gesture (thrust 0, yaw full one way, serial.ll.motor_gesture_s) is
    followed by a hand-back (ctrl mask 0). Exit 0 when the vehicle reports the motors
    in the state asked for, 1 when it does not or refused, 2 on a usage error.
    """
    if action not in get_args(MotorAction):
        raise _fail(f"motors: expected start or stop, got {action!r}", 2)
    cfg = load(config, {"serial.port": serial_port, "serial.protocol": protocol})
    from groundstation.app.motors import motor_gesture_command
    from groundstation.flight.assembly import link_params

    raise typer.Exit(motor_gesture_command(link_params(cfg.serial), start=action == "start",
                                           echo=typer.echo))


def _flight_log(path: Path) -> Path:
    """``path`` if it is a flight log (a flight's directory, or its flight.npy); exit 2
    with one line naming it if it is not there or not one."""
    from groundstation.app.recorder import CONFIG_FILE, FLIGHT_FILE, META_FILE

    if not path.exists():
        raise _fail(f"{path}: no such flight log (a flight's directory, or its "
                    f"{FLIGHT_FILE})", 2)
    directory = path if path.is_dir() else path.parent
    if path.is_file() and path.name != FLIGHT_FILE:
        raise _fail(f"{path}: not a flight log (a flight's directory, or its {FLIGHT_FILE})",
                    2)
    missing = [name for name in (FLIGHT_FILE, META_FILE, CONFIG_FILE)
               if not (directory / name).is_file()]
    if missing:
        raise _fail(f"{directory}: not a flight log: no {' or '.join(missing)} in it", 2)
    return path


def _input_file(path: Path, what: str) -> Path:
    """``path`` if it is a readable file; exit 2 with one line naming it if not."""
    if not path.exists():
        raise _fail(f"{path}: no such {what}", 2)
    if not path.is_file():
        raise _fail(f"{path}: not a {what} (a directory or a device)", 2)
    return path


@app.command()
def export(
    log: Annotated[Path, typer.Argument(help="Flight-log directory or its flight.npy.")],
    out: Annotated[Path | None, typer.Option(
        help="The file to write (default: stdout; required for parquet and mcap).")] = None,
    fmt: Annotated[ExportFormat, typer.Option(
        "--format", help="csv: one column per value, units in the header; parquet: full "
                         "precision; mcap: Foxglove, Lichtblick, PlotJuggler, Rerun.")] = "csv",
) -> None:
    """Export a flight log as CSV (one column per value, `name [unit]` header, floats at
    their sensor's precision), Parquet (full precision, units in the field metadata) or
    MCAP (JSON topics per group of columns, Foxglove poses, transforms and frames in
    protobuf for the 3D view); Parquet and MCAP need the `analysis` extra."""
    from groundstation.export import export_csv, export_mcap, export_parquet

    _flight_log(log)
    try:
        if fmt in ("parquet", "mcap"):
            if out is None:
                raise _fail(f"export --format {fmt} needs --out FILE.{fmt}", 2)
            if fmt == "mcap":
                typer.echo(f"{export_mcap(log, out)} messages written to {out}", err=True)
            else:
                typer.echo(f"{export_parquet(log, out)} rows written to {out}", err=True)
            return
        # a reader that went away (exit 141) is main()'s to report
        rows = export_csv(log, out if out is not None else sys.stdout)
    except RecorderError as exc:  # the log or the output file: a file that cannot be used
        if isinstance(exc.__cause__, BrokenPipeError):
            raise
        raise _fail(str(exc), 2) from exc
    if out is not None:
        typer.echo(f"{rows} rows written to {out}", err=True)


@app.command()
def replay(
    log: Annotated[Path, typer.Argument(help="Flight-log directory.")],
    config: Annotated[Path | None, typer.Option(
        "--config", "-c", help="Replay with this configuration instead of the flight's.")] = None,
) -> None:
    """Re-run the estimator and controller on a recorded flight; report the differences."""
    from groundstation.app.replay import replay_flight

    cfg = load(config) if config is not None else None
    _flight_log(log)
    try:
        report = replay_flight(str(log), cfg)
    except GroundStationError as exc:
        raise _fail(str(exc), 1) from exc
    for line in report.lines():
        typer.echo(line)


@app.command()
def report(
    log: Annotated[Path, typer.Argument(help="Flight-log directory.")],
    truth: Annotated[Path | None, typer.Option(
        help="The virtual lab's truth file (.npz) of the same run.")] = None,
    out_dir: Annotated[Path | None, typer.Option(
        "--out-dir", help="Directory to write the report into (default LOG/report; "
                          "--out, its former spelling, still works).")] = None,
    out: OutAlias = None,
) -> None:
    """Metrics and figures for one recorded flight, real or simulated.

    The truth is `--truth`, else the `truth.npz` that `gs fly --demo` keeps in the
    flight's directory; without one the metrics are computed from the estimate and
    labelled so. Without matplotlib the metrics are still written (a note says so).
    Exit 2 for a log or truth file that is missing or not one.
    """
    from groundstation.evaluation import report_flight

    directory = aliased(out_dir, out, "--out-dir", "--out", None)
    _flight_log(log)
    if truth is not None:
        _input_file(truth, "truth file")
    elif (log / "truth.npz").is_file():
        truth = log / "truth.npz"
    try:
        try:
            result = report_flight(log, truth, directory)
        except GroundStationError as exc:
            if "matplotlib" not in str(exc):
                raise
            typer.echo(f"no figures: {exc}", err=True)
            result = report_flight(log, truth, directory, figures=False)
    except RecorderError as exc:  # the log or the truth file cannot be read
        raise _fail(str(exc), 2) from exc
    except GroundStationError as exc:
        raise _fail(str(exc), 1) from exc
    typer.echo(f"{result.report_md}, {result.metrics_json}"
               + (f", {len(result.figures)} figures ({result.figure.name}, ...) in "
                  f"{result.figure.parent}" if result.figure else ""))


TelemetryOption = Annotated[str | None, typer.Option(
    "--telemetry", help=f"The daemon's telemetry.endpoint (default {DEFAULT_TELEMETRY}; "
                        "--endpoint, its former spelling, still works).")]
SecondsRunOption = Annotated[float | None, typer.Option(
    "--seconds", min=0.0, help="Stop after this many seconds (default: until Ctrl-C; "
                               "--duration, its former spelling, still works).")]


@app.command()
def monitor(
    telemetry: TelemetryOption = None, seconds: SecondsRunOption = None,
    endpoint: EndpointAlias = None, duration: DurationAlias = None,
) -> None:
    """Live terminal view of a flying ground station's telemetry (Ctrl-C to quit)."""
    from groundstation.telemetry.monitor import run_monitor

    source = aliased(telemetry, endpoint, "--telemetry", "--endpoint", DEFAULT_TELEMETRY)
    stop_after = aliased(seconds, duration, "--seconds", "--duration", None)
    try:
        run_monitor(source, stop_after)
    except GroundStationError as exc:
        raise _fail(str(exc), 1) from exc


@app.command()
def foxglove(
    telemetry: TelemetryOption = None,
    host: Annotated[str, typer.Option(
        help="Address to serve the WebSocket on: 0.0.0.0 (or this machine's lab address) "
             "for a viewer on another machine, as it should be: the viewer's rendering "
             "competes with the flight loop for the CPU.")] = "127.0.0.1",
    port: Annotated[int, typer.Option(min=0, max=65535, help="WebSocket port (0: any free).")]
        = 8765,
    seconds: SecondsRunOption = None,
    endpoint: EndpointAlias = None, duration: DurationAlias = None,
) -> None:
    """Live view in Foxglove or Lichtblick: serve the telemetry as a Foxglove WebSocket
    (ws://HOST:PORT; poses, paths and frames in 3D, supervisor state, plots).

    Viewers that speak either subprotocol connect: foxglove.sdk.v1 (Foxglove, current
    Lichtblick) and the former foxglove.websocket.v1 (Lichtblick releases before it).
    Needs foxglove-sdk, the package's `foxglove` extra. Ctrl-C to quit.
    """
    from groundstation.telemetry.foxglove import run_foxglove

    source = aliased(telemetry, endpoint, "--telemetry", "--endpoint", DEFAULT_TELEMETRY)
    stop_after = aliased(seconds, duration, "--seconds", "--duration", None)
    try:
        run_foxglove(source, host=host, port=port, duration=stop_after, echo=typer.echo)
    except GroundStationError as exc:
        raise _fail(str(exc), 1) from exc


@app.command()
def channels(
    auto: Annotated[list[str] | None, typer.Argument(
        help="Channels to put under automatic control: pitch, roll, yaw, thrust; "
             "the others go to the pilot. None: show the current set.")] = None,
    control: Annotated[str | None, typer.Option(
        "--control", help=f"The daemon's telemetry.control_endpoint (default "
                          f"{DEFAULT_CONTROL}; --endpoint, its former spelling, still "
                          "works).")] = None,
    timeout: Annotated[float, typer.Option(
        help="Seconds to wait for the daemon's reply.")] = REPLY_TIMEOUT_S,
    server_key: Annotated[Path | None, typer.Option(
        help="The daemon's public key (server.key), when it authenticates clients "
             "(telemetry.control_server_key).")] = None,
    client_key: Annotated[Path | None, typer.Option(
        help="This client's key pair (a .key_secret file) whose public half is in the "
             "daemon's telemetry.control_client_keys.")] = None,
    endpoint: EndpointAlias = None,
) -> None:
    """Hand channels between the controller and the pilot while flying (bumpless).

    Example, tuning altitude: `gs channels thrust` (the pilot flies attitude and
    yaw), then `gs channels pitch roll yaw thrust` to hand everything back to the
    controller. A daemon that authenticates its clients (CURVE) needs `--server-key`
    and `--client-key`.
    """
    from groundstation.telemetry.curve import CurveClient, load_client_keys
    from groundstation.telemetry.requests import send_request

    control_endpoint = aliased(control, endpoint, "--control", "--endpoint", DEFAULT_CONTROL)
    if not (math.isfinite(timeout) and timeout > 0):
        raise _fail(f"--timeout {timeout:g}: must be a positive number of seconds", 2)
    if (server_key is None) != (client_key is None):
        raise _fail("--server-key and --client-key go together (CURVE needs both)", 2)
    curve: CurveClient | None = None
    try:
        if server_key is not None and client_key is not None:
            curve = load_client_keys(client_key, server_key)
    except GroundStationError as exc:
        raise _fail(str(exc), 2) from exc
    unknown = [c for c in auto or () if c not in get_args(ChannelName)]
    if unknown:  # the daemon would refuse it too; a usage error needs no daemon
        raise _fail(f"unknown channel {unknown[0]!r} (one of "
                    f"{', '.join(get_args(ChannelName))})", 2)
    request: dict[str, Any] = {"request": "channels"}
    if auto:
        request["auto"] = list(auto)
    try:
        reply = send_request(control_endpoint, request, timeout, curve=curve)
    except GroundStationError as exc:
        raise _fail(str(exc), 1) from exc
    if not reply.get("ok"):
        raise _fail(str(reply.get("error", reply)), 1)
    now = reply.get("auto")
    typer.echo(f"automatic: {' '.join(map(str, now)) if isinstance(now, list) else now}  "
               f"(state {reply.get('state')})")


def _is_flight_log(path: Path) -> bool:
    return path.is_dir() or path.name == "flight.npy"


def _fit_from_log(source: Path, fit: str, name: str, out: Path, as_json: bool) -> bool:
    """If ``source`` is a flight log, fit it with ``groundstation.identification.lift``'s
    function ``fit``, report it and return True; else check it is a CSV file, return False."""
    if not _is_flight_log(source):
        _input_file(source, "measurement CSV")
        return False
    from groundstation.identification import lift

    try:
        result = getattr(lift, fit)(source)
    except GroundStationError as exc:
        raise _fail(str(exc), 2) from exc
    _report_fit(result, name, out, as_json)
    return True


@identify_app.command("thrust")
def identify_thrust(
    source: Annotated[Path, typer.Argument(
        help="CSV of thrust-stand measurements, or a flight-log directory.")],
    gravity: Annotated[float, typer.Option(help="g used to turn mass into force.")]
        = VehicleConfig().gravity,
    as_json: Annotated[bool, typer.Option("--json", help="(flight log) One JSON object keyed "
                                          "by the configuration's field names.")] = False,
    out_dir: Annotated[Path | None, typer.Option(
        "--out-dir", help="(flight log) Directory for the figure (default: the working "
                          "directory; --out, its former spelling, still works).")] = None,
    out: OutAlias = None,
) -> None:
    """Fit the thrust polynomial F_lift(u_thrust) (eq. 3.7) to measurements (App. C.1).

    From a CSV (format in `groundstation/model/identify.py`;
    `tests/data/thrust_table_c1.csv` is the thesis's Table C.1): the full cubic. From a
    flight log: the lift in steady flight (accelerometer) against the stick, as a scale on
    the configured polynomial (a flight covers the sticks near hover only).
    """
    out = aliased(out_dir, out, "--out-dir", "--out", Path("."))
    if _fit_from_log(source, "identify_thrust_log", "identify-thrust", out, as_json):
        return
    from groundstation.model.identify import identify_thrust_csv

    try:
        fit = identify_thrust_csv(source, g=gravity)
    except IdentificationError as exc:
        raise _fail(str(exc), 2) from exc
    typer.echo(fit.report())


@identify_app.command("hover-stick")
def identify_hover_stick(
    stick: Annotated[float, typer.Argument(
        help="The thrust stick the vehicle hovers at, flown by hand [RC units, 1..4095]: "
             "gs link-check --expect-switch off shows the pilot's sticks.")],
    config: ConfigOption,
    as_json: Annotated[bool, typer.Option("--json", help="One JSON object keyed by the "
                                          "configuration's field names.")] = False,
    out_dir: Annotated[Path, typer.Option(
        "--out-dir", help="Directory for the figure.")] = Path("."),
) -> None:
    """A first thrust map before any flight log: the configured thrust polynomial (eq. 3.7)
    scaled so that it lifts the vehicle's weight (vehicle.mass_kg, vehicle.gravity) at the
    stick the pilot hovers at. A thrust-automatic flight needs a map to take off with;
    its log then refines it (gs identify thrust LOG). Exit 2 for a stick where the
    configured map gives no lift.
    """
    from groundstation.identification.lift import thrust_from_hover_stick

    vehicle = load(config).vehicle
    try:
        result = thrust_from_hover_stick(stick, mass_kg=vehicle.mass_kg,
                                         gravity=vehicle.gravity,
                                         thrust_poly=vehicle.thrust_poly)
    except GroundStationError as exc:
        raise _fail(str(exc), 2) from exc
    _report_fit(result, "identify-hover-stick", out_dir, as_json, {"stick": stick})


@identify_app.command("inflow")
def identify_inflow(
    source: Annotated[Path, typer.Argument(
        help="CSV of steady-climb measurements, or a flight-log directory.")],
    as_json: Annotated[bool, typer.Option("--json", help="(flight log) One JSON object keyed "
                                          "by the configuration's field names.")] = False,
    out_dir: Annotated[Path | None, typer.Option(
        "--out-dir", help="(flight log) Directory for the figure (default: the working "
                          "directory; --out, its former spelling, still works).")] = None,
    out: OutAlias = None,
) -> None:
    """Fit the induced-inflow constant I_i (eq. 3.9) to steady climbs (App. C.2).

    From a CSV (`tests/data/inflow_table_c2.csv` is the thesis's Table C.2), or from a
    flight log with steady climbs and descents (a waypoint path with vertical legs).
    """
    out = aliased(out_dir, out, "--out-dir", "--out", Path("."))
    if _fit_from_log(source, "identify_inflow_log", "identify-inflow", out, as_json):
        return
    from groundstation.model.identify import identify_inflow_csv

    try:
        fit = identify_inflow_csv(source)
    except IdentificationError as exc:
        raise _fail(str(exc), 2) from exc
    typer.echo(fit.report())


def _report_fit(result: Any, name: str, out: Path, as_json: bool,
                extra: dict[str, Any] | None = None) -> None:
    """Print a calibration or identification (its summary and the YAML to paste, or with
    ``as_json`` one JSON object of its configuration fields plus ``extra``) and write its
    figure to ``out/<name>.png`` (a note instead where matplotlib is missing)."""
    import json

    import yaml

    figure: Path | None = None
    try:
        out.mkdir(parents=True, exist_ok=True)
        figure = result.figure(out / f"{name}.png")
    except GroundStationError as exc:  # matplotlib missing: the numbers still count
        typer.echo(f"no figure: {exc}", err=True)
    fields = result.config_fields()
    if as_json:
        typer.echo(json.dumps({**fields, **(extra or {}),
                                "figure": str(figure) if figure else None}))
        return
    typer.echo(result.summary())
    nested: dict[str, Any] = {}
    for key, value in fields.items():
        if "." in key:  # configuration fields; the rest (jitter, frame check) is in the summary
            section, leaf = key.split(".", 1)
            nested.setdefault(section, {})[leaf] = value
    typer.echo("\npaste into the configuration:\n" + yaml.safe_dump(nested, sort_keys=False))
    if figure is not None:
        typer.echo(f"figure: {figure}")


LogArgument = Annotated[Path, typer.Argument(help="Flight-log directory.")]
OutDirOption = Annotated[Path | None, typer.Option(
    "--out-dir", help="Directory for the figure (default: the working directory; --out, "
                      "its former spelling, still works).")]


@identify_app.command("rates")
def identify_rates_command(
    log: LogArgument,
    as_json: Annotated[bool, typer.Option("--json", help="One JSON object keyed by the "
                                          "configuration's field names.")] = False,
    out_dir: OutDirOption = None, out: OutAlias = None,
    with_scales: Annotated[bool, typer.Option(
        help="Identify the gyro scale from the same log first (a gyro scale error is "
             "otherwise a gain error of the same size).")] = False,
) -> None:
    """Per axis the stick-to-rate gain, transport delay and rate-loop time constant with
    95 % intervals (thesis Ch. 3.3.1, eq. 3.22, Fig. 3.8), from the flight's sticks and gyro.
    Exit 2 for a log that cannot determine them (the message names the axis)."""
    from groundstation.identification import identify_rates, identify_scales

    figures = aliased(out_dir, out, "--out-dir", "--out", Path("."))
    _flight_log(log)
    try:
        gyro_scale = identify_scales(log, axes=("gyro_x", "gyro_y", "gyro_z")).gyro_scale \
            if with_scales else None
        result = identify_rates(log, gyro_scale=gyro_scale)
    except GroundStationError as exc:
        raise _fail(str(exc), 2) from exc
    _report_fit(result, "identify-rates", figures, as_json)


@identify_app.command("scales")
def identify_scales_command(
    log: LogArgument,
    axes: Annotated[list[str] | None, typer.Option(
        "--axis", help=f"An axis to identify: {', '.join(get_args(ScaleAxis))} (repeatable; "
                       "default: the gyro and acc_z: in flight the accelerometer's x and y "
                       "read about zero and need a bench).")] = None,
    as_json: Annotated[bool, typer.Option("--json", help="One JSON object keyed by the "
                                          "configuration's field names.")] = False,
    out_dir: OutDirOption = None, out: OutAlias = None,
) -> None:
    """Gyro and accelerometer scale factors (Table 6.2) against the body rates and
    specific force the flight's Vicon poses imply, with 95 % intervals. Exit 2 for a log
    that cannot determine them (the message names the axis)."""
    from groundstation.identification import SCALE_AXES, identify_scales

    figures = aliased(out_dir, out, "--out-dir", "--out", Path("."))
    unknown = [a for a in axes or () if a not in SCALE_AXES]
    if unknown:
        raise _fail(f"unknown axis {unknown[0]!r} (one of {', '.join(SCALE_AXES)})", 2)
    _flight_log(log)
    chosen = tuple(a for a in SCALE_AXES if a in axes) if axes else (
        "gyro_x", "gyro_y", "gyro_z", "acc_z")
    try:
        result = identify_scales(log, axes=chosen)
    except GroundStationError as exc:
        raise _fail(str(exc), 2) from exc
    _report_fit(result, "identify-scales", figures, as_json)


SerialPortOption = Annotated[str | None, typer.Option(help="Serial device or URL.")]
ViconPortOption = Annotated[int | None, typer.Option(help="Vicon UDP port.")]
ViconObjectOption = Annotated[str | None, typer.Option(help="Vicon object name.")]
SecondsOption = Annotated[float, typer.Option(min=1.0, help="Measurement length [s].")]


@calibrate_app.command("imu")
def calibrate_imu_command(
    config: ConfigOption, seconds: SecondsOption = 10.0, serial_port: SerialPortOption = None,
    vicon_port: ViconPortOption = None, vicon_object: ViconObjectOption = None,
    protocol: ProtocolOption = None, as_json: JsonOption = False,
    out_dir: OutDirOption = None, out: OutAlias = None,
    vicon: Annotated[bool, typer.Option(
        help="Fit the accelerometer to the Vicon attitude (else: the vehicle is level).")] = True,
) -> None:
    """Gyro and accelerometer zeros [counts] and noise variances (Table 6.3), vehicle at rest.

    The link is up but nothing is commanded (the vehicle stays the pilot's). Refused if
    the vehicle moves. Exit 1 if it cannot measure, 2 on a usage error.
    """
    from groundstation.calibration import calibrate_imu
    from groundstation.flight.assembly import assemble

    cfg = load(config, {"serial.port": serial_port, "vicon.port": vicon_port,
                        "vicon.object_name": vicon_object, "serial.protocol": protocol})
    try:
        result = calibrate_imu(assemble(cfg), seconds, use_vicon=vicon)
    except GroundStationError as exc:
        raise _fail(str(exc), 1) from exc
    _report_fit(result, "calibrate-imu", aliased(out_dir, out, "--out-dir", "--out", Path(".")),
                as_json,
                {"samples": result.samples, "seconds": result.seconds})


@calibrate_app.command("vicon")
def calibrate_vicon_command(
    config: ConfigOption, seconds: SecondsOption = 10.0, vicon_port: ViconPortOption = None,
    vicon_object: ViconObjectOption = None, as_json: JsonOption = False,
    out_dir: OutDirOption = None, out: OutAlias = None,
) -> None:
    """Vicon noise (Table 6.1), stream rate, jitter and dropped frames, and a frame check.

    Place the vehicle level with its nose along the lab's +x: if world_to_ned or
    body_to_object is wrong, the rotation that fixes it is suggested. Exit 1 if it
    cannot measure, 2 on a usage error.
    """
    from groundstation.calibration import calibrate_vicon
    from groundstation.flight.assembly import assemble

    cfg = load(config, {"vicon.port": vicon_port, "vicon.object_name": vicon_object})
    try:
        result = calibrate_vicon(assemble(cfg), seconds)
    except GroundStationError as exc:
        raise _fail(str(exc), 1) from exc
    _report_fit(result, "calibrate-vicon",
                aliased(out_dir, out, "--out-dir", "--out", Path(".")), as_json,
                {"samples": result.samples, "seconds": result.seconds})


@app.command("link-check")
def link_check_command(
    config: ConfigOption,
    seconds: Annotated[float, typer.Option(min=1.0, help="How long to listen [s].")] = 10.0,
    serial_port: SerialPortOption = None, protocol: ProtocolOption = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print the report as one JSON "
                                          "object.")] = False,
    expect_switch: Annotated[Literal["on", "off"], typer.Option(
        help="The serial-enable switch position a healthy link shows: on (to fly) or off "
             "(the hand-back test, a pilot flying by hand).")] = "on",
) -> None:
    """Listen to the vehicle's serial link with the propellers off and say whether it is
    fit to fly. Sends nothing that moves the vehicle (X-3D: CONFIG to start its DATA
    stream; AscTec LL: polls; never a command). Reports the DATA rate against
    serial.data_period_ms, rejected frames by reason, the blocks present, the
    serial-enable switch, the channels the vehicle applies, the battery, the pilot's
    sticks and whether the IMU reads rest.

    Exit codes: 0 healthy; 1 not healthy (the reasons on the verdict line); 2 usage or
    configuration error; 3 the port could not be opened (absent, no permission, or in
    use by a flight).
    """
    import json

    from groundstation.errors import LinkError
    from groundstation.flight.assembly import assemble
    from groundstation.linkcheck import run_link_check

    cfg = load(config, {"serial.port": serial_port, "serial.protocol": protocol})
    try:
        report = run_link_check(assemble(cfg), seconds, expect_switch=expect_switch == "on")
    except LinkError as exc:
        raise _fail(str(exc), 3) from exc
    if as_json:
        typer.echo(json.dumps(report.to_json()))
    else:
        for line in report.lines():
            typer.echo(line)
    if not report.healthy:
        raise typer.Exit(1)


@app.command("verify-model")
def verify_model_command(
    log: Annotated[Path, typer.Argument(help="Flight-log directory.")],
    as_json: JsonOption = False, out_dir: OutDirOption = None, out: OutAlias = None,
) -> None:
    """Thesis Ch. 5: the nonlinear and linear models' quaternion and velocity derivatives
    against the flight's, with a figure (Fig. 5.1-5.4) and the RMS and mean error per axis.

    A constant error in v3_dot is a thrust-map or mass error of that size [m/s^2].
    """
    import json

    from groundstation.identification.verify import verify_model

    out = aliased(out_dir, out, "--out-dir", "--out", Path("."))
    _flight_log(log)
    try:
        result = verify_model(log)
    except GroundStationError as exc:
        raise _fail(str(exc), 2) from exc
    figure: Path | None = None
    try:
        out.mkdir(parents=True, exist_ok=True)
        figure = result.figure(out / "verify-model.png")
    except GroundStationError as exc:
        typer.echo(f"no figure: {exc}", err=True)
    if as_json:
        typer.echo(json.dumps({**result.figures(), "figure": str(figure) if figure else None}))
        return
    typer.echo(result.summary())
    if figure is not None:
        typer.echo(f"figure: {figure}")


@synth_app.command("hinf")
def synth_hinf(
    config: ConfigOption,
    out: Annotated[Path, typer.Option(help="Gain file to write (.npz).")],
    rate_loop: Annotated[bool, typer.Option(
        help="Design on the model with the on-board rate-loop lag (Ch. 10.3).")] = True,
) -> None:
    """Synthesise the Ch. 10 H-infinity gain from the LMI (eq. 10.12-10.17) and save it.

    Point `controller.hinf.gain_file` at the result to fly it. Needs cvxpy:
    `pip install 'groundstation[hinf]'`.
    """
    from groundstation.control.hinf import synthesise_hinf
    from groundstation.flight.assembly import hinf_design, link_params, vehicle_model

    cfg = load(config)
    design = hinf_design(cfg.controller.hinf, rate_loop)
    if design.robust_range > 0.0:
        typer.echo(f"robust design for rate gains, rate-loop lag and thrust within "
                   f"+-{100 * design.robust_range:g} %", err=True)
    try:
        gain = synthesise_hinf(vehicle_model(cfg.vehicle, link_params(cfg.serial)),
                               include_rate_loop=design.include_rate_loop,
                               weights=design.weights, robust_range=design.robust_range,
                               pole_radius=design.pole_radius, min_decay=design.min_decay)
    except GroundStationError as exc:  # also: cvxpy (the `hinf` extra) not installed
        raise _fail(str(exc), 1) from exc
    gain.save(out)
    model = "with the rate-loop lag" if rate_loop else "on the thesis's model (no rate loop)"
    typer.echo(f"H-infinity gain designed {model}: |F_s| = {float(abs(gain.F_s).max()):.3g}, "
               f"written to {out}")


OPTIONAL_EXTRAS = {"matplotlib": "plot", "cvxpy": "hinf", "mcap": "analysis", "pandas": "analysis",
                   "zenoh": "fleet"}
"""Optional packages and the extra that installs each (pyproject.toml)."""

EXIT_BROKEN_PIPE = 141
"""Exit code when the reader of our output went away (``gs export LOG | head``): 128 +
SIGPIPE, what a shell reports for a tool that SIGPIPE stopped."""

EXIT_INTERRUPTED = 130
"""Exit code on Ctrl-C outside a flight (128 + SIGINT); a flight lands instead (4)."""


def main(argv: list[str] | None = None) -> None:
    """The ``gs`` entry point and the CLI's one error boundary.

    Every command runs inside it, so no user mistake ends in a traceback: a
    :class:`~groundstation.errors.GroundStationError` prints ``error: ...`` and exits 2
    (ConfigError) or 1; a file that cannot be used (missing, a directory, unreadable)
    exits 2 naming it; a missing optional package exits 1 naming the extra to install;
    a closed pipe exits :data:`EXIT_BROKEN_PIPE` quietly; Ctrl-C exits
    :data:`EXIT_INTERRUPTED`. Usage errors are click's (exit 2 with the usage). Any other
    exception is a bug and keeps its traceback.
    """
    try:
        app(args=argv)
    except BrokenPipeError:
        _quiet_broken_pipe()
    except KeyboardInterrupt:
        typer.echo("interrupted", err=True)
        raise SystemExit(EXIT_INTERRUPTED) from None
    except GroundStationError as exc:
        if isinstance(exc.__cause__, BrokenPipeError):  # e.g. export_csv's RecorderError
            _quiet_broken_pipe()
        for line in str(exc).splitlines() or [""]:  # a ConfigError: one line per problem
            typer.echo(f"error: {line}", err=True)
        raise SystemExit(2 if isinstance(exc, ConfigError) else 1) from None
    except ImportError as exc:
        extra = OPTIONAL_EXTRAS.get((exc.name or "").partition(".")[0])
        if extra is None:
            raise
        typer.echo(f"error: this needs the optional package {exc.name}: "
                   f"pip install 'groundstation[{extra}]'", err=True)
        raise SystemExit(1) from None
    except OSError as exc:
        if exc.filename is None:
            raise
        typer.echo(f"error: {exc.filename}: {exc.strerror or exc}", err=True)
        raise SystemExit(2) from None


def _quiet_broken_pipe() -> NoReturn:
    """Exit :data:`EXIT_BROKEN_PIPE` without a word. Python docs, "Note on SIGPIPE":
    stdout goes to devnull so the interpreter's final flush does not raise again."""
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, sys.stdout.fileno())
    raise SystemExit(EXIT_BROKEN_PIPE)


def add_lab_commands() -> None:
    """Add the installed virtual lab's commands (``gs sim-device``, ``gs eval``; see
    :mod:`groundstation.lab`). Without a lab (the flight image) ``gs`` has none."""
    from groundstation.lab import LabNotInstalledError, virtual_lab

    try:
        plugin = virtual_lab()
    except LabNotInstalledError:
        return
    for name, command in plugin.commands():
        app.command(name)(command)

