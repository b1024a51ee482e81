"""What the ground station needs from a virtual lab, and how it finds one.

Dependencies run one way: a virtual lab imports the ground station, never the
reverse. The bundled lab (``sim_device``) registers itself under the entry-point
group :data:`ENTRY_POINT_GROUP` in ``pyproject.toml``, as python-can's interfaces
register under ``can.interface``; :func:`virtual_lab` loads it by name. The ground
station then talks to it only through the protocols below:

* :class:`Lab`: a lab stepped on its own simulated clock, for the in-process runner
  (:mod:`groundstation.app.inprocess`): bytes in and out of the vehicle's serial
  port, Vicon datagrams, and the ground truth.
* :class:`LabPlugin`: what a lab offers the ground station: it validates the
  configuration's ``sim:`` section (which the ground station does not know), builds
  a :class:`Lab`, starts itself in a process of its own for ``gs fly --demo``, and
  adds its commands to ``gs`` (``gs sim-device``, ``gs eval``).

A lab process announces where it can be reached as one JSON line
(:class:`Announcement`), not prose.

Without a lab installed (the flight image, ``Dockerfile``) everything else works;
what needs one raises :class:`LabNotInstalledError`.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Sequence
from contextlib import AbstractContextManager
from dataclasses import dataclass
from importlib.metadata import entry_points
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

from groundstation.errors import GroundStationError
from groundstation.types import FloatArray

if TYPE_CHECKING:
    from pydantic import BaseModel

    from groundstation.config import GroundStationConfig

ENTRY_POINT_GROUP = "groundstation.labs"
"""Entry-point group a virtual lab registers its :class:`LabPlugin` object under."""

DEFAULT_LAB = "virtual"
"""The entry-point name of the bundled virtual lab (``sim_device``)."""


class LabNotInstalledError(GroundStationError):
    """No virtual lab is installed under the name asked for (or it does not load)."""


class Truth(Protocol):
    """The simulated vehicle's true state at time ``t`` [s]: ``position`` (3,) NED [m],
    ``velocity`` (3,) NED [m/s], ``quaternion`` (4,) scalar first, body FRD -> NED."""

    @property
    def t(self) -> float: ...
    @property
    def position(self) -> FloatArray: ...
    @property
    def velocity(self) -> FloatArray: ...
    @property
    def quaternion(self) -> FloatArray: ...


class TruthLog(Protocol):
    """The ground truth recorded so far."""

    def arrays(self) -> dict[str, FloatArray]:
        """Columns, one row per truth sample: ``t`` (N,) [s], ``position`` (N, 3) NED [m],
        ``quaternion`` (N, 4) scalar first (and whatever else the lab records)."""
        ...


class Datagram(Protocol):
    """One Vicon UDP datagram: its payload and its delivery time ``t`` [s, lab clock]."""

    @property
    def t(self) -> float: ...
    @property
    def data(self) -> bytes: ...


class Lab(Protocol):
    """A virtual lab stepped by hand on its simulated clock [s].

    ``write`` hands it the bytes the ground station sends (COMMAND and CONFIG frames);
    ``advance`` runs it ``dt`` seconds and returns the bytes its vehicle sent, each
    with its delivery time; ``vicon_datagrams`` returns the datagrams that became due.
    """

    @property
    def t(self) -> float: ...
    @property
    def truth(self) -> Truth: ...
    @property
    def truth_log(self) -> TruthLog: ...
    def write(self, data: bytes) -> None: ...
    def advance(self, dt: float) -> Sequence[tuple[float, bytes]]: ...
    def vicon_datagrams(self) -> Sequence[Datagram]: ...


class RunningLab(Protocol):
    """A lab running in real time in a process of its own (``gs fly --demo``)."""

    @property
    def announcement(self) -> Announcement: ...


class LabPlugin(Protocol):
    """What a virtual lab registers under :data:`ENTRY_POINT_GROUP`."""

    def validate_section(self, data: Any) -> BaseModel:
        """The configuration's ``sim:`` section, validated (pydantic ValidationError)."""
        ...

    def in_process(self, config: GroundStationConfig) -> Lab:
        """A lab for ``config`` (its ``sim:`` section, vehicle, link and Vicon stream)."""
        ...

    def start(self, config: GroundStationConfig, workdir: Path
              ) -> AbstractContextManager[RunningLab]:
        """Run the lab for ``config`` in real time in a child process for a ``with``
        block (files it needs go in ``workdir``); entering returns once it is up."""
        ...

    def commands(self) -> Sequence[tuple[str, Callable[..., Any]]]:
        """``(name, typer command function)`` pairs the lab adds to ``gs``."""
        ...


@dataclass(frozen=True, slots=True)
class Announcement:
    """Where a running lab can be reached: the line it prints first, as JSON.

    serial_port : the vehicle's serial port (a pty path) for ``serial.port``
    vicon_target : (address, UDP port) the Vicon datagrams go to
    truth_file : where the lab writes its ground truth (.npz) when it stops
    """

    serial_port: str
    vicon_target: tuple[str, int]
    truth_file: Path

    def to_json(self) -> str:
        """One line of JSON (no newline)."""
        return json.dumps({"serial_port": self.serial_port,
                           "vicon_target": list(self.vicon_target),
                           "truth_file": str(self.truth_file)})

    @classmethod
    def from_json(cls, line: str) -> Announcement:
        """Parse :meth:`to_json`'s line; ValueError naming what is wrong."""
        try:
            data = json.loads(line)
            address, port = data["vicon_target"]
            return cls(str(data["serial_port"]), (str(address), int(port)),
                       Path(data["truth_file"]))
        except (ValueError, KeyError, TypeError) as exc:
            raise ValueError(f"not a lab announcement: {line.strip()[:200]!r}") from exc


def virtual_lab(name: str = DEFAULT_LAB) -> LabPlugin:
    """The lab registered as ``name`` under :data:`ENTRY_POINT_GROUP`.

    Raises LabNotInstalledError when there is none or it fails to load (the flight image
    ships without the virtual lab).
    """
    found = entry_points(group=ENTRY_POINT_GROUP, name=name)
    if not found:
        raise LabNotInstalledError(f"no virtual lab {name!r} is installed (entry point group "
                              f"{ENTRY_POINT_GROUP}); install the project with the virtual "
                              "lab: pip install -e .")
    (entry,) = tuple(found)[:1]
    try:
        plugin: LabPlugin = entry.load()
    except ImportError as exc:
        raise LabNotInstalledError(f"the virtual lab {name!r} ({entry.value}) is registered but "
                              f"does not load: {exc}") from exc
    return plugin


def installed_labs() -> list[str]:
    """Names of the installed labs."""
    return sorted(ep.name for ep in entry_points(group=ENTRY_POINT_GROUP))
