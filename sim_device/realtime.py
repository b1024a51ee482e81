"""The virtual lab in real time: the X-3D on a pseudo-terminal, the Vicon on UDP.

:func:`run_sim_device` is what ``gs sim-device --config config/sim.yaml`` runs.
It builds a :class:`~sim_device.lab.VirtualLab` from the configuration and keeps
its simulated clock on the wall clock (``time.monotonic``), so the in-process
and the real-time modes share one plant, one firmware and one Vicon.

* **Serial.** ``os.openpty()``; the ground station opens the *slave* path (printed
  and passed to ``on_ready``) like a serial port, e.g. ``serial.Serial(path)``.
  Both ends are raw (no echo, no newline translation). The lab's own slave fd
  stays open so the master never reads a hang-up before a client connects. If
  the client stops reading, the backlog is flushed rather than replayed later.
* **Vicon.** Datagrams go to ``(sim.vicon.target_address, vicon.port)`` over UDP.
* **Clock.** Every ``tick`` (default one plant step) the lab advances to the wall
  time, incoming bytes are written at that time (after a stall of this process, at the
  stall's start: :func:`exchange`), and output is sent when its
  simulated delivery time has come; deadlines advance by the tick (no drift) and
  late ticks are counted as overruns.
* **Wire timing.** The instant each DATA frame's last byte is written to the pty
  and each COMMAND frame is read from it are stamped on the monotonic clock
  (:mod:`sim_device.wire`): the ground station's DATA -> COMMAND latency and its
  COMMAND gaps as the vehicle sees them.
* **Dialect.** ``serial.protocol`` (``gs sim-device --protocol``) picks the vehicle's
  dialect: the X-3D's pushes DATA once CONFIGured; the AscTec LL's answers each poll
  written to the pty and acknowledges each command, and sends nothing unpolled.
* **Unplug.** Setting ``unplug`` closes the pty (a serial adapter pulled out); the
  plant and the Vicon run on, and the vehicle's watchdog hands back to the pilot.
* **Stop.** When ``stop`` is set, after ``duration``, or on SIGINT/SIGTERM (handlers
  are installed only when running in the main thread); the ground truth is written
  as ``.npz`` (:mod:`sim_device.truth`) on every way out, with extra keys:
  ``start_monotonic``, the ``time.monotonic()`` of simulated time 0 [s], so a truth
  row's monotonic time is ``start_monotonic + t`` and the truth lines up with a
  flight log's monotonic stamps (the evaluation's ``gs report LOG --truth``), and the
  wire timing (:data:`sim_device.wire.KEYS`).
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import math
import os
import select
import signal
import socket
import struct
import subprocess
import sys
import termios
import threading
import time
import tty
import zipfile
from collections.abc import Callable
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from groundstation.app.realtime import fifo_priority
from groundstation.app.signals import on_stop_signals
from groundstation.config import dump_config
from groundstation.lab import Announcement
from sim_device.config import sim_section
from sim_device.lab import LabStats, VirtualLab
from sim_device.wire import WireRecord, WireTiming

if TYPE_CHECKING:
    from groundstation.config import GroundStationConfig

BACKLOG_LIMIT = 2048
"""Unread bytes on the pty beyond which the client is taken as not reading [bytes]."""


@dataclass(frozen=True, slots=True)
class SimDeviceInfo:
    """Where the running virtual lab can be reached.

    pty_path : the serial port for the ground station (pty slave path)
    vicon_target : (address, port) the Vicon datagrams are sent to
    truth_file : where the ground truth will be written on exit (.npz)
    protocol : the dialect the vehicle speaks ("x3d" or "asctec-ll")
    """

    pty_path: str
    vicon_target: tuple[str, int]
    truth_file: Path
    protocol: str = "x3d"

    @property
    def announcement(self) -> Announcement:
        """The same, as the JSON line ``gs sim-device --json`` prints first."""
        return Announcement(self.pty_path, self.vicon_target, self.truth_file)


@dataclass(frozen=True, slots=True)
class SimDeviceResult:
    """Summary of a real-time run.

    wall_s, cpu_s : wall-clock and process CPU time of the run [s]
    overruns : ticks that started more than one tick late
    serial_dropped : DATA bytes discarded because the client was not reading
    vicon_errors : datagrams the socket refused
    wire : DATA-out and COMMAND-in instants at the vehicle's port (:mod:`sim_device.wire`)
    """

    info: SimDeviceInfo
    stats: LabStats
    wall_s: float
    cpu_s: float
    overruns: int
    serial_dropped: int
    vicon_errors: int
    wire: WireRecord

    @property
    def cpu_share(self) -> float:
        """CPU time over wall time (1.0 = one core busy)."""
        return self.cpu_s / self.wall_s if self.wall_s > 0 else 0.0


def default_truth_path(config: GroundStationConfig) -> Path:
    """``sim.truth_file`` if set, else ``<logging.flight_log_dir>/sim-truth-<UTC time>.npz``."""
    sim = sim_section(config)
    if sim.truth_file is not None:
        return Path(sim.truth_file)
    stamp = datetime.now(UTC).strftime("%Y%m%dT%H%M%SZ")
    return Path(config.logging.flight_log_dir) / f"sim-truth-{stamp}.npz"


class _Pty:
    """A raw pty pair; the master side is non-blocking."""

    def __init__(self) -> None:
        self.master, self.slave = os.openpty()
        try:
            tty.setraw(self.master)
            tty.setraw(self.slave)
            os.set_blocking(self.master, False)
            self.path = os.ttyname(self.slave)
        except BaseException:
            self.close()
            raise
        self.dropped = 0

    def read(self) -> bytes:
        """Everything the client has written so far (b"" if nothing)."""
        parts = []
        while True:
            try:
                chunk = os.read(self.master, 4096)
            except (BlockingIOError, InterruptedError):
                break
            except OSError as exc:  # EIO: no client side open (cannot happen while we hold it)
                if exc.errno != errno.EIO:
                    raise
                break
            if not chunk:
                break
            parts.append(chunk)
        return b"".join(parts)

    def write(self, data: bytes) -> None:
        """Send to the client; if it is not reading, discard the backlog instead of queueing."""
        waiting = struct.unpack("i", fcntl.ioctl(self.slave, termios.FIONREAD, b"\0\0\0\0"))[0]
        if waiting > BACKLOG_LIMIT:
            termios.tcflush(self.slave, termios.TCIFLUSH)
            self.dropped += waiting
        try:
            sent = os.write(self.master, data)
        except BlockingIOError:
            sent = 0
        self.dropped += len(data) - sent

    @property
    def closed(self) -> bool:
        """True once :meth:`close` ran (the adapter is unplugged)."""
        return self.master < 0

    def close(self) -> None:
        """Close both ends (idempotent): the client's reads fail from now on."""
        for fd in (self.master, self.slave):
            if fd >= 0:
                with contextlib.suppress(OSError):
                    os.close(fd)
        self.master = self.slave = -1


