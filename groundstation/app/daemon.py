"""The real-time flight daemon behind ``gs fly``.

Owns every thread, socket and clock of a flight: the serial link (reader and
keep-alive threads), the Vicon client (reader thread), the flight recorder, the
telemetry publisher, systemd notification and the signal handlers. Each tick it
hands the sans-IO :class:`~groundstation.flight.core.FlightCore` one DATA sample
and the Vicon poses that arrived since the last tick.

In a fleet (``fleet:``, :mod:`groundstation.fleet`) it opens its node too: each tick the
nearest peer's distance goes to the supervisor with the input health, and after the
tick this vehicle's state, health and pose go out on Zenoh; run-time requests arrive as
Zenoh queries answered by the same handler as the request socket's, each motion checked
against the peers first; with ``vicon.source: zenoh`` the Vicon poses come from the
fleet's relay through the same pose filter.

Scheduling: one tick per DATA sample (100 Hz). If no DATA arrives within 1.5
periods of the last tick, the loop ticks anyway (without an IMU sample) so a
stalled stream still reaches the supervisor's link-loss failsafe.

Timing per tick (recorded, summarised in :class:`FlightSummary`):

* compute: from the tick's start (DATA in hand) to its COMMAND written;
* jitter: how late the tick started against its schedule. The loop is scheduled
  by DATA arrival, so this is the tick's start minus the DATA frame's receive
  time (the reader thread's stamp), or minus the deadline for a stalled stream;
* latency: DATA frame received to COMMAND written (jitter + compute);
* DATA interval: the spacing of DATA frames as received, a property of the link
  and the vehicle, reported beside the loop's own figures.

While flying, the daemon runs its loop and threads under the real-time FIFO
policy (``realtime.fifo_priority``, 10) when it may, holds a PM QoS request for CPU
wake-up latency (``realtime.cpu_dma_latency_us``, default 0 us) so the CPUs do not
drop into deep idle states between DATA samples, shortens the interpreter's thread
switch interval to ``realtime.switch_interval_ms`` (0.5 ms; default 5 ms) so a
reader thread holding the GIL cannot delay a tick by more, and paces the garbage
collector (``realtime.paced_gc``): start-up objects frozen, full collections only
right after a COMMAND went out (see :mod:`groundstation.app.realtime`).

Stopping: the first stop signal (SIGINT, SIGTERM, SIGHUP, SIGQUIT: see
:mod:`groundstation.app.signals`) asks the supervisor to land (or hand back, see
``safety.on_signal``); a second one at least ``safety.second_signal_after_s``
(0.5 s) later hands back at once, closer ones are the same request (GNU
``timeout`` signals the process and then its group within a millisecond). A
hangup (SIGHUP: the terminal went away) counts only as a first request, never as
the second.

Output cannot stop a flight: the progress lines go to the caller's ``progress``
(``gs fly`` hands it a :class:`~groundstation.logs.LineSink`) and the log lines through
one (:func:`~groundstation.logs.log_through_sink`), so a paused, closed or hung-up
terminal blocks or fails a writer thread, never the loop or the landing.

Every way out ends in a terminal supervisor state with its reason: a serial link
that fails mid-flight is LINK_LOST, an unexpected error in the loop ABORTED (logged
with its traceback); either way one last row goes to the flight log (that state,
ctrl mask 0) and :meth:`FlightDaemon.run` returns the summary. The link sends a
final COMMAND with ctrl mask 0 if it ever flew the vehicle, the flight log is
flushed and closed with the outcome in its meta.json, and systemd hears STOPPING.
Only a resource that cannot be opened raises (nothing was sent to the vehicle).

A flight log that lost rows (a full disk, an I/O error) is an outcome too: the
flight goes on and lands, and the summary (:attr:`FlightSummary.log`,
:attr:`FlightSummary.exit_code`) and meta.json say what is missing and why.
"""

from __future__ import annotations

import math
import signal
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import ExitStack, contextmanager
from dataclasses import asdict, dataclass, field
from functools import partial

import numpy as np
import structlog

