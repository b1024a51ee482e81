"""``gs fleet up``: one daemon process per vehicle on this lab PC, and the relay.

:class:`FleetProcesses` starts, for the members of a fleet file that run on this host
(``host:`` unset or this host's name), ``gs vicon-relay FLEET`` (when the fleet has a
relay) and one ``gs fleet fly FLEET VEHICLE`` per vehicle, each a process of its own, in
a session of its own: a Ctrl-C at the terminal reaches the manager only, which passes
each stop request on to every daemon (the first lands them, a second at least
``safety.second_signal_after_s`` later hands them back, as for ``gs fly``). The relay
is started first and stopped last, once every daemon has ended: a landing needs Vicon.
Each child's lines are echoed with its name in front.

The daemons do not depend on the manager: if it dies, each flies on and lands as it
would alone (its idle landing, ``api.idle_land_s``, without requests). On a lab PC the
systemd template unit ``groundstation@.service`` runs the same ``gs fleet fly`` per
vehicle instead (``config/groundstation@.service``).

Exit code (:func:`fleet_exit_code`): 0 when every daemon exited 0; else the most urgent
of their codes in the order 1 (a failsafe), 5 (a log incomplete), 3 (could not start),
2 (configuration), 4 (stopped on request); a daemon killed by a signal (or any other
code) counts as 1: its vehicle's watchdog handed it back.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import structlog

log = structlog.get_logger(__name__)

URGENCY = (1, 5, 3, 2, 4)
"""Daemon exit codes, most urgent first (``gs fly``'s codes)."""

RELAY_SETTLE_S = 0.5
"""Time the relay is given to open its session before the daemons start [s]."""

RELAY_STOP_S = 10.0
"""How long the relay may take to stop before it is killed [s]."""


def fleet_exit_code(codes: Mapping[str, int]) -> int:
    """The manager's exit code from its daemons' (see the module docstring)."""
    values = set(codes.values())
    if values <= {0}:
        return 0
    if values - {0, *URGENCY}:  # killed by a signal, or a crash: its watchdog handed back
        return 1
    return next(code for code in URGENCY if code in values)


def gs_command() -> list[str]:
    """How to run ``gs`` as a child: the ``gs`` beside this interpreter, else this
    interpreter running the CLI."""
    exe = Path(sys.executable).parent / "gs"
    return [str(exe)] if exe.exists() else [sys.executable, "-m", "groundstation"]


@dataclass
class Child:
    """One process of the fleet: ``name``, the command, the process once started."""

    name: str
    args: list[str]
    process: subprocess.Popen[str] | None = None
    reader: threading.Thread | None = None
    lines: list[str] = field(default_factory=list)


class FleetProcesses:
    """The processes of one fleet on this host (see the module docstring).

    fleet_file : the fleet.yaml; vehicles : the vehicles to fly here; relay : start the
    relay too; echo : where the children's lines go (prefixed with their names)
    """

    def __init__(self, fleet_file: Path, vehicles: Sequence[str], *, relay: bool,
                 echo: Callable[[str], None],
                 extra: Mapping[str, Sequence[str]] | None = None) -> None:
        gs = gs_command()
        self._echo = echo
        self._lock = threading.Lock()
        self.relay = Child("relay", [*gs, "vicon-relay", str(fleet_file)]) if relay else None
        self.daemons = [Child(name, [*gs, "fleet", "fly", str(fleet_file), name,
                                     *(extra or {}).get(name, ())]) for name in vehicles]

    def start(self) -> None:
        """Start the relay, then every daemon."""
        if self.relay is not None:
            self._spawn(self.relay)
            time.sleep(RELAY_SETTLE_S)
        for child in self.daemons:
            self._spawn(child)

    def _spawn(self, child: Child) -> None:
        env = {**os.environ, "PYTHONUNBUFFERED": "1"}
        child.process = subprocess.Popen(child.args, stdout=subprocess.PIPE,
                                         stderr=subprocess.STDOUT, text=True, env=env,
                                         start_new_session=True)
        child.reader = threading.Thread(target=self._read, args=(child,),
                                        name=f"fleet-{child.name}", daemon=True)
        child.reader.start()
        self._echo(f"[{child.name}] started (pid {child.process.pid})")

    def _read(self, child: Child) -> None:
        assert child.process is not None and child.process.stdout is not None
        for line in child.process.stdout:
            text = line.rstrip("\n")
            child.lines.append(text)
            with self._lock:
                self._echo(f"[{child.name}] {text}")

    def signal_daemons(self, sig: signal.Signals) -> None:
        """Pass a stop request on to every daemon still running."""
        for child in self.daemons:
            process = child.process
            if process is not None and process.poll() is None:
                try:
                    process.send_signal(sig)
                except ProcessLookupError:
                    continue

    def wait(self) -> dict[str, int]:
        """Wait for every daemon to end, then stop the relay; each daemon's exit code."""
        codes = {}
        for child in self.daemons:
            assert child.process is not None
            codes[child.name] = child.process.wait()
            if child.reader is not None:
                child.reader.join(5.0)
        self.stop_relay()
        return codes

    def stop_relay(self) -> None:
        """Stop the relay (SIGINT; killed after :data:`RELAY_STOP_S`)."""
        relay = self.relay
        if relay is None or relay.process is None or relay.process.poll() is not None:
            return
        relay.process.send_signal(signal.SIGINT)
        try:
            relay.process.wait(RELAY_STOP_S)
        except subprocess.TimeoutExpired:
            relay.process.kill()
            relay.process.wait()
        if relay.reader is not None:
            relay.reader.join(5.0)

    def kill(self) -> None:
        """Kill whatever still runs (a manager that must go: the vehicles' watchdogs hand
        them back to the pilots)."""
        for child in [*self.daemons, *([self.relay] if self.relay else [])]:
            if child.process is not None and child.process.poll() is None:
                child.process.kill()
                child.process.wait()