def run_sim_device(
    config: GroundStationConfig,
    stop: threading.Event | None = None,
    *,
    truth_file: str | Path | None = None,
    on_ready: Callable[[SimDeviceInfo], None] | None = None,
    announce: Callable[[str], None] | None = print,
    duration: float | None = None,
    tick: float | None = None,
    unplug: threading.Event | None = None,
) -> SimDeviceResult:
    """Run the virtual X-3D (pty) and virtual Vicon (UDP) in real time until stopped.

    config : the whole configuration (``sim`` section, vehicle model, ``serial.baud``,
        ``crc_profile`` and ``protocol`` (with ``serial.ll``), ``vicon.port`` and
        ``object_name``; ``sim`` None = defaults)
    stop : set it to stop (from another thread); SIGINT/SIGTERM also stop the run
        when it runs in the main thread
    truth_file : ground-truth path (.npz); default :func:`default_truth_path`
    on_ready : called once with the pty path and UDP target before the clock starts
    announce : where the human-readable lines go (None = silent)
    duration : stop after this many wall seconds (None = until stopped)
    tick : scheduler period [s] (default the plant step)
    unplug : set it to close the pty while the lab runs on (a pulled serial adapter)

    Returns a :class:`SimDeviceResult`; the truth file is written on every way out.
    """
    stop = stop if stop is not None else threading.Event()
    lab = VirtualLab(config)
    sim = sim_section(config)
    target = (sim.vicon.target_address, config.vicon.port)
    info_path = Path(truth_file) if truth_file is not None else default_truth_path(config)
    tick = lab.dt if tick is None else tick
    say = announce if announce is not None else (lambda _line: None)
    pty = _Pty()
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    counters = {"overruns": 0, "vicon_errors": 0}
    wire = WireTiming(lab.params.link.crc_profile, lab.protocol)
    wall0, cpu0 = time.monotonic(), time.process_time()
    start = wall0  # simulated time 0 on the monotonic clock; reset when the clock starts
    try:
        info = SimDeviceInfo(pty.path, target, info_path.with_suffix(".npz"), lab.protocol)
        if on_ready is not None:
            on_ready(info)
        dialect = ", AscTec LL dialect: answers polls" if lab.protocol == "asctec-ll" else ""
        say(f"virtual X-3D on {pty.path} ({lab.params.link.baud} baud{dialect}); "
            f"virtual Vicon -> udp://{target[0]}:{target[1]} at {lab.params.vicon.rate_hz:g} Hz")
        with on_stop_signals(lambda _sig: stop.set()), \
                fifo_priority(sim.fifo_priority, who="virtual vehicle"):
            start = time.monotonic()
            _loop(lab, _Io(pty, sock, target, wire, unplug), stop, tick, duration, counters,
                  start)
    finally:
        wall, cpu = time.monotonic() - wall0, time.process_time() - cpu0
        sock.close()
        pty.close()
        saved = lab.truth_log.save(info_path)
        _add_arrays(saved, {"start_monotonic": np.array(start, dtype=float), **wire.arrays()})
        say(f"ground truth ({len(lab.truth_log)} rows) written to {saved}")
    return SimDeviceResult(info, lab.stats(), wall, cpu, counters["overruns"], pty.dropped,
                           counters["vicon_errors"], wire.record())


