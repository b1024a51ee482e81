"""``fleet.yaml``: a fleet in one file, over a shared base configuration.

::

    fleet: lab                    # the key prefix of everything the fleet says
    base: lab.yaml                # the shared configuration (relative to this file)
    separation_m: 0.6             # least distance between two vehicles; null: off
    hover_height_m: 1.0           # each vehicle hovers this high above its home
    relay: {listen: tcp/127.0.0.1:7447}    # where `gs vicon-relay` listens (null: none,
                                  # each daemon reads Tracker's UDP stream itself)
    zenoh: {tls_root_ca: ca.pem, tls_directory: certs, operators: [alice]}  # beyond loopback
    vehicles:
      - name: x3d-1               # its keys: lab/x3d-1/...
        serial_port: /dev/x3d-1
        vicon_object: X3D-1
        home: [0.0, -0.6]         # where it stands on the floor, NED x, y [m]
        volume: {x: [-1.5, 1.5], y: [-1.5, 0.0], z: [-2.0, 0.05]}   # optional
        listen: tcp/127.0.0.1:7448   # optional (default: the relay's port + 1 + index)
        host: lab-pc-2            # optional: the lab PC that flies it (`gs fleet up`)
        overrides: {controller.type: lqr-ff}   # optional: any key of the configuration

:func:`load_fleet` reads and checks it (one line per problem, naming the file, the line
and the field, as ``gs check-config`` does; a bad fleet file is exit 2): names, serial
ports, Vicon objects and endpoints unique; homes inside their volumes and at least the
separation apart; two volumes that overlap only with the separation on; and every
vehicle's configuration valid. :meth:`FleetFile.vehicle_config` is the configuration a
vehicle's daemon flies: the base with the vehicle's port, object, home (its take-off
point: ``trajectory.center`` above it, the virtual lab's ``sim.initial_position`` on it),
volume, ``trajectory.name: none`` (commanded at run time), its flight-log directory
``<logging.flight_log_dir>/<name>``, its ``fleet:`` section (peers, endpoints), and its
own overrides last. Per-process pyzmq sockets are off in a fleet (several daemons on one
PC would need a port each): Zenoh serves the fleet's telemetry and requests; a vehicle's
overrides may turn them on (``telemetry.endpoint``, ``telemetry.control_endpoint``).
"""

from __future__ import annotations

import itertools
import math
import socket
from pathlib import Path
from typing import Annotated, Any

from pydantic import Field, ValidationError, model_validator

from groundstation.config.base import ConfigModel, FieldValueError
from groundstation.config.files import (
    _parse_yaml,  # this package's YAML reader: lines, duplicate keys, YAML 1.2
    apply_overrides,
    load_config,
    raise_problems,
    validate_config,
    validation_problems,
)
from groundstation.config.fleet import RESERVED_NAMES, FleetConfig, FleetName, ZenohConfig
from groundstation.config.ranges import FilePath, LabCoordinate, ZenohEndpoint, within
from groundstation.config.schema import GroundStationConfig
from groundstation.errors import ConfigError

Box = tuple[tuple[float, float], tuple[float, float], tuple[float, float]]
"""A volume: ((x_min, x_max), (y_min, y_max), (z_min, z_max)), NED [m]."""

_FLEET = FleetConfig()
"""The fleet section's defaults (:mod:`.fleet`), which the file's keys take."""

DEFAULT_RELAY = "tcp/127.0.0.1:7447"
"""Where the relay listens unless the file says."""

MAX_FLEET = 64
"""Most vehicles in one file (a Zenoh full mesh of 64 is 2016 links)."""


class VolumeSpec(ConfigModel):
    """A vehicle's own flight volume, NED [m] (``safety.volume_x/y/z``)."""

    x: tuple[LabCoordinate, LabCoordinate]
    y: tuple[LabCoordinate, LabCoordinate]
    z: tuple[LabCoordinate, LabCoordinate]

    def box(self) -> Box:
        """As ((x_min, x_max), (y_min, y_max), (z_min, z_max))."""
        return (self.x, self.y, self.z)


