"""``gs fly``: run one flight (optionally against the virtual lab) and report it.

Returns the process exit code (:data:`EXIT_CODES`, printed by ``gs fly --help``):

0. the mission was flown, the vehicle landed and was handed back, no failsafe acted;
1. a failsafe acted or the flight was aborted: a failsafe landing (Vicon lost, the
   volume left, tilt, low battery, take-off timeout), a failsafe handback, the pilot
   took over, the vehicle's watchdog expired in the air, the link was lost, the
   preflight checks failed, an internal error;
2. configuration or usage error, or a trajectory refused before flight: nothing was
   connected;
3. could not start: a resource could not be opened (the serial port absent or in use
   by another flight, the Vicon or telemetry port taken, no flight-log directory
   writable: the configured one, else a user's, :mod:`groundstation.app.logdir`);
   nothing was sent to the vehicle;
4. stopped on request (SIGINT/SIGTERM, SIGHUP: the terminal went away, SIGQUIT) without
   a failsafe: landed, or handed back at a second request or as ``safety.on_signal``
   configures;
5. flown without a failsafe, but the flight log is incomplete: rows were lost (a full
   disk, an I/O error) or meta.json could not be written. It takes precedence over 0
   and 4, never over 1 (see :attr:`FlightSummary.exit_code`).

Whatever the way out of a flight, the summary is printed (its first line says the final
state, why, whether the log is incomplete, and the exit code) and the flight log's
meta.json holds the same outcome. Resource errors are reported in one line, never as a
traceback. Output never stops a flight: every line goes through a
:class:`~groundstation.logs.LineSink`, so a closed, hung-up or paused terminal loses
lines, not the landing.
"""

from __future__ import annotations

import math
import shutil
import sys
import tempfile
from collections.abc import Callable, Sequence
from contextlib import ExitStack
from dataclasses import replace
from pathlib import Path

from groundstation.app.daemon import (
    EXIT_LOG_INCOMPLETE,
    FlightDaemon,
    FlightSummary,
    link_figures,
)
from groundstation.config import apply_overrides
from groundstation.errors import ConfigError, GroundStationError
from groundstation.flight.core import FlightCore
from groundstation.flight.params import FlightParams
from groundstation.flight.supervisor import Outcome
from groundstation.logs import LineSink, log_through_sink, retire_lost_stream, stream_writer

Echo = Callable[[str], None]

AfterFlight = Callable[[Path, Path | None], list[str]]
"""A step run once a flight's log is closed and the vehicle is the pilot's: given the
flight-log directory and the virtual lab's truth file (None without one), the lines to
print. The CLI hands them in: the MCAP copy (``logging.mcap``,
:func:`groundstation.export.mcap_after_flight`) and, with ``--demo``, the flight's report
(:func:`groundstation.evaluation.report.report_after_flight`)."""

EXIT_USAGE = 2
EXIT_NOT_STARTED = 3

EXIT_CODES: dict[int, str] = {
    int(Outcome.COMPLETED): "mission completed: landed and handed back, no failsafe",
    int(Outcome.FAILSAFE): "failsafe or abort: a failsafe landing or handback, pilot "
                           "takeover, watchdog expiry in the air, link lost, preflight "
                           "failed, internal error",
    EXIT_USAGE: "configuration or usage error, or a trajectory refused before flight "
                "(nothing connected)",
    EXIT_NOT_STARTED: "could not start: serial port absent or in use, Vicon or telemetry "
                      "port taken, no flight-log directory writable (nothing sent to the "
                      "vehicle)",
    int(Outcome.STOPPED): "stopped on request (SIGINT/SIGTERM, SIGHUP, SIGQUIT): landed, or "
                          "handed back at a second request",
    EXIT_LOG_INCOMPLETE: "flight log incomplete: flown without a failsafe, but rows were "
                         "lost (disk full, I/O error) or meta.json not written; before 0 "
                         "and 4, never before 1",
}
"""Exit code -> meaning, as ``gs fly --help`` and the README list them."""

