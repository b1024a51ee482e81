"""The `gs` command line.

Each command is a thin shell: parse options, load the configuration, call the
package, translate :class:`~groundstation.errors.GroundStationError` into a
one-line message and a non-zero exit code. Exit codes: 0 success, 1 runtime
failure, 2 bad configuration or usage.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

import typer

from groundstation import __version__
from groundstation.config import GroundStationConfig, apply_overrides, dump_config, load_config
from groundstation.errors import ConfigError, GroundStationError, IdentificationError
from groundstation.logs import configure_logging

app = typer.Typer(
    name="gs",
    help="Ground station for the AscTec X-3D in a Vicon lab.",
    no_args_is_help=True,
    add_completion=False,
)
identify_app = typer.Typer(help="Identify model parameters from measurement CSVs.",
                           no_args_is_help=True)
app.add_typer(identify_app, name="identify")

ConfigOption = Annotated[Path, typer.Option("--config", "-c", help="YAML configuration file.")]


def _fail(message: str, code: int) -> typer.Exit:
    typer.echo(f"error: {message}", err=True)
    return typer.Exit(code)


def load(path: Path, overrides: dict[str, Any] | None = None) -> GroundStationConfig:
    """Load the configuration and apply CLI overrides; exit 2 with the errors if invalid."""
    try:
        config = load_config(path)
        if overrides:
            config = apply_overrides(config, overrides)
    except ConfigError as exc:
        raise _fail(str(exc), 2) from exc
    configure_logging(config.logging.level, config.logging.format)
    return config


@app.command()
def version() -> None:
    """Print the version."""
    typer.echo(__version__)


@app.command("check-config")
def check_config(file: Annotated[Path, typer.Argument(help="YAML configuration file.")]) -> None:
    """Validate a configuration file and print it with every default filled in."""
    try:
        config = load_config(file)
    except ConfigError as exc:
        raise _fail(str(exc), 2) from exc
    typer.echo(dump_config(config), nl=False)


@app.command()
def fly(
    config: ConfigOption,
    serial_port: Annotated[str | None, typer.Option(help="Serial device or URL.")] = None,
    vicon_port: Annotated[int | None, typer.Option(help="Vicon UDP port.")] = None,
    vicon_object: Annotated[str | None, typer.Option(help="Vicon object name.")] = None,
    trajectory: Annotated[str | None, typer.Option(help="Trajectory name.")] = None,
    controller: Annotated[str | None, typer.Option(help="lqr-cv|lqr-cp|pid|hinf")] = None,
    duration: Annotated[float | None, typer.Option(help="Seconds on the trajectory.")] = None,
    log_dir: Annotated[Path | None, typer.Option(help="Flight-log directory.")] = None,
    demo: Annotated[bool, typer.Option(help="Also start the virtual lab (sim config).")] = False,
) -> None:
    """Fly: preflight, take off, track the trajectory, land, hand back to the pilot."""
    cfg = load(config, {
        "serial.port": serial_port, "vicon.port": vicon_port, "vicon.object_name": vicon_object,
        "trajectory.name": trajectory, "controller.type": controller,
        "logging.flight_log_dir": str(log_dir) if log_dir else None,
    })
    del cfg, duration, demo
    raise _fail("the flight loop is not built yet (issue 8); see README 'Status'", 1)


@identify_app.command("thrust")
def identify_thrust(
    csv: Annotated[Path, typer.Argument(help="CSV of thrust-stand measurements.")],
    gravity: Annotated[float, typer.Option(help="g used to turn mass into force.")] = 9.82,
) -> None:
    """Fit the thrust polynomial F_lift(u_thrust) (eq. 3.7) to measurements (App. C.1).

    The CSV format is described in ``groundstation/model/identify.py``;
    ``tests/data/thrust_table_c1.csv`` is the thesis's Table C.1 in that format.
    """
    from groundstation.model.identify import identify_thrust_csv

    try:
        fit = identify_thrust_csv(csv, g=gravity)
    except IdentificationError as exc:
        raise _fail(str(exc), 2) from exc
    typer.echo(fit.report())


@identify_app.command("inflow")
def identify_inflow(
    csv: Annotated[Path, typer.Argument(help="CSV of steady-climb measurements.")],
) -> None:
    """Fit the induced-inflow constant I_i (eq. 3.9) to steady climbs (App. C.2).

    ``tests/data/inflow_table_c2.csv`` is the thesis's Table C.2 in that format.
    """
    from groundstation.model.identify import identify_inflow_csv

    try:
        fit = identify_inflow_csv(csv)
    except IdentificationError as exc:
        raise _fail(str(exc), 2) from exc
    typer.echo(fit.report())


def main() -> None:  # pragma: no cover - console entry point alternative
    """Run the CLI, turning unexpected package errors into exit code 1."""
    try:
        app()
    except GroundStationError as exc:
        typer.echo(f"error: {exc}", err=True)
        raise SystemExit(1) from exc
