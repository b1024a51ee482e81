"""The virtual lab's commands in ``gs``: ``gs sim-device`` and ``gs eval``.

The ground station's CLI adds them from the lab's plugin (:mod:`sim_device.plugin`,
entry point ``groundstation.labs``), so ``gs`` has them wherever the virtual lab is
installed and the flight image (without the lab) does not. They share the ground
station's option types, configuration loading and error boundary.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from groundstation.cli import ConfigOption, fail, load
from groundstation.errors import ConfigError, GroundStationError


def sim_device(
    config: ConfigOption,
    duration: Annotated[float | None, typer.Option(help="Stop after this many seconds.")] = None,
    truth_file: Annotated[Path | None, typer.Option(help="Ground-truth .npz path.")] = None,
    json: Annotated[bool, typer.Option(
        "--json", help="Print where the lab is as one JSON line first (for programs: "
                       "serial_port, vicon_target, truth_file).")] = False,
    protocol: Annotated[str | None, typer.Option(
        help="The vehicle's serial dialect: x3d|asctec-ll (overrides serial.protocol).")]
        = None,
) -> None:
    """Run the virtual X-3D (pty) and virtual Vicon (UDP) in real time until Ctrl-C.

    Prints the pty path to use as ``--serial-port`` and the Vicon UDP target, and
    writes the ground truth on exit (also on SIGINT/SIGTERM). With ``--json`` the first
    line is the same as JSON (``groundstation.lab.Announcement``). With ``--protocol
    asctec-ll`` the vehicle speaks the AscTec LL dialect (answers polls, acknowledges
    commands; ``serial.ll`` of the configuration).
    """
    cfg = load(config, {"serial.protocol": protocol})
    from sim_device.realtime import run_sim_device

    run_sim_device(cfg, truth_file=truth_file, duration=duration, announce=typer.echo,
                   on_ready=(lambda info: typer.echo(info.announcement.to_json())) if json
                   else None)


def evaluate(
    config: ConfigOption,
    fast: Annotated[bool, typer.Option(
        help="In-process on the simulated clock (default: real time over the pty and UDP).")]
        = False,
    out: Annotated[Path, typer.Option(help="Report directory.")] = Path("eval_out"),
    scenario: Annotated[list[str] | None, typer.Option(
        help="Fly only these scenarios (repeatable; default all).")] = None,
    perturb: Annotated[list[str] | None, typer.Option(
        help="Fly every scenario on the plant drawn for this seed (repeatable; a range "
             "1-5 or a list 1,4); the report gives the worst case over the seeds.")] = None,
) -> None:
    """Fly the thesis's Ch. 11 flight tests and issue 13's in the virtual lab; write a report.

    Metrics come from the virtual lab's ground truth; the report is ``report.md`` with
    PNG figures mirroring Fig. 11.1-11.8 and ``metrics.json``. With ``--perturb`` the
    virtual vehicle differs from the design model (rate gains, rate-loop lag, mass,
    thrust, delay, IMU errors: see sim_device/evaluation/perturb.py).
    """
    from sim_device.evaluation import run_eval
    from sim_device.evaluation.perturb import parse_seeds

    cfg = load(config)
    try:
        seeds = parse_seeds(perturb or [])
        report = run_eval(cfg, fast=fast, out_dir=out, scenarios=scenario, progress=typer.echo,
                          perturb=seeds)
    except GroundStationError as exc:
        raise fail(str(exc), 2 if isinstance(exc, ConfigError) else 1) from exc
    typer.echo(f"{len(report.outcomes)} scenarios in {report.wall_s:.0f} s: {report.report_md}, "
               f"{report.metrics_json}, {len(report.figures)} figures")


COMMANDS = (("sim-device", sim_device), ("eval", evaluate))
"""The commands the lab adds to ``gs``, by name."""