_OUTCOME_WORDS = {
    Outcome.COMPLETED: "mission completed",
    Outcome.FAILSAFE: "failsafe or abort",
    Outcome.STOPPED: "stopped on request",
}


def summary_lines(summary: FlightSummary) -> list[str]:
    """The short human-readable report printed after a flight."""
    words = _OUTCOME_WORDS[summary.outcome]
    if not summary.log.complete:
        words += f"; {summary.log.describe()}"
    lines = [f"flight ended in {summary.final_state.name}: {summary.reason} "
             f"({words}, exit code {summary.exit_code})"]
    t0 = summary.transitions[0].t if summary.transitions else 0.0
    lines += [f"  {tr.t - t0:7.2f} s  {tr.old.name} -> {tr.new.name}: {tr.reason}"
              + ("  [failsafe]" if tr.failsafe else "") for tr in summary.transitions]
    lines += [f"  {e.t - t0:7.2f} s  failsafe event ({e.kind}, {1e3 * e.duration_s:.0f} ms): "
              f"{e.reason}" for e in summary.events]
    if not math.isnan(summary.track_rms_m):
        lines.append(f"  tracking error (estimate vs reference): RMS "
                     f"{100 * summary.track_rms_m:.1f} cm, max {100 * summary.track_max_m:.1f} cm")
    p = summary.percentiles()
    lines.append(
        f"  ticks {summary.ticks}, commands {summary.commands_sent}; compute p50/p99 "
        f"{1e6 * p['compute'][0]:.0f}/{1e6 * p['compute'][1]:.0f} us, jitter p99 "
        f"{1e3 * p['jitter'][1]:.2f} ms, DATA->COMMAND latency p50/p99 "
        f"{1e3 * p['latency'][0]:.2f}/{1e3 * p['latency'][1]:.2f} ms")
    gc = summary.collector
    lines.append(
        f"  longest COMMAND gap {1e3 * summary.max_command_gap_s:.1f} ms (keep-alive resends "
        f"{summary.keepalive_resends}); garbage collections: {gc.young} young (longest "
        f"{1e3 * gc.longest_young_s:.2f} ms), {gc.full} full (longest "
        f"{1e3 * gc.longest_full_s:.2f} ms)")
    c = summary.control
    if any(c.values()):
        lines.append(", ".join([f"  control socket: {c.get('answered', 0)} requests answered",
                                *(f"{n} {name.replace('_', ' ')}" for name, n in c.items()
                                  if n and name != "answered")]))
    link = link_figures(summary)
    if link is not None:
        lines.append(f"  serial link ({link.protocol}): in {link.in_bytes_per_s:.0f} B/s "
                     f"({100 * link.in_line_share:.0f} % of the line), out "
                     f"{link.out_bytes_per_s:.0f} B/s ({100 * link.out_line_share:.0f} %), "
                     f"{link.rejected} rejected")
        if link.ack_p50_ms is not None and link.ack_p99_ms is not None:
            lines.append(f"  polls {link.polls} ({link.polls_unanswered} unanswered), "
                         f"acknowledgements {link.acks} ({link.acks_missing} missing), "
                         f"command->ack p50/p99 {link.ack_p50_ms:.1f}/{link.ack_p99_ms:.1f} ms")
    lines.append(f"  flight log: {summary.log_dir}")
    return lines


def fly_command(params: FlightParams, *, duration_s: float | None = None,
                demo: bool = False, echo: Echo | None = None,
                after_flight: Sequence[AfterFlight] = ()) -> int:
    """Fly once with ``params`` (:func:`groundstation.flight.assembly.assemble`); with
    ``demo`` start the virtual lab first (its truth is kept in the
    flight's log as ``truth.npz``). Then run the ``after_flight`` steps in order and print
    their lines. Returns the flight's exit code (see the module docstring): an
    after-flight step changes none.

    echo : where the lines go (default: this process's stdout, written below Python's
        buffers, see :func:`~groundstation.logs.fd_writer`); called from a thread of
        its own, so a blocked or failing ``echo`` delays or loses lines, never the
        flight. Its last lines get :data:`~groundstation.logs.OUTPUT_DRAIN_S` to go out.
    """
    stdout = sys.stdout
    out = LineSink(stream_writer(stdout) if echo is None else echo, "stdout")
    try:
        with log_through_sink():
            return _fly(params, duration_s, demo, out.put, after_flight)
    finally:
        out.close()
        if echo is None:
            retire_lost_stream(stdout, out)


