"""A fleet: several vehicles on one Vicon, one daemon each (README "Fleet").

The ``fleet:`` section makes a daemon one vehicle of a fleet: its keys, its peers, the
separation kept between them and how it joins the fleet's Zenoh network
(``fleet.zenoh``). A single-vehicle configuration has none. A fleet file (fleet.yaml,
:mod:`.fleetfile`) writes this section for each of its daemons.
"""

from __future__ import annotations

from typing import Annotated

from pydantic import Field, model_validator

from groundstation.config.base import ConfigModel, FieldValueError
from groundstation.config.ranges import LAB_EXTENT_M, FilePath, ZenohEndpoint, within
from groundstation.endpoints import zenoh_local

FLEET_NAME = r"^[A-Za-z0-9][A-Za-z0-9_-]{0,31}$"
"""A fleet's or a vehicle's name: one Zenoh key chunk (letters, digits, - and _; no /,
*, $, # or ?: those are Zenoh's wildcards and separators)."""

RESERVED_NAMES = ("vicon", "relay")
"""Key chunks under a fleet's prefix that are not vehicles: the relayed Vicon poses and
the relay's own health."""

FleetName = Annotated[str, Field(pattern=FLEET_NAME)]


class ZenohConfig(ConfigModel):
    """How this process joins the fleet's Zenoh network: peer to peer, no multicast
    scouting, explicit endpoints. Anything beyond loopback needs TLS with client
    certificates (mTLS) signed by ``tls_root_ca``; the fleet's access rules are then on,
    by certificate common name (groundstation/fleet/session.py)."""

    listen: list[ZenohEndpoint] = Field(default_factory=list)
    # where this process accepts the others' links (a daemon: its own port; a client: none)
    connect: list[ZenohEndpoint] = Field(default_factory=lambda: ["tcp/127.0.0.1:7447"])
    # the others' listen endpoints (the relay's and every other daemon's): a full mesh, so
    # any one process may stop without cutting the others apart; retried while absent
    tls_root_ca: FilePath | None = None
    # PEM certificate of the lab's CA: every member's certificate must be signed by it
    tls_certificate: FilePath | None = None
    # this process's PEM certificate; its common name is its name in the access rules
    tls_private_key: FilePath | None = None  # its PEM private key
    operators: list[FleetName] = Field(default_factory=list)
    # certificate common names allowed to send requests (go_to, follow, hold, land) and
    # read telemetry beyond the vehicles themselves (a lab member's laptop, `gs fleet`)

    @model_validator(mode="after")
    def _access(self) -> ZenohConfig:
        tls = (self.tls_root_ca, self.tls_certificate, self.tls_private_key)
        if any(v is not None for v in tls) and not all(v is not None for v in tls):
            raise FieldValueError("tls_root_ca", self.tls_root_ca, "tls_root_ca, "
                                  "tls_certificate and tls_private_key go together (mTLS)")
        secured = self.tls_root_ca is not None
        for field in ("listen", "connect"):
            for endpoint in getattr(self, field):
                if secured and not endpoint.startswith(("tls/", "quic/")) \
                        and not zenoh_local(endpoint):
                    raise FieldValueError(field, endpoint, f"{endpoint}: a plain link beyond "
                                          "loopback: use tls/HOST:PORT with TLS on")
                if not secured and not zenoh_local(endpoint):
                    raise FieldValueError(field, endpoint, f"{endpoint} reaches beyond "
                                          "loopback without TLS: set fleet.zenoh.tls_root_ca, "
                                          "tls_certificate and tls_private_key (mTLS and the "
                                          "fleet's access rules), or use tcp/127.0.0.1:PORT")
        return self


class FleetConfig(ConfigModel):
    """This daemon as one vehicle of a fleet: its keys, its peers and the separation kept
    between them (README "Fleet")."""

    name: FleetName = "lab"
    # the key prefix: every key of the fleet is <name>/..., so two fleets on one network
    # never mix
    vehicle: FleetName = "x3d"
    # this vehicle's name: its telemetry and requests are under <name>/<vehicle>/
    peers: list[FleetName] = Field(default_factory=list)
    # the other vehicles of the fleet, whose estimated poses this daemon watches
    separation_m: Annotated[float, within(0.0, LAB_EXTENT_M, "m: a distance within a "
                                          "lab (LAB_EXTENT_M)", lo_open=True)] | None = None
    # least distance between two vehicles [m], kept at planning (a motion that would bring
    # them closer is refused) and in flight (closer: both hold; closer than half of it:
    # both land). null: off, and then no two vehicles' volumes may overlap (fleet.yaml)
    separation_hold_s: Annotated[float, within(
        0.0, 30.0, "s: a hold beside a peer longer than 30 s is a stand-off, not a pause",
        lo_open=True)] = 3.0
    # held closer than separation_m this long without the gap opening again: land
    peer_timeout_s: Annotated[float, within(
        0.0, 5.0, "s: a peer silent for 5 s may be anywhere a vehicle can fly in 5 s",
        lo_open=True)] = 0.5
    # a peer whose pose is older than this is silent: new motions are refused (the one
    # in progress, already checked, is flown); the Vicon loss-hold time, by analogy
    pose_rate_hz: Annotated[float, within(
        0.0, 100.0, "Hz: at most one pose per IMU sample (100 Hz)", lo_open=True)] = 50.0
    # estimated pose published for the peers' separation checks (the command rate)
    zenoh: ZenohConfig = ZenohConfig()

    @model_validator(mode="after")
    def _names(self) -> FleetConfig:
        for field, names in (("vehicle", [self.vehicle]), ("peers", self.peers)):
            for name in names:
                if name in RESERVED_NAMES:
                    raise FieldValueError(field, name, f"{name!r} is a key of the fleet "
                                          f"itself ({', '.join(RESERVED_NAMES)}), not a vehicle")
        if self.vehicle in self.peers or len(set(self.peers)) != len(self.peers):
            raise FieldValueError("peers", self.peers, "each peer once, and not this "
                                  "vehicle itself")
        return self
