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

from groundstation.cli import load
from groundstation.cli.options import (
    ConfigOption,
    DurationAlias,
    OutAlias,
    ProtocolOption,
    aliased,
    fail,
)
from groundstation.errors import ConfigError, GroundStationError

SCENARIO_NAMES = (
    "hover-1hz", "hover-10hz", "hover-100hz", "step-x", "step-y", "step-z", "square-pid",
    "square-lqr-cp", "square-lqr-cv", "yz-rectangle-pid", "yz-rectangle-lqr-cp",
    "yz-rectangle-lqr-cv", "low-hover", "square-vicon-outage", "hover-thrust-error",
    "square-thrust-error", "hinf-thesis-model", "hinf-rate-loop-model", "figure-eight-lqr-ff",
    "figure-eight-pid", "figure-eight-lqr-cp", "figure-eight-lqr-cv", "yaw-turn",
    "square-shaped-lqr-ff", "square-shaped-h135-lqr-ff", "square-shaped-pid",
    "square-shaped-lqr-cp", "square-shaped-lqr-cv", "takeoff-h135", "hover-h90", "hover-h180",
    "hover-h270", "hinf-rate-gains-low", "hinf-rate-gains-high", "file-eight-8s",
    "file-eight-4s", "file-figure8", "hover-exact-angles",
    "payload-hover-lqr-ff", "payload-eight-lqr-ff", "wind-hover-lqr-ff",
    "gust-hover-lqr-ff", "battery-sag-lqr-ff", "ground-effect-lqr-ff",
    "payload-hover-lqr-cv", "payload-eight-lqr-cv", "wind-hover-lqr-cv",
    "gust-hover-lqr-cv", "battery-sag-lqr-cv", "ground-effect-lqr-cv",
    "payload-hover-lqr-cp", "payload-eight-lqr-cp", "wind-hover-lqr-cp",
    "gust-hover-lqr-cp", "battery-sag-lqr-cp", "ground-effect-lqr-cp", "payload-hover-pid",
    "payload-eight-pid", "wind-hover-pid", "gust-hover-pid", "battery-sag-pid",
    "ground-effect-pid", "payload-hover-hinf", "payload-eight-hinf", "wind-hover-hinf",
    "gust-hover-hinf", "battery-sag-hinf", "ground-effect-hinf", "outage-1s-hover",
    "outage-1s-eight", "outage-2s-hover", "outage-2s-eight",
)
"""The scenarios ``gs eval --scenario`` takes, in suite order, for its help (importing the
suite to list them would slow every ``gs`` command; a test checks they are the suite's)."""


def sim_device(
    config: ConfigOption,
    seconds: Annotated[float | None, typer.Option(
        "--seconds", min=0.0, help="Stop after this many seconds (default: until Ctrl-C; "
                                   "--duration, its former spelling, still works).")] = None,
    truth_file: Annotated[Path | None, typer.Option(help="Ground-truth .npz path.")] = None,
    json: Annotated[bool, typer.Option(
        "--json", help="Print where the lab is as one JSON line first (for programs: "
                       "serial_port, vicon_target, truth_file).")] = False,
    protocol: ProtocolOption = None,
    duration: DurationAlias = None,
    vehicles: Annotated[int | None, typer.Option(
        "--vehicles", min=1, max=64,
        help="A virtual fleet: N vehicles v1..vN (objects X3D-1..X3D-N, 1 m apart along "
             "north), each on its own pty, all in one Vicon stream.")] = None,
    fleet: Annotated[Path | None, typer.Option(
        "--fleet", help="A virtual fleet: the vehicles of this fleet.yaml, each as its "
                        "daemon flies it (its object, home and sim overrides).")] = None,
) -> None:
    """Run the virtual X-3D (pty) and virtual Vicon (UDP) in real time until Ctrl-C.

    Prints the pty path to use as `--serial-port` and the Vicon UDP target, and
    writes the ground truth on exit (also on SIGINT/SIGTERM). With `--json` the first
    line is the same as JSON (`groundstation.lab.Announcement`). With `--protocol
    asctec-ll` the vehicle speaks the AscTec LL dialect (answers polls, acknowledges
    commands; `serial.ll` of the configuration). With `--vehicles N` or `--fleet FILE` a
    virtual fleet: one pty per vehicle, one Tracker stream carrying every object, one
    truth file per vehicle (`--json`: one line naming them all).
    """
    stop_after = aliased(seconds, duration, "--seconds", "--duration", None)
    cfg = load(config, {"serial.protocol": protocol})
    if vehicles is not None or fleet is not None:  # a virtual fleet (sim_device/fleet.py)
        from sim_device.fleet import run_fleet_command

        try:
            run_fleet_command(cfg, vehicles=vehicles, fleet_file=fleet, truth_file=truth_file,
                              json_line=json, duration=stop_after, echo=typer.echo)
        except ConfigError as exc:
            raise fail(str(exc), 2) from exc
        return
    from sim_device.realtime import run_sim_device

    run_sim_device(cfg, truth_file=truth_file, duration=stop_after, announce=typer.echo,
                   on_ready=(lambda info: typer.echo(info.announcement.to_json())) if json
                   else None)


def evaluate(
    config: ConfigOption,
    fast: Annotated[bool, typer.Option(
        help="In-process on the simulated clock (default: real time over the pty and UDP).")]
        = False,
    out_dir: Annotated[Path | None, typer.Option(
        "--out-dir", help="Report directory (default eval_out; --out, its former spelling, "
                          "still works).")] = None,
    scenario: Annotated[list[str] | None, typer.Option(
        help="Fly only this scenario (repeatable; default all): "
             f"{', '.join(SCENARIO_NAMES)}.")] = None,
    perturb: Annotated[list[str] | None, typer.Option(
        help="Fly every scenario on the plant drawn for this seed (repeatable; a range "
             "1-5 or a list 1,4); the report gives the worst case over the seeds.")] = None,
    out: OutAlias = None,
) -> None:
    """Fly the thesis's Ch. 11 flight tests and the later ones (headings, trajectory files,
    disturbances) in the virtual lab; write a report.

    Metrics come from the virtual lab's ground truth; the report is `report.md` with
    PNG figures mirroring Fig. 11.1-11.8 and `metrics.json`. With `--perturb` the
    virtual vehicle differs from the design model (rate gains, rate-loop lag, mass,
    thrust, delay, motors, IMU errors: see sim_device/evaluation/perturb.py).
    """
    from sim_device.evaluation import run_eval
    from sim_device.evaluation.perturb import parse_seeds

    report_dir = aliased(out_dir, out, "--out-dir", "--out", Path("eval_out"))
    cfg = load(config)
    try:
        seeds = parse_seeds(perturb or [])
        report = run_eval(cfg, fast=fast, out_dir=report_dir, scenarios=scenario,
                          progress=typer.echo, perturb=seeds)
    except GroundStationError as exc:
        raise fail(str(exc), 2 if isinstance(exc, ConfigError) else 1) from exc
    typer.echo(f"{len(report.outcomes)} scenarios in {report.wall_s:.0f} s: {report.report_md}, "
               f"{report.metrics_json}, {len(report.figures)} figures")


COMMANDS = (("sim-device", sim_device), ("eval", evaluate))
"""The commands the lab adds to ``gs``, by name."""
