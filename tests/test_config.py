"""Configuration: shipped files validate; every class of bad input names field, value, reason."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml
from typer.testing import CliRunner

from groundstation.asctec.blocks import sensor_mask
from groundstation.cli import app
from groundstation.config import (
    GroundStationConfig,
    apply_overrides,
    dump_config,
    load_config,
    validate_config,
)
from groundstation.errors import ConfigError, GroundStationError
from groundstation.flight.assembly import check_config
from groundstation.vicon.frames import rotation_from_euler_deg

runner = CliRunner()


@pytest.mark.parametrize("name", ["lab.yaml", "sim.yaml"])
def test_shipped_files_validate(repo: Path, name: str) -> None:
    cfg = load_config(repo / "config" / name)
    assert isinstance(cfg, GroundStationConfig)
    # The numbers the thesis prints must survive the round trip unchanged.
    assert cfg.vehicle.thrust_poly == [2.073e-10, -1.143e-6, -1.054e-3, -0.903]  # eq. 3.7
    assert cfg.vehicle.acc_scale == [0.0086, 0.0077, 0.0111]  # Table 6.2
    assert cfg.vehicle.induced_inflow == -0.423  # eq. C.8
    assert (cfg.sim is not None) == (name == "sim.yaml")


def test_defaults_are_consistent_with_the_thesis_and_spec() -> None:
    cfg = GroundStationConfig()
    # STATUS|GYRO|ACC|RC = bits 0,1,2,4 (spec 3.3).
    assert sensor_mask(cfg.serial.sensors) == 0b10111
    # Mid-stick hover: the polynomial's lift at u = 2000 carries the default mass (DESIGN errata).
    lift_2000 = -np.polyval(cfg.vehicle.thrust_poly, 2000.0)
    assert lift_2000 == pytest.approx(cfg.vehicle.mass_kg * cfg.vehicle.gravity, rel=0.01)
    # The 12-bit zero and Table 6.2 scale put 1 g of specific force at count 1163 (spec 5).
    count = cfg.vehicle.acc_zero[2] + (-cfg.vehicle.gravity) / cfg.vehicle.acc_scale[2]
    assert round(count) == 1163
    # |K| from Ch. 3.3.1: 2047 units gave 2.25 rad/s.
    assert cfg.vehicle.k_rate[0] * 2047 == pytest.approx(2.25, rel=0.01)
    # The default world rotation maps Vicon's z-up to NED's z-down.
    up_in_ned = rotation_from_euler_deg(cfg.vicon.world_to_ned.euler_xyz_deg) \
        @ np.array([0.0, 0.0, 1.0])
    np.testing.assert_allclose(up_in_ned, [0.0, 0.0, -1.0], atol=1e-12)


def _error_for(data: dict[str, object]) -> ConfigError:
    """The error a command reports for ``data``: validated, then checked where it is
    assembled (the virtual lab validates its ``sim:`` section there)."""
    with pytest.raises(ConfigError) as info:
        check_config(validate_config(data, "test.yaml"), "test.yaml")
    return info.value


@pytest.mark.parametrize(
    ("data", "path", "reason"),
    [
        ({"vehicle": {"mass_kg": -0.5}}, "vehicle.mass_kg", "outside [0.01, 20]: kg"),
        ({"vehicle": {"mass": 0.6}}, "vehicle.mass", "unknown key"),
        ({"serial": {"baud": "fast"}}, "serial.baud", "valid integer"),
        ({"channels": {"auto": ["roll", "elevator"]}}, "channels.auto.1", "'pitch', 'roll'"),
        ({"estimator": {"initial_covariance": [1e-4] * 15 + [-1.0]}},
         "estimator.initial_covariance", "not positive definite"),
        ({"estimator": {"r_override": [[1.0, 2.0], [2.0, 1.0]]}},
         "estimator.r_override", "must be 7x7"),
        ({"controller": {"lqr": {"r_input": [1.0, 1.0, 0.0, 1.0]}}},
         "controller.lqr.r_input.2", "outside [1e-06, 1e+06]"),
        ({"serial": {"sensors": ["status", "gyro"]}}, "serial.sensors", "'acc'"),
        ({"vehicle": {"mass_kg": 5.0}}, "vehicle.mass_kg", "could not hover"),  # the mass
        ({"safety": {"volume_x": [1.0, -1.0]}}, "safety.volume_x", "min < max"),
        ({"safety": {"handback_tilt_deg": 30.0}}, "safety", "exceed max_tilt_deg"),
        ({"controller": {"type": "hinf", "hinf": {"gain_file": "/nonexistent.npz"}}},
         "controller", "does not exist"),
        ({"sim": {"vicon": {"outages": [[1.0]]}}}, "sim.vicon.outages.0.1", "missing"),
        ({"vehicle": {"k_rate": [1e-3, 0.0, 1e-3]}}, "vehicle.k_rate.1", "magnitude outside"),
    ],
)
def test_bad_input_names_field_value_and_reason(data: dict[str, object], path: str,
                                                reason: str) -> None:
    err = _error_for(data)
    assert [p for p, _, _ in err.problems] == [path], err
    _, value, why = err.problems[0]
    assert reason in why
    assert path in str(err) and "test.yaml" in str(err)
    assert repr(value) in str(err)


def test_several_problems_are_all_reported() -> None:
    err = _error_for({"vehicle": {"mass_kg": -1, "bogus": 1}, "telemetry": {"rate_hz": 0}})
    assert {p for p, _, _ in err.problems} == {"vehicle.mass_kg", "vehicle.bogus",
                                               "telemetry.rate_hz"}


def test_error_is_also_a_value_error_and_package_error() -> None:
    err = _error_for({"serial": {"port": 3}})
    assert isinstance(err, ValueError) and isinstance(err, GroundStationError)


def test_load_config_file_problems(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="cannot read"):
        load_config(tmp_path / "missing.yaml")
    bad = tmp_path / "bad.yaml"
    bad.write_text("serial: [unclosed\n")
    with pytest.raises(ConfigError, match="not valid YAML"):
        load_config(bad)
    scalar = tmp_path / "scalar.yaml"
    scalar.write_text("42\n")
    with pytest.raises(ConfigError, match="mapping"):
        load_config(scalar)
    empty = tmp_path / "empty.yaml"
    empty.write_text("")  # an empty file is a mistake, not "all defaults"
    with pytest.raises(ConfigError, match="empty"):
        load_config(empty)


def test_overrides_are_validated_like_the_file() -> None:
    cfg = GroundStationConfig()
    new = apply_overrides(cfg, {"serial.port": "/dev/pts/7", "vicon.port": 51002,
                                "controller.type": None})
    assert new.serial.port == "/dev/pts/7" and new.vicon.port == 51002
    assert new.controller.type == cfg.controller.type  # None = option not given
    assert cfg.serial.port == "/dev/ttyUSB0"  # the original is untouched
    with pytest.raises(ConfigError) as info:
        apply_overrides(cfg, {"vicon.port": 70000})
    assert info.value.problems[0][0] == "vicon.port"
    with pytest.raises(ConfigError, match="unknown key"):
        apply_overrides(cfg, {"serial.prot": "/dev/x"})


def test_dump_round_trips() -> None:
    cfg = GroundStationConfig()
    assert validate_config(yaml.safe_load(dump_config(cfg))) == cfg


@pytest.mark.slow
def test_cli_check_config(repo: Path, tmp_path: Path) -> None:
    ok = runner.invoke(app, ["check-config", "--show", str(repo / "config" / "lab.yaml")])
    assert ok.exit_code == 0, ok.output
    assert "thrust_poly" in ok.output and "0.0086" in ok.output
    bad = tmp_path / "bad.yaml"
    bad.write_text("vehicle:\n  mass_kg: -2\n")
    res = runner.invoke(app, ["check-config", str(bad)])
    assert res.exit_code == 2
    assert "vehicle.mass_kg" in res.output and "-2" in res.output


def test_cli_help_lists_commands() -> None:
    res = runner.invoke(app, ["--help"])
    assert res.exit_code == 0
    for command in ("check-config", "fly", "identify"):
        assert command in res.output
