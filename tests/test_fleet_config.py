"""The fleet's configuration: the ``fleet:`` section and ``vicon.source``, and fleet.yaml
checked as a whole (each problem one line naming the file, the line and the field; a bad
fleet file exits 2), and what each vehicle's daemon is given."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
import yaml
from typer.testing import CliRunner

from groundstation.cli import app
from groundstation.config import validate_config, zenoh_local
from groundstation.config.fleetfile import load_fleet
from groundstation.errors import ConfigError
from sim_device.config import sim_section

REPO = Path(__file__).resolve().parents[1]


def problems(data: dict[str, Any]) -> dict[str, str]:
    with pytest.raises(ConfigError) as err:
        validate_config(data, "t.yaml")
    return {path: reason for path, _value, reason in err.value.problems}


@pytest.mark.parametrize(("endpoint", "local"), [
    ("tcp/127.0.0.1:7447", True), ("tcp/127.5.5.5:0", True), ("tcp/[::1]:7447", True),
    ("udp/localhost:7447", True), ("tcp/0.0.0.0:7447", False), ("tcp/10.0.0.2:7447", False),
    ("tcp/lab-pc:7447", False), ("tls/[fe80::1]:7447", False)])
def test_loopback_is_told_from_the_rest(endpoint: str, local: bool) -> None:
    assert zenoh_local(endpoint) is local


def test_beyond_loopback_needs_tls_and_tls_needs_tls_links(tmp_path: Path) -> None:
    assert "without TLS" in problems({"fleet": {"zenoh": {"listen": ["tcp/0.0.0.0:7447"]}}})[
        "fleet.zenoh.listen"]
    assert "reaches beyond loopback" in problems(
        {"fleet": {"zenoh": {"connect": ["tcp/lab-pc:7447"]}}})["fleet.zenoh.connect"]
    for name in ("ca.pem", "me.pem", "me.key"):
        (tmp_path / name).write_text("x")
    tls = {"tls_root_ca": str(tmp_path / "ca.pem"), "tls_certificate": str(tmp_path / "me.pem"),
           "tls_private_key": str(tmp_path / "me.key")}
    plain = problems({"fleet": {"zenoh": {**tls, "listen": ["tcp/10.0.0.1:7447"]}}})
    assert "a plain link beyond loopback" in plain["fleet.zenoh.listen"]
    assert validate_config({"fleet": {"zenoh": {**tls, "listen": ["tls/10.0.0.1:7447"],
                                                "connect": ["tls/10.0.0.2:7447"]}}}).fleet
    half = problems({"fleet": {"zenoh": {"tls_root_ca": str(tmp_path / "ca.pem")}}})
    assert "go together" in half["fleet.zenoh.tls_root_ca"]
    assert "Zenoh endpoint" in problems({"fleet": {"zenoh": {"listen": ["127.0.0.1:7447"]}}})[
        "fleet.zenoh.listen.0"]


def test_names_and_the_zenoh_source() -> None:
    assert "pattern" in problems({"fleet": {"vehicle": "a/b"}})["fleet.vehicle"]
    assert "key of the fleet itself" in problems({"fleet": {"vehicle": "vicon"}})[
        "fleet.vehicle"]
    assert "each peer once" in problems({"fleet": {"vehicle": "a", "peers": ["a"]}})[
        "fleet.peers"]
    assert "needs a fleet: section" in problems({"vicon": {"source": "zenoh"}})["vicon.source"]
    assert validate_config({"vicon": {"source": "zenoh"}, "fleet": {}}).vicon.source == "zenoh"


def write(tmp_path: Path, **changes: Any) -> Path:
    vehicles = [{"name": f"v{k}", "serial_port": f"/dev/x3d-{k}", "vicon_object": f"X3D-{k}",
                 "home": [float(k) - 2.0, 0.0]} for k in (1, 2, 3)]
    data: dict[str, Any] = {"fleet": "lab", "base": str(REPO / "config" / "sim.yaml"),
                            "separation_m": 0.6, "vehicles": vehicles}
    data.update(changes)
    path = tmp_path / "fleet.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    return path


def fleet_problems(path: Path) -> list[str]:
    with pytest.raises(ConfigError) as err:
        load_fleet(path)
    return str(err.value).splitlines()


def test_a_vehicles_daemon_gets_its_port_object_home_peers_and_endpoints(tmp_path: Path
                                                                         ) -> None:
    fleet, base = load_fleet(write(tmp_path, hover_height_m=1.2))
    cfg = fleet.vehicle_config(base, "v2")
    assert cfg.fleet is not None
    assert (cfg.serial.port, cfg.vicon.object_name, cfg.vicon.source) == \
        ("/dev/x3d-2", "X3D-2", "zenoh")
    assert cfg.trajectory.name == "none" and cfg.trajectory.center == [0.0, 0.0, -1.2]
    assert sim_section(cfg).initial_position == [0.0, 0.0, 0.0]
    assert (cfg.fleet.name, cfg.fleet.vehicle, cfg.fleet.peers) == ("lab", "v2", ["v1", "v3"])
    assert cfg.fleet.separation_m == 0.6
    assert cfg.fleet.zenoh.listen == ["tcp/127.0.0.1:7449"]  # the relay's 7447, then 7448..
    assert cfg.fleet.zenoh.connect == ["tcp/127.0.0.1:7447", "tcp/127.0.0.1:7448",
                                       "tcp/127.0.0.1:7450"]
    assert str(cfg.logging.flight_log_dir).endswith("flightlogs/v2")
    assert not cfg.telemetry.enabled and cfg.telemetry.control_endpoint is None


def test_a_vehicles_own_overrides_come_last(tmp_path: Path) -> None:
    path = write(tmp_path)
    data = yaml.safe_load(path.read_text())
    data["vehicles"][0]["overrides"] = {"controller.type": "pid",
                                        "telemetry.control_endpoint": "tcp://127.0.0.1:5600"}
    data["vehicles"][0]["volume"] = {"x": [-1.5, -0.5], "y": [-1.5, 1.5], "z": [-2.0, 0.05]}
    path.write_text(yaml.safe_dump(data))
    fleet, base = load_fleet(path)
    cfg = fleet.vehicle_config(base, "v1")
    assert cfg.controller.type == "pid"
    assert cfg.telemetry.control_endpoint == "tcp://127.0.0.1:5600"
    assert cfg.safety.volume_x == (-1.5, -0.5)


def test_the_fleet_file_is_checked_as_a_whole(tmp_path: Path) -> None:
    path = write(tmp_path)
    data = yaml.safe_load(path.read_text())
    data["vehicles"][1]["serial_port"] = "/dev/x3d-1"
    data["vehicles"][2]["vicon_object"] = "X3D-1"
    data["vehicles"][2]["name"] = "v1"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    lines = fleet_problems(path)
    text = path.read_text().splitlines()
    second = [i + 1 for i, x in enumerate(text) if "serial_port: /dev/x3d-1" in x][1]
    assert any(f":{second}: vehicles.1.serial_port: '/dev/x3d-1': also vehicle 0's" in x
               for x in lines), lines
    assert any("vehicles.2.name: 'v1': also vehicle 0's" in x for x in lines), lines
    assert any("vehicles.2.vicon_object: 'X3D-1'" in x for x in lines), lines


def test_homes_keep_the_separation_and_volumes_overlap_only_with_it(tmp_path: Path) -> None:
    data = yaml.safe_load(write(tmp_path).read_text())
    data["vehicles"][1]["home"] = [-0.5, 0.0]  # 0.5 m from v1: less than 0.6
    close = write(tmp_path, vehicles=data["vehicles"])
    assert any("vehicles.1.home: [-0.5, 0.0]: 0.50 m from v1's, less than separation_m"
               in x for x in fleet_problems(close))
    shared = write(tmp_path, separation_m=None)
    assert sum("overlaps" in x and "only with separation_m set" in x
               for x in fleet_problems(shared)) == 3
    data = yaml.safe_load(write(tmp_path).read_text())
    for k, (lo, hi) in enumerate(((-1.5, -0.5), (-0.5, 0.5), (0.5, 1.5))):
        data["vehicles"][k]["volume"] = {"x": [lo, hi], "y": [-1.5, 1.5], "z": [-2.0, 0.05]}
    apart = write(tmp_path, separation_m=None, vehicles=data["vehicles"])
    assert load_fleet(apart)[0].separation_m is None  # side by side: no separation needed
    data["vehicles"][0]["home"] = [0.0, 0.0]
    outside = write(tmp_path, separation_m=None, vehicles=data["vehicles"])
    assert any("vehicles.0.home: [0.0, 0.0]: outside its volume" in x
               for x in fleet_problems(outside))


def test_a_bad_fleet_file_is_exit_2_naming_the_field(tmp_path: Path) -> None:
    path = write(tmp_path, separation_m=-1.0, relay={"listen": "tcp/0.0.0.0:7447"})
    result = CliRunner().invoke(app, ["fleet", "check", str(path)])
    assert result.exit_code == 2, result.output
    assert "separation_m: -1.0: outside (0, 100]" in result.output
    good = CliRunner().invoke(app, ["fleet", "check", str(write(tmp_path))])
    assert good.exit_code == 0, good.output
    assert good.output.splitlines()[-1].endswith("valid: 3 vehicles, separation 0.6 m")


def test_the_shipped_example_is_valid() -> None:
    fleet, base = load_fleet(REPO / "config" / "fleet.yaml")
    assert len(fleet.names) == 3 and fleet.separation_m is not None
    for name in fleet.names:
        assert fleet.vehicle_config(base, name).fleet is not None
