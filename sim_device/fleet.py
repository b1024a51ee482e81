"""A virtual fleet in real time: N virtual X-3Ds on N pseudo-terminals, one virtual
Vicon Tracker sending all of them in one UDP stream.

``gs sim-device --vehicles N`` (or ``--fleet fleet.yaml``) runs it. Each vehicle is a
:class:`~sim_device.lab.VirtualLab` of its own (its plant, firmware, radio, pty, seed,
truth), built from that vehicle's configuration: with ``--fleet`` exactly what its daemon
flies (:meth:`groundstation.config.fleetfile.FleetFile.vehicle_config`: its Vicon object,
its home as ``sim.initial_position``, its own ``sim.*`` overrides); with ``--vehicles N``
the base configuration with objects ``<vicon.object_name>-1 .. -N`` standing
:data:`DEFAULT_SPACING_M` apart along north (x) around ``trajectory.center``. The labs step on
one wall clock; every Vicon sample instant, the datagrams the labs produced for it are
merged into one datagram carrying every object (the Tracker's own frame number, each
object's lost-tracking encoding kept: a vehicle out of view is missing from it, or
zero, or held), sent to ``(sim.vicon.target_address, vicon.port)``: what a relay or a
daemon reading the stream itself receives from a real Tracker.

On every way out each vehicle's truth is written to ``<truth stem>-<name>.npz`` with its
``start_monotonic`` and wire timing, as ``gs sim-device`` writes one.
``--json`` prints one line first: ``{"vicon_target": [address, port], "vehicles":
[{"name", "serial_port", "vicon_object", "truth_file"}, ...]}``.
"""

from __future__ import annotations

import json
import select
import socket
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from groundstation.app.realtime import fifo_priority
from groundstation.app.signals import on_stop_signals
from groundstation.config import apply_overrides
from groundstation.vicon.decoder import (
    MAX_ITEMS,
    OBJECT_ITEM_SIZE,
    ViconFrame,
    decode_datagram,
    encode_datagram,
)
from sim_device.config import sim_section
from sim_device.lab import VirtualLab
from sim_device.realtime import _add_arrays, _Pty, default_truth_path, exchange
from sim_device.vicon import ViconDatagram
from sim_device.wire import WireTiming

if TYPE_CHECKING:
    from groundstation.config import GroundStationConfig

DEFAULT_SPACING_M = 1.0
"""How far apart ``--vehicles N`` places its vehicles along north (x) [m]."""


@dataclass(frozen=True, slots=True)
class FleetVehicle:
    """One virtual vehicle of the fleet: its name, configuration and truth file."""

    name: str
    config: GroundStationConfig
    truth_file: Path


def vehicles_in_a_row(config: GroundStationConfig, n: int, truth_file: Path,
                      spacing_m: float = DEFAULT_SPACING_M) -> list[FleetVehicle]:
    """``n`` vehicles ``v1..vN`` with objects ``<object_name>-1..-N``, on the floor
    ``spacing_m`` apart along north (x), centred under ``trajectory.center``."""
    cx, cy, _ = config.trajectory.center
    out = []
    for k in range(n):
        x = cx + (k - (n - 1) / 2.0) * spacing_m
        cfg = apply_overrides(config, {
            "vicon.object_name": f"{config.vicon.object_name}-{k + 1}",
            "sim.initial_position": [x, cy, 0.0],
            "sim.seed": sim_section(config).seed + k})
        out.append(FleetVehicle(f"v{k + 1}", cfg, _truth_for(truth_file, f"v{k + 1}")))
    return out


def vehicles_of_fleet(path: str | Path, truth_file: Path) -> list[FleetVehicle]:
    """The vehicles of a fleet file, each with the configuration its daemon flies."""
    from groundstation.config.fleetfile import load_fleet

    fleet, base = load_fleet(path)
    return [FleetVehicle(name, fleet.vehicle_config(base, name), _truth_for(truth_file, name))
            for name in fleet.names]


def _truth_for(truth_file: Path, name: str) -> Path:
    return truth_file.with_name(f"{truth_file.stem}-{name}.npz")


def merge_datagrams(groups: Sequence[Sequence[ViconDatagram]], pad_to: int | None
                    ) -> list[tuple[float, bytes]]:
    """One datagram per Vicon instant from every lab's datagrams of that instant
    (``groups[k]``: lab k's, in order; the labs sample on one schedule, so the i-th of each
    belong together; a lab with fewer, paused, is missing from the later ones). Items
    keep their encoding; the frame number is the largest of the instant's. (delivery
    time [s], bytes) in order."""
    out = []
    for i in range(max((len(g) for g in groups), default=0)):
        here = [g[i] for g in groups if i < len(g)]
        frames = [f for f in (decode_datagram(d.data) for d in here) if isinstance(f, ViconFrame)]
        objects = [obj for f in frames for obj in f.objects][:MAX_ITEMS]
        number = max((f.frame for f in frames), default=0)
        size = 5 + OBJECT_ITEM_SIZE * len(objects)
        pad = pad_to if pad_to is not None and size <= pad_to else None
        out.append((min(d.t for d in here), encode_datagram(number, objects, pad)))
    return out


