"""The real-time flight daemon behind ``gs fly``.

Owns every thread, socket and clock of a flight: the serial link (reader and
keep-alive threads), the Vicon client (reader thread), the flight recorder, the
telemetry publisher, systemd notification and the signal handlers. Each tick it
hands the sans-IO :class:`~groundstation.loop.core.FlightCore` one DATA sample
and the Vicon poses that arrived since the last tick.

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

While flying, the daemon holds a PM QoS request for CPU wake-up latency
(``realtime.cpu_dma_latency_us``, default 0 us) so the CPUs do not drop into
deep idle states between DATA samples, and shortens the interpreter's thread
switch interval to ``realtime.switch_interval_ms`` (0.5 ms; default 5 ms) so a
reader thread holding the GIL cannot delay a tick by more (see
:mod:`groundstation.loop.realtime`).

Stopping: the first SIGINT/SIGTERM asks the supervisor to land (or hand back,
see ``safety.on_signal``), a second one hands back at once. Whatever the way
out, the link sends a final COMMAND with ctrl mask 0, the flight log is flushed
and closed, and systemd hears STOPPING.
"""

from __future__ import annotations

import math
import signal
import threading
import time
from collections.abc import Callable
from contextlib import ExitStack
from dataclasses import dataclass, field
from functools import partial

import numpy as np
import structlog

from groundstation.asctec.link import SerialLink
from groundstation.asctec.messages import CHANNELS, ConfigMsg
from groundstation.config import GroundStationConfig, dump_config
from groundstation.control.base import Controller
from groundstation.control.trajectory import Trajectory
from groundstation.loop.core import FlightCore, TickResult
from groundstation.loop.inputs import DataFrontEnd
from groundstation.loop.realtime import cpu_latency_request, switch_interval
from groundstation.loop.recorder import FlightRecorder
from groundstation.loop.sdnotify import SdNotifier
from groundstation.loop.signals import on_stop_signals
from groundstation.loop.supervisor import State, Transition
from groundstation.loop.ticklog import TickLogger
from groundstation.loop.timing import TimingHistogram
from groundstation.telemetry.control import ControlServer, Reply, Request
from groundstation.telemetry.publisher import TelemetryPublisher
from groundstation.telemetry.schema import health_payload, state_payload
from groundstation.types import Pose
from groundstation.vicon.client import ViconClient

log = structlog.get_logger(__name__)

RESEND_CONFIG_AFTER_S = 0.5
"""Re-send CONFIG when no DATA arrived for this long (spec 3.1: stream stopped)."""