def _add_arrays(path: Path, arrays: dict[str, np.ndarray]) -> None:
    """Add ``arrays`` to a saved truth ``.npz``: one more ``.npy`` member each, exactly as
    ``np.savez`` writes them, so ``np.load(path)["start_monotonic"]`` reads it."""
    with zipfile.ZipFile(path, "a", compression=zipfile.ZIP_DEFLATED) as archive:
        for name, value in arrays.items():
            with archive.open(f"{name}.npy", "w") as member:
                np.lib.format.write_array(member, value)


@dataclass
class _Io:
    """The real-time loop's ports: the pty, the Vicon socket and the wire timing."""

    pty: _Pty
    sock: socket.socket
    target: tuple[str, int]
    wire: WireTiming
    unplug: threading.Event | None


STALL_S = 0.02
"""A wake-up of the real-time loop this much later than the time the lab was advanced to
[s] (ten plant steps; the loop wakes every step or on a byte) is a stall of the virtual
lab's own process: a loaded machine did not run it."""


def exchange(lab: VirtualLab, now: float, incoming: bytes) -> list[tuple[float, bytes]]:
    """Advance ``lab`` to ``now`` [s] with ``incoming``, the bytes this wake-up read from the
    ground station; the frames due (:meth:`VirtualLab.advance_to`).

    The bytes go in after the advance, at the instant the ground station's write woke the
    loop. After a stall of this process (a wake-up more than :data:`STALL_S` late) they were
    written at unknown instants during it, and a stall of the simulator is not a COMMAND gap
    of the ground station (the vehicle's 100 ms watchdog would hand back to the pilot for
    it): they go in spread evenly over the stall, from its start, in pieces at most
    :data:`STALL_S` apart. A ground station that wrote nothing meanwhile is judged by its
    gap as before."""
    late = now - lab.t
    if not incoming or late <= STALL_S:
        frames = lab.advance_to(now)
        if incoming:
            lab.write(incoming)
        return frames
    frames = []
    start = lab.t
    pieces = math.ceil(late / STALL_S)
    size = math.ceil(len(incoming) / pieces)
    for k in range(pieces):
        frames += lab.advance_to(start + late * k / pieces)
        lab.write(incoming[k * size:(k + 1) * size])
    frames += lab.advance_to(now)
    return frames