@dataclass
class _Vehicle:
    spec: FleetVehicle
    lab: VirtualLab
    pty: _Pty
    wire: WireTiming


def run_fleet(vehicles: Sequence[FleetVehicle], stop: threading.Event | None = None, *,
              on_ready: Callable[[dict[str, object]], None] | None = None,
              announce: Callable[[str], None] | None = print,
              duration: float | None = None) -> None:
    """Run the virtual fleet in real time until ``stop``, ``duration`` [s] or
    SIGINT/SIGTERM (in the main thread); every vehicle's truth is written on every way out.
    ``on_ready`` gets the announcement (see the module docstring) before the clock starts."""
    stop = stop if stop is not None else threading.Event()
    say = announce if announce is not None else (lambda _line: None)
    first = vehicles[0].config
    sim = sim_section(first)
    target = (sim.vicon.target_address, first.vicon.port)
    fleet: list[_Vehicle] = []
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    start = time.monotonic()
    try:
        for spec in vehicles:
            lab = VirtualLab(spec.config)
            pty = _Pty()
            fleet.append(_Vehicle(spec, lab, pty, WireTiming(lab.params.link.crc_profile,
                                                             lab.protocol)))
        info: dict[str, object] = {"vicon_target": list(target), "vehicles": [
            {"name": v.spec.name, "serial_port": v.pty.path,
             "vicon_object": v.spec.config.vicon.object_name,
             "truth_file": str(v.spec.truth_file)} for v in fleet]}
        if on_ready is not None:
            on_ready(info)
        for v in fleet:
            say(f"virtual X-3D {v.spec.name} ({v.spec.config.vicon.object_name}) on "
                f"{v.pty.path}")
        say(f"virtual Vicon: {len(fleet)} objects -> udp://{target[0]}:{target[1]}")
        with on_stop_signals(lambda _sig: stop.set()), \
                fifo_priority(sim.fifo_priority, who="virtual fleet"):
            start = time.monotonic()
            _loop(fleet, sock, target, stop, duration, start, fleet[0].lab.params.vicon.pad_to)
    finally:
        sock.close()
        for v in fleet:
            v.pty.close()
            saved = v.lab.truth_log.save(v.spec.truth_file)
            _add_arrays(saved, {"start_monotonic": np.array(start, dtype=float),
                                **v.wire.arrays()})
            say(f"ground truth of {v.spec.name} ({len(v.lab.truth_log)} rows) written to "
                f"{saved}")


def _loop(fleet: Sequence[_Vehicle], sock: socket.socket, target: tuple[str, int],
          stop: threading.Event, duration: float | None, start: float,
          pad_to: int | None) -> None:
    tick = fleet[0].lab.dt
    deadline = tick
    end = float("inf") if duration is None else duration
    masters = [v.pty.master for v in fleet]
    while not stop.is_set():
        now = time.monotonic() - start
        if now >= end:
            break
        groups = []
        for v in fleet:
            incoming = v.pty.read()
            if incoming:
                v.wire.received(time.monotonic(), incoming)
            for _, frame in exchange(v.lab, now, incoming):
                v.pty.write(frame)
                v.wire.frame_sent(time.monotonic(), frame)
            groups.append(v.lab.vicon_datagrams())
        for _, data in merge_datagrams(groups, pad_to):
            try:
                sock.sendto(data, target)
            except OSError:
                continue  # nobody listening yet: Tracker does not care either
        while deadline <= now:
            deadline += tick
        select.select(masters, [], [], max(0.0, min(deadline, end) - now))


def run_fleet_command(config: GroundStationConfig, *, vehicles: int | None,
                      fleet_file: Path | None, truth_file: Path | None, json_line: bool,
                      duration: float | None, echo: Callable[[str], None]) -> None:
    """``gs sim-device --vehicles N | --fleet FILE``: build the vehicles and run them."""
    truth = Path(truth_file) if truth_file is not None else default_truth_path(config)
    if fleet_file is not None:
        specs = vehicles_of_fleet(fleet_file, truth)
    else:
        specs = vehicles_in_a_row(config, vehicles or 1, truth)
    run_fleet(specs, on_ready=(lambda info: echo(json.dumps(info))) if json_line else None,
              announce=echo, duration=duration)