from groundstation.app.api import LoopInbox, MotionApi
from groundstation.app.logdir import create_flight_log
from groundstation.app.planner_process import PlannerProcess
from groundstation.app.realtime import (
    CollectorPacer,
    CollectorStats,
    cpu_latency_request,
    fifo_priority,
    switch_interval,
)
from groundstation.app.recorder import FlightRecorder, LogLoss
from groundstation.app.sdnotify import SdNotifier
from groundstation.app.signals import HANGUP_SIGNALS, StopRequests, on_stop_signals
from groundstation.app.ticklog import TickLogger
from groundstation.asctec.dialect import VehicleLink, open_link
from groundstation.asctec.stats import LinkStats
from groundstation.control.base import Controller
from groundstation.control.trajectory import Trajectory
from groundstation.errors import LinkError
from groundstation.fleet.node import FleetNode
from groundstation.flight.assembly import config_text
from groundstation.flight.core import FlightCore, TickResult
from groundstation.flight.inputs import DataFrontEnd, VehicleStatus, with_vicon
from groundstation.flight.params import FlightParams
from groundstation.flight.supervisor import FailsafeEvent, Outcome, State, Transition
from groundstation.logs import log_through_sink
from groundstation.telemetry.publisher import TelemetryPublisher
from groundstation.telemetry.requests import Reply, Request, RequestServer
from groundstation.telemetry.schema import health_payload, state_payload
from groundstation.timing import TimingHistogram
from groundstation.types import Pose
from groundstation.vicon.receiver import ViconReceiver

log = structlog.get_logger(__name__)

RESEND_CONFIG_AFTER_S = 0.5
"""Re-send CONFIG when no DATA arrived for this long (spec 3.1: stream stopped)."""

FINAL_LINGER_S = 0.2
"""How long the flight's final telemetry may take to reach subscribers before the
publisher closes [s] (a local subscriber takes well under a millisecond)."""

EXIT_LOG_INCOMPLETE = 5
"""``gs fly``'s exit code for a flight flown without a failsafe whose log is incomplete
(:attr:`FlightSummary.exit_code`)."""


@dataclass
class FlightSummary:
    """What a flight did, for the CLI's closing lines and the benchmarks.

    final_state, success : the supervisor's terminal state; True for a normal end
        (the mission completed, or a requested stop, without a failsafe)
    outcome : how it ended; its value is `gs fly`'s exit code
    reason : the reason of the last transition (what ended the flight)
    transitions : every state change with its reason
    events : failsafe events that changed no state (watchdog expiries in the air)
    log_dir : the flight log directory
    track_rms_m, track_max_m : estimate-vs-reference 3-D error while tracking [m]
    compute, jitter, latency : per-tick timing histograms [s] (see the module docstring)
    data_interval : spacing of the received DATA frames [s]
    commands_sent, ticks : counters; duration_s : wall time of the loop [s]
    max_command_gap_s : longest time between two COMMAND writes while armed [s]
    keepalive_resends : COMMANDs the keep-alive wrote because the loop had not
    collector : garbage collections during the loop and their longest pauses
    control : the request socket's counters (:class:`~groundstation.telemetry.requests.
        RequestStats`: requests answered, malformed, refused...)
    link, protocol, baud : the serial link's counters at the end (bytes each way,
        rejections; in the AscTec LL dialect polls and acknowledgements), its dialect and
        line rate [baud]
    log : what the flight log is missing (rows lost and why, meta.json not written)
    """

    final_state: State
    success: bool
    transitions: list[Transition]
    log_dir: str
    track_rms_m: float
    track_max_m: float
    compute: TimingHistogram
    jitter: TimingHistogram
    latency: TimingHistogram
    data_interval: TimingHistogram
    commands_sent: int
    ticks: int
    duration_s: float
    outcome: Outcome = Outcome.FAILSAFE
    reason: str = ""
    events: list[FailsafeEvent] = field(default_factory=list)
    max_command_gap_s: float = math.nan
    keepalive_resends: int = 0
    collector: CollectorStats = field(default_factory=CollectorStats)
    control: dict[str, int] = field(default_factory=dict)
    link: LinkStats | None = None
    protocol: str = "x3d"
    baud: int = 57600
    log: LogLoss = field(default_factory=LogLoss)

    @property
    def exit_code(self) -> int:
        """``gs fly``'s exit code: the outcome's value, except that a flight whose log is
        incomplete exits :data:`EXIT_LOG_INCOMPLETE` (5) instead of 0 or 4. A failsafe
        keeps 1: it is what the vehicle did, the more urgent news (the summary's first
        line and meta.json still say the log is incomplete). And an incomplete log wins
        over 4: a stop on request is what the operator asked for, lost data is not."""
        if self.outcome is Outcome.FAILSAFE or self.log.complete:
            return int(self.outcome)
        return EXIT_LOG_INCOMPLETE

    def percentiles(self) -> dict[str, tuple[float, float]]:
        """p50 and p99 of compute time, |jitter| and latency [s]."""
        return {name: (h.percentile(50.0), h.percentile(99.0)) for name, h in
                (("compute", self.compute), ("jitter", self.jitter), ("latency", self.latency))}