def _fly(params: FlightParams, duration_s: float | None, demo: bool,
         echo: Echo, after_flight: Sequence[AfterFlight]) -> int:
    try:  # the checks `gs check-config` runs, before anything is connected; the daemon
        # builds the core again (about 50 ms) for the configuration it flies
        FlightCore(params, duration_s=duration_s)
    except (GroundStationError, ValueError, ArithmeticError) as exc:
        echo(f"error: {exc}")
        return EXIT_USAGE
    # the lab writes its truth when it stops (the ExitStack closes); the directory holding
    # it outlives the stack so that the truth can be kept with the flight log
    with ExitStack() as keep, ExitStack() as stack:
        truth_file: Path | None = None
        try:
            if demo:
                if params.source.sim is None:  # the lab's own section
                    echo("error: --demo needs a configuration with a `sim:` section "
                         "(config/sim.yaml)")
                    return EXIT_USAGE
                workdir = Path(keep.enter_context(tempfile.TemporaryDirectory(prefix="gs-demo-")))
                params, truth_file = _start_virtual_lab(params, stack, workdir, echo)
            summary = FlightDaemon(params, duration_s=duration_s, progress=echo).run()
        except ConfigError as exc:
            echo(f"error: {exc}")
            return EXIT_USAGE
        except GroundStationError as exc:  # a resource could not be opened: nothing flown
            echo(f"error: {exc}")
            return EXIT_NOT_STARTED
        finally:
            stack.close()  # the lab stops and writes its truth
        for line in summary_lines(summary):
            echo(line)
        if summary.log_dir:
            log_dir = Path(summary.log_dir)
            truth = _keep_truth(log_dir, truth_file)
            for step in after_flight:
                _after(step, log_dir, truth, echo)
    return summary.exit_code


def _start_virtual_lab(params: FlightParams, stack: ExitStack, workdir: Path,
                       echo: Echo) -> tuple[FlightParams, Path]:
    """Start the installed virtual lab (:func:`groundstation.lab.virtual_lab`) in a child
    process, working in ``workdir``, for the block ``stack`` closes; return the
    parameters with the link on its pty and its truth file (written when it stops). A
    process of its own, as the vehicle is: a pause of this one (a loaded machine) cannot
    stop the vehicle's clock."""
    from groundstation.lab import virtual_lab

    plugin = virtual_lab()
    try:
        lab = stack.enter_context(plugin.start(params.source, workdir)).announcement
    except RuntimeError as exc:
        raise GroundStationError(f"the virtual lab did not start: {exc}") from exc
    address, port = lab.vicon_target
    echo(f"virtual lab: vehicle ({params.link.protocol}) on {lab.serial_port}, "
         f"Vicon -> udp://{address}:{port}")
    pty = lab.serial_port  # the flight log's copy of the configuration says it too
    return replace(params, link=replace(params.link, port=pty),
                   source=apply_overrides(params.source, {"serial.port": pty})), lab.truth_file


def _keep_truth(log_dir: Path, truth_file: Path | None) -> Path | None:
    """Keep the virtual lab's truth in the flight's directory (``truth.npz``); its path
    there, or None without a lab."""
    if truth_file is None or not truth_file.exists():
        return None
    truth = log_dir / "truth.npz"
    shutil.copyfile(truth_file, truth)
    return truth


def _after(step: AfterFlight, log_dir: Path, truth: Path | None, echo: Echo) -> None:
    """Run one after-flight step and print its lines; one that fails says so in a line
    (the flight and its log are done: only the step's own output is lost)."""
    try:
        lines = step(log_dir, truth)
    except Exception as exc:
        echo(f"  {getattr(step, '__name__', 'after-flight step')}: failed: {exc}")
        return
    for line in lines:
        echo(line)