def _loop(lab: VirtualLab, io: _Io, stop: threading.Event, tick: float,
          duration: float | None, counters: dict[str, int], start: float) -> None:
    """The real-time loop: advance to the wall clock, exchange bytes, sleep to the next tick.

    start : ``time.monotonic()`` of simulated time 0 [s]. Bytes from the ground station
    are read (and stamped) before the lab advances, and handed to the lab by
    :func:`exchange`: the stamp is the instant the ground station's write woke the loop.
    """
    deadline = tick
    end = float("inf") if duration is None else duration
    pty, wire = io.pty, io.wire
    while not stop.is_set():
        now = time.monotonic() - start
        if now >= end:
            break
        if io.unplug is not None and io.unplug.is_set() and not pty.closed:
            pty.close()
        incoming = b"" if pty.closed else pty.read()
        if incoming:
            wire.received(time.monotonic(), incoming)
        for _, frame in exchange(lab, now, incoming):
            if not pty.closed:
                pty.write(frame)
                wire.frame_sent(time.monotonic(), frame)
        for dgram in lab.vicon_datagrams():
            try:
                io.sock.sendto(dgram.data, io.target)
            except OSError:
                counters["vicon_errors"] += 1
        if now > deadline + tick:
            counters["overruns"] += 1
            deadline = now
        while deadline <= now:
            deadline += tick
        timeout = max(0.0, min(deadline, end) - now)
        if pty.closed:
            stop.wait(timeout)
        else:
            select.select([pty.master], [], [], timeout)


class SimDeviceThread:
    """Run :func:`run_sim_device` in a background thread for a ``with`` block.

    ``with SimDeviceThread(config) as dev:`` returns once the pty exists;
    ``dev.info`` says where to connect. Leaving the block stops the run, joins the
    thread (the truth file is then written), fills ``dev.result`` and re-raises
    the run's error as RuntimeError, if there was one.
    """

    def __init__(self, config: GroundStationConfig, *, truth_file: str | Path | None = None,
                 timeout: float = 5.0) -> None:
        self._config = config
        self._truth_file = truth_file
        self._timeout = timeout
        self._stop = threading.Event()
        self._unplug = threading.Event()
        self._ready = threading.Event()
        self._info: SimDeviceInfo | None = None
        self.result: SimDeviceResult | None = None
        self.error: BaseException | None = None
        self._thread = threading.Thread(target=self._run, name="sim-device", daemon=True)

    @property
    def info(self) -> SimDeviceInfo:
        """Where to connect (available inside the ``with`` block)."""
        if self._info is None:
            raise RuntimeError("the virtual lab is not running")
        return self._info

    def unplug(self) -> None:
        """Pull the serial adapter: the pty closes at the next tick, the lab runs on."""
        self._unplug.set()

    def _on_ready(self, info: SimDeviceInfo) -> None:
        self._info = info
        self._ready.set()

    def _run(self) -> None:
        try:
            self.result = run_sim_device(self._config, self._stop, truth_file=self._truth_file,
                                         on_ready=self._on_ready, announce=None,
                                         unplug=self._unplug)
        except BaseException as exc:  # handed to the caller's thread in __exit__
            self.error = exc
        finally:
            self._ready.set()

    def __enter__(self) -> SimDeviceThread:
        self._thread.start()
        if not self._ready.wait(self._timeout) or self._info is None:
            self.__exit__(None, None, None)
            raise RuntimeError("the virtual lab did not start") from self.error
        return self

    def __exit__(self, *exc_info: object) -> None:
        self._stop.set()
        self._thread.join(self._timeout)
        if self.error is not None:
            raise RuntimeError("the virtual lab failed") from self.error