@dataclass
class _Stats:
    compute: TimingHistogram = field(default_factory=TimingHistogram)
    jitter: TimingHistogram = field(default_factory=TimingHistogram)
    latency: TimingHistogram = field(default_factory=TimingHistogram)
    data_interval: TimingHistogram = field(default_factory=TimingHistogram)
    t_start: float = 0.0
    t_end: float = 0.0
    track_sq: float = 0.0
    track_max: float = 0.0
    track_n: int = 0
    sent: int = 0
    ticks: int = 0
    max_command_gap: float = math.nan
    keepalive_resends: int = 0
    collector: CollectorStats = field(default_factory=CollectorStats)
    link: LinkStats | None = None


class FlightDaemon:
    """One real-time flight. Build it, then :meth:`run` it (blocks until the flight ends).

    params : the flight's parameters (:func:`groundstation.flight.assembly.assemble`;
        ``link.port`` is the vehicle's)
    duration_s : trajectory time before landing (default one trajectory period)
    controller, trajectory : replace the ones the parameters name
    progress : called about once a second with a one-line status, from the loop: it
        must return at once (``gs fly`` passes a :class:`~groundstation.logs.LineSink`'s
        ``put``); an exception it raises is logged and ends the progress lines, not the
        flight
    stop : an extra way to ask for a stop (counts like a signal), e.g. from a test
    """

    def __init__(self, params: FlightParams, *, duration_s: float | None = None,
                 controller: Controller | None = None, trajectory: Trajectory | None = None,
                 progress: Callable[[str], None] | None = None,
                 stop: threading.Event | None = None) -> None:
        self.params = params
        self.core = FlightCore(params, controller=controller, trajectory=trajectory,
                               duration_s=duration_s)
        self._front = DataFrontEnd(params.imu)
        self._progress = progress
        self._stop_event = stop
        self._stops = StopRequests(params.daemon.second_signal_after_s)
        self._period = params.link.data_period_ms / 1000.0
        self._stats = _Stats()
        self.log_dir = ""
        self.telemetry_endpoint: str | None = None
        """The bound telemetry endpoint once :meth:`run` has started (``*`` ports resolved)."""
        self.control_endpoint: str | None = None
        """The bound control endpoint (``gs channels``) once :meth:`run` has started."""
        self._request_stats: Callable[[], dict[str, int]] = dict  # the socket's, once open
        self._last: TickResult | None = None  # the last tick's result (final telemetry)
        self._inbox = LoopInbox()
        self._front_health: Callable[[], dict[str, object]] = dict
        self._planner = PlannerProcess(params.planner, timeout_s=params.daemon.plan_timeout_s)
        self._api = MotionApi(self.core, params, in_loop=self._inbox.call,
                              planner=self._planner, health=lambda: self._front_health())
        self.ready = threading.Event()
        """Set once every resource is open and the loop is about to start."""

    def _on_signal(self, sig: signal.Signals) -> None:
        if self._stops.request(escalates=sig not in HANGUP_SIGNALS):
            log.warning("signal", signal=sig.name, count=self._stops.count)
        else:
            log.warning("signal taken as a repeat of the first stop request", signal=sig.name,
                        within_s=self._stops.repeat_after_s)

    @property
    def stop_requests(self) -> int:
        """Stop requests that counted (see :class:`StopRequests`) plus one if the stop
        event is set."""
        extra = 1 if self._stop_event is not None and self._stop_event.is_set() else 0
        return self._stops.count + extra

    def run(self) -> FlightSummary:
        """Fly. Raises LinkError/ViconError/GroundStationError if a resource cannot be opened;
        once flying, failures are supervisor transitions and the flight ends with a summary."""
        p = self.params
        notifier = SdNotifier.from_env()
        with ExitStack() as stack:
            # first in, last out: every log line of the flight, its closing ones too
            stack.enter_context(log_through_sink())
            stack.callback(notifier.stopping, "stopping: vehicle handed back")
            # first: the serial, Vicon and ZeroMQ threads started below inherit it
            stack.enter_context(fifo_priority(p.daemon.fifo_priority))
            link = open_link(p.link)  # the configured dialect
            stack.callback(link.close)  # sends the final COMMAND with ctrl mask 0
            fleet = self._open_fleet(stack)  # a fleet: section: peers, Zenoh (None alone)
            vicon = (fleet.pose_source() if p.vicon.source == "zenoh" and fleet is not None
                     else ViconReceiver.from_params(p.vicon)).start()
            stack.callback(vicon.close)
            # the configured directory, else a user's (one line says so): logdir.py
            recorder = create_flight_log(p.daemon.log_dir, config_text(p),
                                         {"supervisor_states": [s.name for s in State]})
            stack.callback(recorder.close)
            self.log_dir = str(recorder.directory)
            telemetry = TelemetryPublisher.from_params(p.telemetry)
            stack.callback(telemetry.close)
            self.telemetry_endpoint = telemetry.endpoint
            server = RequestServer.from_params(p.requests)
            stack.callback(server.close)
            self.control_endpoint = server.endpoint
            self._request_stats = server.stats
            if server.endpoint is not None or fleet is not None:  # stopped before they close
                if self.core.commander is not None:  # motions planned in a process of its own
                    stack.enter_context(self._planner)
                if server.endpoint is not None:
                    stack.enter_context(self._serving(server))
                if fleet is not None:  # requests as Zenoh queries, the same handler
                    self._api.guard = fleet
                    stack.enter_context(fleet.serving(self.handle_request))
            stack.enter_context(on_stop_signals(self._on_signal))
            stack.enter_context(cpu_latency_request(p.daemon.cpu_dma_latency_us))
            stack.enter_context(switch_interval(p.daemon.switch_interval_s))
            # its full collection runs now, before the vehicle streams, and freezes all
            # that is open
            pacer = stack.enter_context(CollectorPacer(p.daemon.paced_gc))
            link.start_stream()
            notifier.ready("preflight")
            self.ready.set()
            log.info("flight starting", port=p.link.port, vicon_port=p.vicon.port,
                     log=self.log_dir, controller=p.controller_type)
            self._front_health = partial(self._health_section, link, vicon)
            try:
                self._loop(_Io(link, vicon, recorder, telemetry, notifier, pacer, fleet))
            finally:
                self._inbox.close()  # requests now run where they arrive, or are refused
            self._publish_end(telemetry, link, vicon, fleet)
            stats = link.stats()
            self._stats.max_command_gap = stats.max_command_gap
            self._stats.keepalive_resends = stats.keepalive_resends
            self._stats.link = stats
            self._stats.collector = pacer.stats
            recorder.finish()  # the last rows, so that the summary counts what is lost
            summary = self._summary(recorder.loss())
            recorder.meta["outcome"] = _outcome_meta(summary)
        summary.log = recorder.loss()  # now with meta.json's fate
        return summary

    # ------------------------------------------------------------------ the loop
    def _loop(self, io: _Io) -> None:
        """Tick until the supervisor reaches a terminal state. A failure inside a tick
        ends the flight there (see the module docstring), with one last logged row."""
        core = self.core
        ticklog = TickLogger(io.recorder)
        self._inbox.open()
        self._stats.t_start = time.monotonic()
        clock = _Clock(t_prev=self._stats.t_start, wd_interval=io.notifier.watchdog_interval(),
                       last_config=self._stats.t_start)  # run() has just sent CONFIG
        while not core.supervisor.terminal:
            try:
                self._tick(io, ticklog, clock)
            except Exception as exc:  # every way out must end in a logged terminal state
                self._end(exc, ticklog)
        self._stats.t_end = time.monotonic()

    def _tick(self, io: _Io, ticklog: TickLogger, clock: _Clock) -> None:
        core, link = self.core, io.link
        deadline = clock.t_prev + 1.5 * self._period
        rx = link.get(timeout=max(0.0, deadline - time.monotonic()))
        start = time.monotonic()
        poses = _drain(io.vicon)
        imu = None
        if rx is not None:
            imu = self._front.receive(rx.t, rx.msg)
            scheduled = rx.t
            self._stats.data_interval.add(rx.t - clock.t_rx_prev)
            clock.t_rx_prev = rx.t
        else:
            scheduled = deadline
            if start - clock.last_config > RESEND_CONFIG_AFTER_S and \
                    self._front.data_age(start) > RESEND_CONFIG_AFTER_S:
                link.start_stream()  # the stream stopped: ask for it again
                clock.last_config = start
        vicon_rate, vicon_age = io.vicon.rate_and_age()
        health = with_vicon(self._front.health(start, vicon_age, vicon_rate),
                            io.vicon.evidence(), io.vicon.diagnosis)
        if io.fleet is not None:  # the nearest peer, for the supervisor's separation rule
            health = io.fleet.with_peers(health, start, core.last_estimate)
        result = core.tick(start, imu, poses, self._front.status, health, self.stop_requests)
        self._last = result
        clock.t_prev = start
        latency = math.nan
        if result.due:
            link.send(result.command)
            self._stats.sent += 1
            if rx is not None:
                latency = time.monotonic() - rx.t
        if core.supervisor.commanding and not link.armed:
            link.arm()
        compute = time.monotonic() - start
        self._account(start - scheduled, compute, latency, result)
        ticklog.record(start, rx.msg if rx is not None else None, imu, poses, result,
                       compute=compute, jitter=start - scheduled, latency=latency)
        io.telemetry.maybe_publish(start, partial(self._snapshot, result, link, io.vicon))
        if io.fleet is not None:  # the fleet's telemetry and this vehicle's pose for its peers
            io.fleet.after_tick(start, result, poses,
                                partial(self._snapshot, result, link, io.vicon))
        self._inbox.run_pending()  # run-time requests, between ticks (app/api.py)
        if clock.wd_interval is not None and start >= clock.next_wd:
            io.notifier.watchdog()
            clock.next_wd = start + clock.wd_interval / 2
        if self._progress is not None and start >= clock.next_progress:
            self._report_progress(self._progress_line(result, health.data_rate_hz, vicon_rate,
                                                      io.recorder.rows_dropped))
            clock.next_progress = start + 1.0
        if result.due:
            io.pacer.after_command()  # a full collection, if due, now: the next COMMAND is
            # a command period away

    def _end(self, exc: Exception, ticklog: TickLogger) -> None:
        """End the flight after ``exc`` escaped a tick: LINK_LOST for the serial link,
        ABORTED for anything else; log it and record one last row in that state."""
        t = time.monotonic()
        if isinstance(exc, LinkError):
            log.error("serial link failed in flight", error=str(exc))
            result = self.core.abort(t, State.LINK_LOST, f"serial link failed: {exc}")
        else:
            log.exception("flight loop failed", error=repr(exc))
            result = self.core.abort(t, State.ABORTED,
                                     f"internal error: {type(exc).__name__}: {exc}")
        self._last = result
        try:
            ticklog.record(t, None, None, [], result, compute=0.0, jitter=math.nan,
                           latency=math.nan)
        except Exception as record_error:  # the row is lost; the flight still ends
            log.error("last flight-log row not written", error=repr(record_error))

    def _account(self, jitter: float, compute: float, latency: float,
                 result: TickResult) -> None:
        s = self._stats
        s.ticks += 1
        s.compute.add(compute)
        s.jitter.add(jitter)
        s.latency.add(latency)  # NaN (no command this tick) is ignored
        if result.state is State.TRACK and result.estimate is not None:
            err = float(np.linalg.norm(result.reference.position - result.estimate.position))
            s.track_sq += err * err
            s.track_n += 1
            s.track_max = max(s.track_max, err)

    def handle_request(self, request: Request) -> Reply:
        """Answer one run-time request (:mod:`groundstation.app.api`): status, motions,
        land, channels. Runs in the request socket's thread; what touches the flight runs
        in the loop between two ticks."""
        return self._api.handle(request)

    @contextmanager
    def _serving(self, server: RequestServer) -> Iterator[None]:
        """Answer the request socket in a thread of its own while the block runs."""
        stop = threading.Event()
        thread = threading.Thread(target=server.serve, args=(self.handle_request, stop),
                                  name="gs-requests", daemon=True)
        thread.start()
        try:
            yield
        finally:
            stop.set()
            thread.join(5.0)

    def _open_fleet(self, stack: ExitStack) -> FleetNode | None:
        """This vehicle's node in its fleet (``params.fleet``; groundstation/fleet), closed
        with ``stack``; None without a fleet. FleetError if its session cannot be opened."""
        if self.params.fleet is None:
            return None
        return stack.enter_context(FleetNode.open(self.params))

    def _health_section(self, link: VehicleLink, vicon: ViconReceiver) -> dict[str, object]:
        """Input health for a status reply: DATA and Vicon rates [Hz] and ages [s], and the
        battery [V]."""
        now = time.monotonic()
        rate, age = vicon.rate_and_age()
        status = self._front.status
        return {"data_rate_hz": link.stats().data_rate_hz,
                "data_age_s": self._front.data_age(now), "vicon_rate_hz": rate,
                "vicon_age_s": age, "battery_v": status.battery_v,
                "pilot_enabled": status.pilot_enabled}

    def _publish_end(self, telemetry: TelemetryPublisher, link: VehicleLink,
                     vicon: ViconReceiver, fleet: FleetNode | None = None) -> None:
        """Publish the flight's last ``state`` (``final``, with its terminal state, outcome
        and reason) and ``health``, and give subscribers up to :data:`FINAL_LINGER_S` to
        receive them before the publisher closes; in a fleet on Zenoh too."""
        if self._last is None:
            return
        sup = self.core.supervisor
        reason = sup.transitions[-1].reason if sup.transitions else ""
        try:
            snapshot = self._snapshot(self._last, link, vicon, final=(sup.outcome.name, reason))
        except Exception:  # the flight has ended: a failed last message loses only itself
            log.warning("final telemetry not published", exc_info=True)
            return
        t = time.monotonic()
        for topic, body in snapshot.items():
            telemetry.publish(topic, body, t)
        if fleet is not None:
            fleet.publish_end(snapshot, int(sup.state))
        telemetry.close(linger_s=FINAL_LINGER_S)

    def _snapshot(self, result: TickResult, link: VehicleLink, vicon: ViconReceiver,
                  final: tuple[str, str] | None = None) -> dict[str, dict[str, object]]:
        status = self._front.status
        sticks = result.sticks if result.sticks is not None else status.pilot
        stats = link.stats()
        outcome, reason = final if final is not None else (None, None)
        return {
            "state": state_payload(state=int(result.state), state_name=result.state.name,
                                   estimate=result.estimate, reference=result.reference,
                                   sticks=sticks, ctrl_mask=result.command.ctrl,
                                   sent=result.due, vehicle=_vehicle_section(status),
                                   flight_time_s=time.monotonic() - self._stats.t_start,
                                   final=final is not None, outcome=outcome, reason=reason),
            "health": health_payload(
                link={"rate_hz": stats.data_rate_hz, "rejected": dict(stats.rejections)},
                vicon=vicon.health(), estimator=self.core.ekf.health()
                if self.core.init_report is not None else None,
                loop={"ticks": self._stats.ticks, "commands": self._stats.sent},
                control=self._request_stats()),
        }

    def _report_progress(self, line: str) -> None:
        """Hand ``line`` to the progress callback; one that raises is dropped."""
        assert self._progress is not None
        try:
            self._progress(line)
        except Exception as exc:  # the flight does not depend on who watches it
            log.warning("progress lines stopped", error=repr(exc))
            self._progress = None

    def _progress_line(self, result: TickResult, data_hz: float, vicon_hz: float,
                       rows_lost: int = 0) -> str:
        err = "-"
        if result.estimate is not None:
            e = float(np.linalg.norm(result.reference.position - result.estimate.position))
            err = f"{100 * e:5.1f} cm"
        volts = self._front.status.battery_v
        return (f"{result.state.name:<9} error {err}  DATA {data_hz:5.1f} Hz  "
                f"Vicon {vicon_hz:5.1f} Hz  mask 0x{result.command.ctrl:X}  battery "
                + ("--" if math.isnan(volts) else f"{volts:.2f} V")
                + (f"  LOG: {rows_lost} rows lost" if rows_lost else ""))

    def _summary(self, log_loss: LogLoss | None = None) -> FlightSummary:
        s, sup = self._stats, self.core.supervisor
        return FlightSummary(
            final_state=sup.state, success=sup.success, transitions=list(sup.transitions),
            log_dir=self.log_dir,
            track_rms_m=math.sqrt(s.track_sq / s.track_n) if s.track_n else math.nan,
            track_max_m=s.track_max if s.track_n else math.nan,
            compute=s.compute, jitter=s.jitter, latency=s.latency,
            data_interval=s.data_interval, commands_sent=s.sent,
            ticks=s.ticks, duration_s=s.t_end - s.t_start, outcome=sup.outcome,
            reason=sup.transitions[-1].reason if sup.transitions else "",
            events=list(sup.events), max_command_gap_s=s.max_command_gap,
            keepalive_resends=s.keepalive_resends, collector=s.collector,
            control=self._request_stats(), link=s.link,
            protocol=self.params.link.protocol, baud=self.params.link.baud,
            log=log_loss if log_loss is not None else LogLoss(),
        )