class VehicleSpec(ConfigModel):
    """One vehicle of the fleet (see the module docstring)."""

    name: FleetName
    serial_port: str = Field(min_length=1)
    vicon_object: str = Field(min_length=1, max_length=23)  # the spec's 23 characters
    home: tuple[LabCoordinate, LabCoordinate]
    volume: VolumeSpec | None = None
    listen: ZenohEndpoint | None = None
    host: str | None = None
    overrides: dict[str, Any] = Field(default_factory=dict)

    @model_validator(mode="after")
    def _name(self) -> VehicleSpec:
        if self.name in RESERVED_NAMES:
            raise FieldValueError("name", self.name, f"{self.name!r} is a key of the fleet "
                                  f"itself ({', '.join(RESERVED_NAMES)}), not a vehicle")
        return self


class RelaySpec(ConfigModel):
    """Where ``gs vicon-relay`` listens (and on which PC ``gs fleet up`` starts it)."""

    listen: ZenohEndpoint = DEFAULT_RELAY
    host: str | None = None


class ZenohSpec(ConfigModel):
    """The fleet's Zenoh security: TLS with client certificates beyond loopback.

    tls_root_ca : the lab CA's certificate; tls_directory : ``<name>.pem`` and
    ``<name>.key`` for each member (vehicles by name, ``relay``, each operator);
    operators : names that may send requests besides the vehicles."""

    tls_root_ca: FilePath | None = None
    tls_directory: Path | None = None
    operators: list[FleetName] = Field(default_factory=list)

    @model_validator(mode="after")
    def _pair(self) -> ZenohSpec:
        if (self.tls_root_ca is None) != (self.tls_directory is None):
            raise FieldValueError("tls_directory", self.tls_directory,
                                  "tls_root_ca and tls_directory go together")
        return self