class SimDeviceProcess:
    """Run ``gs sim-device`` in a child process for a ``with`` block.

    The virtual vehicle then keeps its own interpreter: a pause of the ground station's
    process (its garbage collector, a loaded core) does not stall the vehicle's clock,
    so the vehicle's watchdog and the wire timing see the ground station as a real
    X-3D would. ``with SimDeviceProcess(config_file, truth_file) as dev:`` returns once
    the child announced itself (``gs sim-device --json``: ``dev.announcement``,
    ``dev.pty_path``); leaving the block stops the child with SIGINT,
    waits for its truth file and loads the wire record into ``dev.wire``. The child
    has a session of its own: a Ctrl-C at the terminal reaches the ground station
    (which lands), not the vehicle.

    config_file : a YAML configuration with a ``sim`` section and the Vicon port
    truth_file : where the child writes the ground truth (.npz)
    gs : the ``gs`` executable (default: next to this interpreter, else this
        interpreter running the CLI)
    protocol : the vehicle's dialect ("x3d" or "asctec-ll", ``--protocol``); None = the
        configuration's ``serial.protocol``
    """

    def __init__(self, config_file: str | Path, truth_file: str | Path, *,
                 gs: str | Path | None = None, timeout: float = 30.0,
                 duration: float | None = None, stderr: Path | None = None,
                 protocol: str | None = None) -> None:
        exe = Path(gs) if gs is not None else Path(sys.executable).parent / "gs"
        command = [str(exe)] if exe.exists() else [
            sys.executable, "-c", "from groundstation.cli import main; main()"]
        self.truth_file = Path(truth_file)
        self._timeout = timeout
        self._stderr = stderr
        self._args = [*command, "sim-device", "--json", "--config", str(config_file),
                      "--truth-file", str(self.truth_file)]
        if duration is not None:  # bounds the child should this process die without stopping it
            self._args += ["--duration", f"{duration:g}"]
        if protocol is not None:
            self._args += ["--protocol", protocol]
        self._child: subprocess.Popen[str] | None = None
        self._announcement: Announcement | None = None
        self.pty_path = ""
        self.output = ""
        """What the child printed after its first line (read when the block ends)."""
        self.wire: WireRecord | None = None

    @classmethod
    def for_config(cls, config: GroundStationConfig, workdir: Path) -> SimDeviceProcess:
        """The lab for ``config``: its YAML written to ``workdir``, the truth to
        :func:`default_truth_path` (``gs fly --demo``)."""
        truth_file = default_truth_path(config)
        truth_file.parent.mkdir(parents=True, exist_ok=True)
        config_file = Path(workdir) / "sim.yaml"
        config_file.write_text(dump_config(config), encoding="utf-8")
        return cls(config_file, truth_file)

    def __enter__(self) -> SimDeviceProcess:
        if self._stderr is not None:
            with self._stderr.open("w") as err:
                self._child = subprocess.Popen(self._args, stdout=subprocess.PIPE, stderr=err,
                                               text=True, start_new_session=True)
        else:
            self._child = subprocess.Popen(self._args, stdout=subprocess.PIPE, text=True,
                                           start_new_session=True)
        assert self._child.stdout is not None
        ready, _, _ = select.select([self._child.stdout], [], [], self._timeout)
        line = self._child.stdout.readline() if ready else ""
        try:
            self._announcement = Announcement.from_json(line)
        except ValueError as exc:
            self.__exit__(None, None, None)
            where = f"; see {self._stderr}" if self._stderr is not None else ""
            raise RuntimeError(f"gs sim-device did not start: {line.strip()!r}{where}") from exc
        self.pty_path = self._announcement.serial_port
        return self

    @property
    def announcement(self) -> Announcement:
        """Where the child is, as it announced itself (inside the ``with`` block)."""
        if self._announcement is None:
            raise RuntimeError("the virtual lab is not running")
        return self._announcement

    def __exit__(self, *exc_info: object) -> None:
        child = self._child
        if child is None:
            return
        self._child = None
        if child.poll() is None:
            child.send_signal(signal.SIGINT)
        try:
            self.output = child.communicate(timeout=self._timeout)[0]
        except subprocess.TimeoutExpired:
            child.kill()
            self.output = child.communicate()[0]
        if self.truth_file.exists():
            self.wire = WireRecord.load(self.truth_file)