@dataclass
class _Io:
    """What the loop talks to, opened by :meth:`FlightDaemon.run`."""

    link: VehicleLink
    vicon: ViconReceiver
    recorder: FlightRecorder
    telemetry: TelemetryPublisher
    notifier: SdNotifier
    pacer: CollectorPacer
    fleet: FleetNode | None = None
    """This vehicle's node in a fleet (groundstation/fleet), None alone."""


@dataclass
class _Clock:
    """The loop's schedule between ticks [monotonic s]."""

    t_prev: float
    wd_interval: float | None
    t_rx_prev: float = math.nan
    next_wd: float = -math.inf
    next_progress: float = -math.inf
    last_config: float = -math.inf
    """When CONFIG was last sent: it is re-sent when no DATA came for 0.5 s after it."""


def _vehicle_section(status: VehicleStatus) -> dict[str, object]:
    """The telemetry ``vehicle`` section from the X-3D's last STATUS and RC blocks."""
    return {"battery_v": status.battery_v, "serial_active": bool(status.flags & 0x01),
            "motors_on": bool(status.flags & 0x02), "rc_valid": bool(status.flags & 0x04),
            "applied_mask": status.applied_mask, "pilot_enabled": status.pilot_enabled}


def _outcome_meta(summary: FlightSummary) -> dict[str, object]:
    """The flight's outcome for meta.json."""
    return {
        "outcome": summary.outcome.name, "exit_code": summary.exit_code,
        "final_state": summary.final_state.name, "reason": summary.reason,
        "log": summary.log.as_meta(),
        "failsafe_transitions": [
            {"t": tr.t, "old": tr.old.name, "new": tr.new.name, "reason": tr.reason}
            for tr in summary.transitions if tr.failsafe],
        "events": [{"t": e.t, "kind": e.kind, "duration_s": e.duration_s, "reason": e.reason}
                   for e in summary.events],
        "link": None if (link := link_figures(summary)) is None else asdict(link),
    }


