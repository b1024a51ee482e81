"""Every key of the ``fleet:`` section is read (as ``test_config_keys_read.py`` checks the
rest: that test sees the section itself, not its keys, since it is optional): reads are
recorded while the assembly maps a vehicle's configuration (the ``fleet:`` section into
its node's parameters, the separation and its hold time into the supervisor's limits)
and the TLS settings into a session's (the certificates), and while the node opens on
those parameters (its session: name, vehicle, peers, endpoints, operators, its rates)
and guards a motion (the separation and the peers' timeout)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from test_config_keys_read import leaves, recording

from groundstation.config import FleetConfig, ZenohConfig, load_config
from groundstation.config.fleetfile import load_fleet
from groundstation.fleet.node import FleetNode
from groundstation.fleet.session import Membership, zenoh_config
from groundstation.fleetops.virtual import write_fleet
from groundstation.flight.assembly import assemble, zenoh_params
from groundstation.flight.commander import PlanBase, Rest, plan_go_to

REPO = Path(__file__).resolve().parents[1]


@pytest.mark.slow  # a Zenoh session waits 0.5 s for the relay that is not there
def test_every_fleet_key_is_read(tmp_path: Path) -> None:
    spec, base = load_fleet(write_fleet(tmp_path, load_config(REPO / "config" / "sim.yaml"),
                                        [(0.0, 0.0)], separation_m=0.5))
    cfg = spec.vehicle_config(base, "v1")
    for name in ("ca.pem", "v1.pem", "v1.key"):
        (tmp_path / name).write_text("x")
    tls = ZenohConfig(listen=[], connect=[], tls_root_ca=tmp_path / "ca.pem",
                      tls_certificate=tmp_path / "v1.pem", tls_private_key=tmp_path / "v1.key")
    start = PlanBase((Rest(0.0, np.array(cfg.trajectory.center), 0.0),), 0, 1.0, 0.0,
                     "TRACK", np.zeros(3), 1.0)
    reads: set[tuple[type, str]] = set()
    with recording(reads):
        params = assemble(cfg)
        planned = plan_go_to(start, np.array([0.0, 0.3, -1.0]), None, None,
                             params.planner.limits)
        with FleetNode.open(params) as node:
            node.check(planned)
        zenoh_config(zenoh_params(tls), Membership("lab", ("v1",)))
    keys = {**leaves(FleetConfig, "fleet."), **leaves(ZenohConfig, "fleet.zenoh.")}
    assert [path for path, key in keys.items() if key not in reads] == []