class FleetFile(ConfigModel):
    """A whole fleet.yaml (see the module docstring). ``source`` is its path."""

    fleet: FleetName = "lab"
    base: Path
    separation_m: float | None = None  # fleet.separation_m, checked there
    separation_hold_s: float = _FLEET.separation_hold_s  # likewise
    peer_timeout_s: float = _FLEET.peer_timeout_s  # likewise
    hover_height_m: Annotated[float, within(0.0, 100.0, "m: above the floor",
                                            lo_open=True)] | None = None
    relay: RelaySpec | None = RelaySpec()
    zenoh: ZenohSpec = ZenohSpec()
    vehicles: list[VehicleSpec] = Field(min_length=1, max_length=MAX_FLEET)

    @model_validator(mode="after")
    def _fleet_keys(self) -> FleetFile:
        """The keys every daemon's ``fleet:`` section takes, checked as it checks them."""
        try:
            FleetConfig(name=self.fleet, separation_m=self.separation_m,
                        separation_hold_s=self.separation_hold_s,
                        peer_timeout_s=self.peer_timeout_s)
        except ValidationError as exc:
            path, value, reason = validation_problems(exc)[0]
            raise FieldValueError(path, value, reason) from None
        return self

    # ------------------------------------------------------------------ derived
    @property
    def names(self) -> list[str]:
        """The vehicles' names, in file order."""
        return [v.name for v in self.vehicles]

    def vehicle(self, name: str) -> VehicleSpec:
        """The vehicle called ``name``; ConfigError naming the known ones otherwise."""
        for v in self.vehicles:
            if v.name == name:
                return v
        raise ConfigError(f"no vehicle {name!r} in the fleet (vehicles: "
                          f"{', '.join(self.names)})")

    def relay_port(self) -> int:
        """The relay's Zenoh port (default vehicles' ports count on from it)."""
        return int((self.relay.listen if self.relay is not None else DEFAULT_RELAY)
                   .rpartition(":")[2])

    def listen_of(self, index: int) -> str:
        """Vehicle ``index``'s listen endpoint: its own, else the relay's port + 1 + index
        on loopback (``tls/`` with TLS on)."""
        own = self.vehicles[index].listen
        if own is not None:
            return own
        scheme = "tls" if self.zenoh.tls_root_ca is not None else "tcp"
        return f"{scheme}/127.0.0.1:{self.relay_port() + 1 + index}"

    def endpoints(self) -> list[str]:
        """Every member's listen endpoint: the relay's first, then the vehicles'."""
        out = [self.relay.listen] if self.relay is not None else []
        return out + [self.listen_of(i) for i in range(len(self.vehicles))]

    def zenoh_for(self, member: str, listen: list[str]) -> ZenohConfig:
        """The ``fleet.zenoh`` of a member called ``member`` listening on ``listen``: it
        connects to every other member's endpoint, with the fleet's TLS."""
        tls: dict[str, Any] = {}
        z = self.zenoh
        if z.tls_root_ca is not None and z.tls_directory is not None:
            tls = {"tls_root_ca": z.tls_root_ca,
                   "tls_certificate": z.tls_directory / f"{member}.pem",
                   "tls_private_key": z.tls_directory / f"{member}.key"}
        return ZenohConfig(listen=listen,
                           connect=[e for e in self.endpoints() if e not in listen],
                           operators=list(z.operators), **tls)

    def fleet_section(self, name: str, index: int) -> FleetConfig:
        """Vehicle ``name``'s ``fleet:`` section."""
        return FleetConfig(name=self.fleet, vehicle=name,
                           peers=[n for n in self.names if n != name],
                           separation_m=self.separation_m,
                           separation_hold_s=self.separation_hold_s,
                           peer_timeout_s=self.peer_timeout_s,
                           zenoh=self.zenoh_for(name, [self.listen_of(index)]))

    def vehicle_config(self, base: GroundStationConfig, name: str) -> GroundStationConfig:
        """The configuration vehicle ``name``'s daemon flies (see the module docstring).
        ConfigError naming the vehicle's field if it is not valid."""
        index = self.names.index(self.vehicle(name).name)
        spec = self.vehicles[index]
        height = self.hover_height_m if self.hover_height_m is not None \
            else -base.trajectory.center[2]
        overrides: dict[str, Any] = {
            "serial.port": spec.serial_port, "vicon.object_name": spec.vicon_object,
            "vicon.source": "zenoh" if self.relay is not None else "udp",
            "trajectory.name": "none",
            "trajectory.center": [spec.home[0], spec.home[1], -height],
            "logging.flight_log_dir": str(Path(base.logging.flight_log_dir) / name),
            "telemetry.enabled": False, "telemetry.control_endpoint": None,
            "fleet": self.fleet_section(name, index).model_dump(mode="json"),
        }
        if spec.volume is not None:
            overrides.update({"safety.volume_x": list(spec.volume.x),
                              "safety.volume_y": list(spec.volume.y),
                              "safety.volume_z": list(spec.volume.z)})
        if base.sim is not None:  # the virtual lab: the vehicle stands on its home
            sim = base.sim  # as given (a mapping), or as the lab validated it (a model)
            seed = int(sim.get("seed", 1) if isinstance(sim, dict)  # 1: the lab's default
                       else getattr(sim, "seed", 1))
            overrides.update({"sim.initial_position": [spec.home[0], spec.home[1], 0.0],
                              "sim.seed": seed + index})
        data = base.model_dump(mode="json")
        data["telemetry"]["control_endpoint"] = None  # apply_overrides skips None: set here
        config = apply_overrides(validate_config(data, str(self.base)), overrides)
        if spec.overrides:
            config = apply_overrides(config, spec.overrides)
        return config

    def volume_of(self, base: GroundStationConfig, spec: VehicleSpec) -> Box:
        """A vehicle's volume: its own, else the base's."""
        if spec.volume is not None:
            return spec.volume.box()
        s = base.safety
        return (s.volume_x, s.volume_y, s.volume_z)

    # ------------------------------------------------------------------ checks
    def problems(self, base: GroundStationConfig) -> list[tuple[str, object, str]]:
        """What is wrong with the fleet as a whole (empty if nothing): (field, value,
        reason) as the configuration reports them."""
        out: list[tuple[str, object, str]] = []
        for field in ("name", "serial_port", "vicon_object"):
            seen: dict[object, int] = {}
            for i, v in enumerate(self.vehicles):
                value = getattr(v, field)
                if value in seen:
                    out.append((f"vehicles.{i}.{field}", value,
                                f"also vehicle {seen[value]}'s: each vehicle needs its own"))
                seen.setdefault(value, i)
        endpoints = self.endpoints()
        for i, endpoint in enumerate(endpoints):
            if endpoint in endpoints[:i]:
                out.append((f"vehicles.{i - (self.relay is not None)}.listen", endpoint,
                            "another member listens there"))
        for i, v in enumerate(self.vehicles):
            box = self.volume_of(base, v)
            if not (box[0][0] <= v.home[0] <= box[0][1] and box[1][0] <= v.home[1] <= box[1][1]):
                out.append((f"vehicles.{i}.home", list(v.home), "outside its volume "
                            f"x {list(box[0])}, y {list(box[1])}"))
        for (_, a), (j, b) in itertools.combinations(enumerate(self.vehicles), 2):
            gap = math.dist(a.home, b.home)
            if self.separation_m is not None and gap < self.separation_m:
                out.append((f"vehicles.{j}.home", list(b.home), f"{gap:.2f} m from "
                            f"{a.name}'s, less than separation_m ({self.separation_m:g} m)"))
            if self.separation_m is None and volumes_overlap(self.volume_of(base, a),
                                                             self.volume_of(base, b)):
                out.append((f"vehicles.{j}.volume", "the base's" if b.volume is None
                            else b.volume.model_dump(), f"overlaps {a.name}'s volume: "
                            "volumes may overlap only with separation_m set"))
        return out