@dataclass(frozen=True, slots=True)
class LinkFigures:
    """The serial link over one flight: bytes per second each way [B/s] and their share of
    the line (10 bits per byte at the baud), rejected frame candidates, X-3D DATA of an
    unexpected mask; in the AscTec LL dialect also polls (and unanswered ones) and command
    acknowledgements (and missing ones) with their p50/p99 time [ms]."""

    protocol: str
    seconds: float
    in_bytes_per_s: float
    out_bytes_per_s: float
    in_line_share: float
    out_line_share: float
    rejected: int
    unexpected_data: int
    polls: int | None = None
    polls_unanswered: int | None = None
    acks: int | None = None
    acks_missing: int | None = None
    ack_p50_ms: float | None = None
    ack_p99_ms: float | None = None


def link_figures(summary: FlightSummary) -> LinkFigures | None:
    """:class:`LinkFigures` of a flight (None without link counters)."""
    stats, seconds = summary.link, summary.duration_s
    if stats is None or not seconds > 0:
        return None
    line = summary.baud / 10.0  # bytes per second one way
    ll: dict[str, float | int | None] = {}
    if summary.protocol == "asctec-ll":
        times = sorted(stats.ack_times)
        p50 = 1e3 * times[len(times) // 2] if times else None
        p99 = 1e3 * times[min(len(times) - 1, int(0.99 * len(times)))] if times else None
        ll = {"polls": stats.polls_sent, "polls_unanswered": stats.polls_unanswered,
              "acks": stats.acks, "acks_missing": stats.acks_missing, "ack_p50_ms": p50,
              "ack_p99_ms": p99}
    return LinkFigures(
        summary.protocol, seconds, stats.bytes_in / seconds, stats.bytes_out / seconds,
        stats.bytes_in / seconds / line, stats.bytes_out / seconds / line,
        sum(stats.rejections.values()), stats.unexpected_data, **ll)  # type: ignore[arg-type]


def _drain(vicon: ViconReceiver) -> list[Pose]:
    """Every pose the Vicon reader queued since the last tick (never blocks)."""
    poses = []
    while (pose := vicon.get(0.0)) is not None:
        poses.append(pose)
    return poses
