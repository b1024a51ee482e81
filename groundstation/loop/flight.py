"""``gs fly``: run one flight (optionally against the virtual lab) and report it.

Returns the process exit code: 0 after a normal landing and handover or a
requested stop, 1 otherwise, 2 for a trajectory that cannot be flown (refused
before anything is connected). Resource errors (port, socket, log directory)
are reported in one line, never as a traceback.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from contextlib import ExitStack
from pathlib import Path

from groundstation.config import GroundStationConfig, apply_overrides
from groundstation.errors import GroundStationError, TrajectoryError
from groundstation.loop.assemble import trajectory_for_flight
from groundstation.loop.daemon import FlightDaemon, FlightSummary

Echo = Callable[[str], None]


def summary_lines(summary: FlightSummary) -> list[str]:
    """The short human-readable report printed after a flight."""
    lines = [f"flight ended in {summary.final_state.name} "
             f"({'normal end' if summary.success else 'NOT a normal end'})"]
    lines += [f"  {tr.t - summary.transitions[0].t:7.2f} s  {tr.old.name} -> {tr.new.name}: "
              f"{tr.reason}" for tr in summary.transitions]
    if not math.isnan(summary.track_rms_m):
        lines.append(f"  tracking error (estimate vs reference): RMS "
                     f"{100 * summary.track_rms_m:.1f} cm, max {100 * summary.track_max_m:.1f} cm")
    p = summary.percentiles()
    lines.append(
        f"  ticks {summary.ticks}, commands {summary.commands_sent}; compute p50/p99 "
        f"{1e6 * p['compute'][0]:.0f}/{1e6 * p['compute'][1]:.0f} us, jitter p99 "
        f"{1e3 * p['jitter'][1]:.2f} ms, DATA->COMMAND latency p50/p99 "
        f"{1e3 * p['latency'][0]:.2f}/{1e3 * p['latency'][1]:.2f} ms")
    lines.append(f"  flight log: {summary.log_dir}")
    return lines


def fly_command(config: GroundStationConfig, *, duration_s: float | None = None,
                demo: bool = False, echo: Echo = print) -> int:
    """Fly once; with ``demo`` start the virtual lab first and plot the result."""
    try:
        trajectory_for_flight(config, duration_s=duration_s)  # the flight core builds it again
    except TrajectoryError as exc:
        echo(f"error: {exc}")
        return 2
    try:
        with ExitStack() as stack:
            truth_file: Path | None = None
            device = None
            if demo:
                if config.sim is None:
                    echo("error: --demo needs a configuration with a `sim:` section "
                         "(config/sim.yaml)")
                    return 2
                from sim_device.realtime import SimDeviceThread, default_truth_path

                truth_file = default_truth_path(config)
                device = stack.enter_context(SimDeviceThread(config, truth_file=truth_file))
                echo(f"virtual lab: X-3D on {device.info.pty_path}, Vicon -> "
                     f"udp://{device.info.vicon_target[0]}:{device.info.vicon_target[1]}")
                config = apply_overrides(config, {"serial.port": device.info.pty_path})
            summary = FlightDaemon(config, duration_s=duration_s, progress=echo).run()
        for line in summary_lines(summary):
            echo(line)
        if demo and summary.log_dir:
            _plot(summary.log_dir, truth_file, echo)
        return 0 if summary.success else 1
    except GroundStationError as exc:
        echo(f"error: {exc}")
        return 1


def _plot(log_dir: str, truth_file: Path | None, echo: Echo) -> None:
    from groundstation.loop.plot import plot_flight

    try:
        png = plot_flight(log_dir, Path(log_dir) / "flight.png", truth_file)
    except GroundStationError as exc:
        echo(f"no plot: {exc}")
        return
    echo(f"  plot of the flown path against the reference: {png}")