def volumes_overlap(a: Box, b: Box) -> bool:
    """Whether two volumes share more than a face (a positive volume)."""
    return all(min(ha, hb) > max(la, lb) for (la, ha), (lb, hb) in zip(a, b, strict=True))


def load_fleet(path: str | Path) -> tuple[FleetFile, GroundStationConfig]:
    """Read ``fleet.yaml`` and its base configuration and check them (see the module
    docstring); ConfigError with one line per problem (``FILE:LINE: field: value:
    reason``), also for each vehicle whose configuration would not be valid."""
    path = Path(path)
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read: {exc.strerror}") from exc
    data, lines = _parse_yaml(raw, str(path))
    if not isinstance(data, dict):
        raise_problems([("<root>", data, "a fleet file is a mapping: fleet, base, vehicles")],
                       str(path), lines)
    if isinstance(data.get("base"), str):  # relative to the fleet file
        data["base"] = str(path.parent / data["base"])
    for section in ("zenoh",):
        sub = data.get(section)
        if isinstance(sub, dict):
            for key in ("tls_root_ca", "tls_directory"):
                if isinstance(sub.get(key), str):
                    sub[key] = str(path.parent / sub[key])
    try:
        fleet = FleetFile.model_validate(data)
    except ValidationError as exc:
        raise_problems(validation_problems(exc), str(path), lines)
    base = load_config(fleet.base)
    problems = fleet.problems(base)
    if not problems:
        for i, v in enumerate(fleet.vehicles):
            try:
                fleet.vehicle_config(base, v.name)
            except ConfigError as exc:
                problems += [(f"vehicles.{i}.{p}", value, reason)
                             for p, value, reason in exc.problems] or \
                    [(f"vehicles.{i}", v.name, str(exc))]
    if problems:
        raise_problems(problems, str(path), lines)
    return fleet, base


def this_host() -> str:
    """This lab PC's name, as ``host:`` in a fleet file names it."""
    return socket.gethostname()


def on_this_host(host: str | None) -> bool:
    """Whether a member with ``host:`` runs here (no host: wherever ``gs fleet up`` runs)."""
    return host is None or host in (this_host(), socket.getfqdn(), "localhost")
