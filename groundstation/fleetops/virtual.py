"""A virtual fleet as processes: the lab, the relay and one daemon per vehicle.

:class:`VirtualFleet` is what ``gs fleet demo``, the fleet's end-to-end tests and
``benchmarks/bench_fleet.py`` fly: ``gs sim-device --fleet FILE`` (the installed virtual
lab, a process of its own: the ground station never imports it), then, from the ptys it
announces, a copy of the fleet file naming them as the serial ports, and
:class:`~groundstation.fleetops.manager.FleetProcesses` on that copy (``gs vicon-relay`` and
one ``gs fleet fly`` per vehicle). Every process talks to the others only over ptys,
UDP and Zenoh on loopback.

:func:`write_fleet` writes a fleet file for a virtual lab: a base configuration with a
free Vicon port and the flight logs in the work directory, the vehicles at the homes
given, every Zenoh endpoint on a free loopback port.
"""

from __future__ import annotations

import json
import select
import signal
import socket
import subprocess
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import yaml

from groundstation.config import GroundStationConfig, apply_overrides, dump_config
from groundstation.endpoints import free_ports
from groundstation.errors import GroundStationError
from groundstation.fleetops.manager import FleetProcesses, gs_command

LAB_START_S = 60.0
"""How long the virtual lab may take to announce itself [s] (a loaded machine)."""


def write_fleet(workdir: Path, base: GroundStationConfig, homes: Sequence[tuple[float, float]],
                *, name: str = "demo", separation_m: float | None = 0.4,
                overrides: Mapping[str, Mapping[str, Any]] | None = None,
                extra: Mapping[str, Any] | None = None) -> Path:
    """A fleet file in ``workdir`` for a virtual lab of ``len(homes)`` vehicles ``v1..vN``
    (objects ``X3D-1..N``) standing at ``homes`` (NED x, y [m]); ``overrides``: per vehicle
    name, configuration keys; ``extra``: more top-level keys of the fleet file."""
    workdir.mkdir(parents=True, exist_ok=True)
    vicon_port = free_ports(1, socket.SOCK_DGRAM)[0]
    cfg = apply_overrides(base, {"vicon.port": vicon_port,
                                 "logging.flight_log_dir": str(workdir / "logs")})
    (workdir / "base.yaml").write_text(dump_config(cfg), encoding="utf-8")
    ports = free_ports(len(homes) + 1)
    vehicles = []
    for k, (x, y) in enumerate(homes):
        vname = f"v{k + 1}"
        vehicles.append({"name": vname, "serial_port": f"virtual:{vname}",
                         "vicon_object": f"X3D-{k + 1}", "home": [float(x), float(y)],
                         "listen": f"tcp/127.0.0.1:{ports[k + 1]}",
                         **({"overrides": dict(overrides[vname])}
                            if overrides and vname in overrides else {})})
    fleet: dict[str, Any] = {"fleet": name, "base": "base.yaml", "separation_m": separation_m,
                             "relay": {"listen": f"tcp/127.0.0.1:{ports[0]}"},
                             "vehicles": vehicles, **(extra or {})}
    path = workdir / "fleet.yaml"
    path.write_text(yaml.safe_dump(fleet, sort_keys=False), encoding="utf-8")
    return path


class VirtualFleet:
    """The virtual lab, the relay and the daemons of ``fleet_file`` for a ``with`` block.

    ``echo`` gets every process's lines (prefixed with its name). Inside the block:
    :attr:`run_file` is the fleet file naming the ptys, :attr:`truth_files` each vehicle's
    truth (written when the block ends), :attr:`processes` the relay's and daemons'.
    Leaving the block asks the daemons still flying to land (SIGINT), waits for them, then
    stops the relay and the lab.
    """

    def __init__(self, fleet_file: Path, *, echo: Callable[[str], None],
                 relay: bool = True, daemons: Sequence[str] | None = None) -> None:
        self.fleet_file = Path(fleet_file)
        self._echo = echo
        self._relay = relay
        self._daemons = daemons
        spec = yaml.safe_load(self.fleet_file.read_text(encoding="utf-8"))
        self.names: list[str] = [v["name"] for v in spec["vehicles"]]
        self._spec = spec
        self.run_file = self.fleet_file.with_name("fleet-run.yaml")
        self.truth_files: dict[str, Path] = {}
        self.ptys: dict[str, str] = {}
        self._lab: subprocess.Popen[str] | None = None
        self.processes: FleetProcesses | None = None
        self.codes: dict[str, int] = {}
        self.lab_output = ""

    def __enter__(self) -> VirtualFleet:
        base = self.fleet_file.parent / self._spec["base"]
        self._lab = subprocess.Popen(
            [*gs_command(), "sim-device", "--json", "--config", str(base), "--fleet",
             str(self.fleet_file), "--truth-file", str(self.fleet_file.parent / "truth.npz")],
            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
            start_new_session=True)
        try:
            self._announced()
            spec = dict(self._spec)
            spec["vehicles"] = [{**v, "serial_port": self.ptys[v["name"]]}
                                for v in spec["vehicles"]]
            self.run_file.write_text(yaml.safe_dump(spec, sort_keys=False), encoding="utf-8")
            self.processes = FleetProcesses(self.run_file, self._daemons or self.names,
                                            relay=self._relay, echo=self._echo)
            self.processes.start()
        except BaseException:
            self.__exit__(None, None, None)
            raise
        return self

    def _announced(self) -> None:
        assert self._lab is not None and self._lab.stdout is not None
        ready, _, _ = select.select([self._lab.stdout], [], [], LAB_START_S)
        line = self._lab.stdout.readline() if ready else ""
        try:
            info = json.loads(line)
            vehicles = info["vehicles"]
        except (ValueError, KeyError, TypeError) as exc:
            raise GroundStationError(f"the virtual fleet did not start: {line.strip()!r}") \
                from exc
        for v in vehicles:
            self.ptys[v["name"]] = v["serial_port"]
            self.truth_files[v["name"]] = Path(v["truth_file"])
        self._echo(f"virtual fleet: {', '.join(f'{n} on {p}' for n, p in self.ptys.items())}")

    def wait(self) -> dict[str, int]:
        """Wait for every daemon to end (then the relay stops); their exit codes."""
        assert self.processes is not None
        self.codes = self.processes.wait()
        return self.codes

    def log_dir(self, name: str) -> Path:
        """The flight log of vehicle ``name`` (the newest under its directory)."""
        base = yaml.safe_load((self.fleet_file.parent / self._spec["base"]).read_text())
        root = Path(base["logging"]["flight_log_dir"]) / name
        logs = sorted(p for p in root.iterdir() if (p / "meta.json").exists())
        if not logs:
            raise GroundStationError(f"no flight log of {name} under {root}")
        return logs[-1]

    def __exit__(self, *exc_info: object) -> None:
        processes = self.processes
        try:
            if processes is not None:
                processes.signal_daemons(signal.SIGINT)
                try:
                    self.codes = {**self.codes, **processes.wait()}
                except BaseException:
                    processes.kill()
                    raise
        finally:
            lab = self._lab
            if lab is not None and lab.poll() is None:
                lab.send_signal(signal.SIGINT)
                try:
                    self.lab_output = lab.communicate(timeout=30.0)[0]
                except subprocess.TimeoutExpired:
                    lab.kill()
                    self.lab_output = lab.communicate()[0]
