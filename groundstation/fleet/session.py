"""The fleet's Zenoh session: peer to peer on explicit endpoints, and who may say what.

Every process of a fleet (the relay, each daemon, ``gs fleet``, a script's
:class:`~groundstation.client.Fleet`) opens one session in Zenoh's *peer* mode with:

* multicast scouting and gossip off: a session talks only to the endpoints it is given
  (``fleet.zenoh.listen`` and ``connect``), so a test or a lab never reaches anything it
  was not told about; the fleet file lists every member's endpoint, so the members form
  a full mesh and any one of them may stop without cutting the others apart;
* beyond loopback, TLS with client certificates (mTLS): every member's certificate is
  signed by the lab's CA (``tls_root_ca``), and the session turns Zenoh's access control
  on, deny by default, with rules by certificate common name (:func:`access_rules`):
  the relay alone may publish Vicon poses, each vehicle only under its own key, and only
  the vehicles and the listed operators may send requests. Endpoints beyond loopback
  without TLS are refused by the configuration (``fleet.zenoh``:
  :class:`~groundstation.config.ZenohConfig`), as the request socket refuses them without
  CURVE. A session takes its settings as :class:`~groundstation.flight.params.ZenohParams`
  (:func:`groundstation.flight.assembly.zenoh_params`).

Zenoh's own errors are translated here into :class:`~groundstation.errors.FleetError`.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from groundstation.errors import FleetError
from groundstation.fleet import keys
from groundstation.flight.params import ZenohParams

if TYPE_CHECKING:
    import zenoh

ALL_MESSAGES = ("put", "delete", "declare_subscriber", "query", "reply", "declare_queryable",
                "liveliness_token", "declare_liveliness_subscriber", "liveliness_query")
"""Zenoh's access-control message kinds."""


@dataclass(frozen=True, slots=True)
class Membership:
    """Who belongs to a fleet, by the names their certificates carry (common names).

    fleet : the key prefix; vehicles : the vehicles' names; relays : the relays' names
    (``relay``); operators : whoever else may send requests (``fleet.zenoh.operators``)
    """

    fleet: str
    vehicles: tuple[str, ...]
    relays: tuple[str, ...] = (keys.RELAY,)
    operators: tuple[str, ...] = ()

    @property
    def members(self) -> tuple[str, ...]:
        """Every name, once."""
        return tuple(dict.fromkeys((*self.vehicles, *self.relays, *self.operators)))


def access_rules(membership: Membership) -> dict[str, Any]:
    """Zenoh's ``access_control`` section for the fleet: deny by default; each member
    sends what it likes (every node checks what it *receives*: the egress rule); on
    ingress, by certificate common name: everyone may subscribe; the relays may publish
    ``<fleet>/vicon/**`` and ``<fleet>/relay/**``; a vehicle may publish, declare its
    queryable and reply only under ``<fleet>/<its name>/**``; the vehicles and the
    operators may send queries (requests) to ``<fleet>/*/cmd/**``."""
    f = membership.fleet
    rules: list[dict[str, Any]] = [
        {"id": "send", "messages": list(ALL_MESSAGES), "flows": ["egress"],
         "permission": "allow", "key_exprs": [f"{f}/**"]},
        {"id": "subscribe", "messages": ["declare_subscriber"], "flows": ["ingress"],
         "permission": "allow", "key_exprs": [f"{f}/**"]},
        {"id": "relay", "messages": ["put", "delete"], "flows": ["ingress"],
         "permission": "allow", "key_exprs": [f"{f}/{keys.VICON}/**", f"{f}/{keys.RELAY}/**"]},
        {"id": "request", "messages": ["query"], "flows": ["ingress"], "permission": "allow",
         "key_exprs": [keys.request_key(f, "*", "**")]},
    ]
    subjects: list[dict[str, Any]] = [
        {"id": "members", "cert_common_names": list(membership.members)},
        {"id": "relays", "cert_common_names": list(membership.relays)},
        {"id": "requesters", "cert_common_names":
            list(dict.fromkeys((*membership.vehicles, *membership.operators)))},
    ]
    policies: list[dict[str, Any]] = [
        {"rules": ["send", "subscribe"], "subjects": ["members"]},
        {"rules": ["relay"], "subjects": ["relays"]},
        {"rules": ["request"], "subjects": ["requesters"]},
    ]
    for i, vehicle in enumerate(membership.vehicles):
        rules.append({"id": f"vehicle{i}", "messages": ["put", "delete", "reply",
                                                        "declare_queryable"],
                      "flows": ["ingress"], "permission": "allow",
                      "key_exprs": [f"{f}/{vehicle}/**"]})
        subjects.append({"id": f"vehicle{i}", "cert_common_names": [vehicle]})
        policies.append({"rules": [f"vehicle{i}"], "subjects": [f"vehicle{i}"]})
    return {"enabled": True, "default_permission": "deny", "rules": rules,
            "subjects": subjects, "policies": policies}


def zenoh_config(settings: ZenohParams, membership: Membership) -> zenoh.Config:
    """The ``zenoh.Config`` of a fleet member (see the module docstring)."""
    import zenoh

    entries: dict[str, Any] = {
        "mode": "peer",
        "listen/endpoints": list(settings.listen),
        "connect/endpoints": list(settings.connect),
        "scouting/multicast/enabled": False,
        "scouting/gossip/enabled": False,
    }
    if settings.tls_root_ca is not None:
        ca, cert, key = (str(Path(p).resolve()) for p in (
            settings.tls_root_ca, settings.tls_certificate, settings.tls_private_key)
            if p is not None)
        entries["transport/link/tls"] = {
            "root_ca_certificate": ca, "enable_mtls": True,
            "listen_certificate": cert, "listen_private_key": key,
            "connect_certificate": cert, "connect_private_key": key,
            "verify_name_on_connect": True}
        entries["access_control"] = access_rules(membership)
    config = zenoh.Config()
    try:
        for key, value in entries.items():
            config.insert_json5(key, json.dumps(value))
    except zenoh.ZError as exc:
        raise FleetError(f"fleet.zenoh: {exc}") from exc
    return config


def open_session(settings: ZenohParams, membership: Membership) -> zenoh.Session:
    """Open a fleet member's session. FleetError (one line) if it cannot be opened: a
    listen port taken, a certificate or key that cannot be read. Endpoints to connect
    to that do not answer yet are retried in the background (a member started first
    waits for the others)."""
    import zenoh

    config = zenoh_config(settings, membership)
    try:
        return zenoh.open(config)
    except zenoh.ZError as exc:
        text = str(exc)
        reason = text.split(" at /", 1)[0] if " at /" in text else text
        raise FleetError(f"the fleet's Zenoh session could not be opened: {reason}") from exc