@dataclass
class FlightSummary:
    """What a flight did, for the CLI's closing lines and the benchmarks.

    final_state, success : the supervisor's terminal state; True for a normal end
    transitions : every state change with its reason
    log_dir : the flight log directory
    track_rms_m, track_max_m : estimate-vs-reference 3-D error while tracking [m]
    compute, jitter, latency : per-tick timing histograms [s] (see the module docstring)
    data_interval : spacing of the received DATA frames [s]
    commands_sent, ticks : counters; duration_s : wall time of the loop [s]
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


class FlightDaemon:
    """One real-time flight. Build it, then :meth:`run` it (blocks until the flight ends).

    config : validated configuration (``serial.port`` is the X-3D)
    duration_s : trajectory time before landing (default one trajectory period)
    controller, trajectory : replace the ones the configuration names
    progress : called about once a second with a one-line status
    stop : an extra way to ask for a stop (counts like a signal), e.g. from a test
    """

    def __init__(self, config: GroundStationConfig, *, duration_s: float | None = None,
                 controller: Controller | None = None, trajectory: Trajectory | None = None,
                 progress: Callable[[str], None] | None = None,
                 stop: threading.Event | None = None) -> None:
        self.config = config
        self.core = FlightCore(config, controller=controller, trajectory=trajectory,
                               duration_s=duration_s)
        self._front = DataFrontEnd(config)
        self._progress = progress
        self._stop_event = stop
        self._signals = [0]
        self._period = config.serial.data_period_ms / 1000.0
        self._config_msg = ConfigMsg(config.serial.sensor_mask, config.serial.data_period_ms)
        self._stats = _Stats()
        self.log_dir = ""
        self.telemetry_endpoint: str | None = None
        """The bound telemetry endpoint once :meth:`run` has started (``*`` ports resolved)."""
        self.control_endpoint: str | None = None
        """The bound control endpoint (``gs channels``) once :meth:`run` has started."""
        self.ready = threading.Event()
        """Set once every resource is open and the loop is about to start."""

    def _on_signal(self, sig: signal.Signals) -> None:
        self._signals[0] += 1
        log.warning("signal", signal=sig.name, count=self._signals[0])

    @property
    def stop_requests(self) -> int:
        """Signals received plus one if the stop event is set."""
        extra = 1 if self._stop_event is not None and self._stop_event.is_set() else 0
        return self._signals[0] + extra

    def run(self) -> FlightSummary:
        """Fly. Raises LinkError/ViconError/GroundStationError if a resource cannot be opened;
        once flying, failures are supervisor transitions and the flight ends with a summary."""
        cfg = self.config
        notifier = SdNotifier.from_env()
        with ExitStack() as stack:
            stack.callback(notifier.stopping, "stopping: vehicle handed back")
            link = SerialLink.from_config(cfg.serial)
            stack.callback(link.close)  # sends the final COMMAND with ctrl mask 0
            vicon = ViconClient.from_config(cfg.vicon).start()
            stack.callback(vicon.close)
            recorder = FlightRecorder.create(cfg.logging.flight_log_dir, dump_config(cfg),
                                             {"supervisor_states": [s.name for s in State]})
            stack.callback(recorder.close)
            self.log_dir = str(recorder.directory)
            telemetry = TelemetryPublisher.from_config(cfg.telemetry)
            stack.callback(telemetry.close)
            self.telemetry_endpoint = telemetry.endpoint
            control = ControlServer.from_config(cfg.telemetry)
            stack.callback(control.close)
            self.control_endpoint = control.endpoint
            stack.enter_context(on_stop_signals(self._on_signal))
            stack.enter_context(cpu_latency_request(cfg.realtime.cpu_dma_latency_us))
            stack.enter_context(switch_interval(cfg.realtime.switch_interval_ms / 1000.0))
            link.send(self._config_msg)
            notifier.ready("preflight")
            self.ready.set()
            log.info("flight starting", port=cfg.serial.port, vicon_port=cfg.vicon.port,
                     log=self.log_dir, controller=cfg.controller.type)
            self._loop(link, vicon, recorder, telemetry, control, notifier)
        return self._summary()

    # ------------------------------------------------------------------ the loop
    def _loop(self, link: SerialLink, vicon: ViconClient, recorder: FlightRecorder,
              telemetry: TelemetryPublisher, control: ControlServer,
              notifier: SdNotifier) -> None:
        core = self.core
        ticklog = TickLogger(recorder)
        wd_interval = notifier.watchdog_interval()
        next_wd = next_progress = last_config = -math.inf
        t_prev = self._stats.t_start = time.monotonic()
        t_rx_prev = math.nan
        while not core.supervisor.terminal:
            deadline = t_prev + 1.5 * self._period
            rx = link.get(timeout=max(0.0, deadline - time.monotonic()))
            start = time.monotonic()
            poses = _drain(vicon)
            imu = None
            if rx is not None:
                imu = self._front.receive(rx.t, rx.msg)
                scheduled = rx.t
                self._stats.data_interval.add(rx.t - t_rx_prev)
                t_rx_prev = rx.t
            else:
                scheduled = deadline
                if start - last_config > RESEND_CONFIG_AFTER_S and \
                        self._front.data_age(start) > RESEND_CONFIG_AFTER_S:
                    link.send(self._config_msg)  # the stream stopped: ask for it again
                    last_config = start
            vicon_rate, vicon_age = vicon.rate_and_age()
            health = self._front.health(start, vicon_age, vicon_rate)
            result = core.tick(start, imu, poses, self._front.status, health, self.stop_requests)
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
            telemetry.maybe_publish(start, partial(self._snapshot, result, link, vicon))
            control.poll(self.handle_request)
            if wd_interval is not None and start >= next_wd:
                notifier.watchdog()
                next_wd = start + wd_interval / 2
            if self._progress is not None and start >= next_progress:
                self._progress(self._progress_line(result, health.data_rate_hz, vicon_rate))
                next_progress = start + 1.0
            t_prev = start
        self._stats.t_end = time.monotonic()

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
        """Answer one run-time request (see :mod:`groundstation.telemetry.control`).

        ``channels`` with ``auto`` (a non-empty list of channel names) hands exactly
        those channels to the controller from the next COMMAND, bumpless; the rest go
        to the pilot at once. An empty set is refused: handing everything back is
        the pilot's serial-enable switch (or a stop), which the supervisor follows.
        """
        if request.get("request") != "channels":
            return {"ok": False, "error": f"unknown request {request.get('request')!r} "
                                          "(known: 'channels')"}
        core = self.core
        if "auto" in request:
            auto = request["auto"]
            if not isinstance(auto, list) or not auto or \
                    any(c not in CHANNELS for c in auto) or len(set(auto)) != len(auto):
                return {"ok": False, "error": f"'auto' must list one or more of {list(CHANNELS)} "
                                              f"once each, got {auto!r}"}
            core.set_auto_channels(auto)
            log.info("channels", auto=auto, state=core.state.name)
        auto_now = core.auto_channels
        return {"ok": True, "auto": [c for c in CHANNELS if c in auto_now],
                "state": core.state.name}

    def _snapshot(self, result: TickResult, link: SerialLink, vicon: ViconClient
                  ) -> dict[str, dict[str, object]]:
        sticks = result.sticks if result.sticks is not None else self._front.status.pilot
        stats = link.stats()
        return {
            "state": state_payload(state=int(result.state), state_name=result.state.name,
                                   estimate=result.estimate, reference=result.reference,
                                   sticks=sticks, ctrl_mask=result.command.ctrl,
                                   sent=result.due),
            "health": health_payload(
                link={"rate_hz": stats.data_rate_hz, "rejected": dict(stats.rejections)},
                vicon=vicon.health(), estimator=self.core.ekf.health()
                if self.core.init_report is not None else None,
                loop={"ticks": self._stats.ticks, "commands": self._stats.sent}),
        }

    def _progress_line(self, result: TickResult, data_hz: float, vicon_hz: float) -> str:
        err = "-"
        if result.estimate is not None:
            e = float(np.linalg.norm(result.reference.position - result.estimate.position))
            err = f"{100 * e:5.1f} cm"
        return (f"{result.state.name:<9} error {err}  DATA {data_hz:5.1f} Hz  "
                f"Vicon {vicon_hz:5.1f} Hz  mask 0x{result.command.ctrl:X}")

    def _summary(self) -> FlightSummary:
        s, sup = self._stats, self.core.supervisor
        return FlightSummary(
            final_state=sup.state, success=sup.success, transitions=list(sup.transitions),
            log_dir=self.log_dir,
            track_rms_m=math.sqrt(s.track_sq / s.track_n) if s.track_n else math.nan,
            track_max_m=s.track_max if s.track_n else math.nan,
            compute=s.compute, jitter=s.jitter, latency=s.latency,
            data_interval=s.data_interval, commands_sent=s.sent,
            ticks=s.ticks, duration_s=s.t_end - s.t_start,
        )


def _drain(vicon: ViconClient) -> list[Pose]:
    """Every pose the Vicon reader queued since the last tick (never blocks)."""
    poses = []
    while (pose := vicon.get(0.0)) is not None:
        poses.append(pose)
    return poses
