"""Hostile configuration files: every bad file or value is refused with exit
2 and a message naming the field, the value and the reason, through `gs check-config` and
through the `load()` that `gs fly` runs; never a traceback, never a silent default."""

from __future__ import annotations

from pathlib import Path

import pytest
import typer
from typer.testing import CliRunner

from groundstation.cli import app, load
from groundstation.config import MAX_YAML_VALUES, load_config

runner = CliRunner()

KEYS = "KEYS"  # replaced by the CURVE key directory in the test


@pytest.fixture
def keys(tmp_path: Path) -> Path:
    """A directory with the daemon's key pair and one authorised client's public key."""
    import zmq.auth

    folder = tmp_path / "keys"
    (folder / "clients").mkdir(parents=True)
    zmq.auth.create_certificates(folder, "server")
    zmq.auth.create_certificates(folder / "clients", "alice")
    return folder


# (file content, the field or words the refusal names)
BAD_FILES: list[tuple[bytes, str]] = [
    (b"serial:\n  port: /dev/ttyUSB0\n  baud: 1e30\n", "serial.baud: 1e+30"),
    (b"serial:\n  data_period_ms: 10.5\n", "serial.data_period_ms: 10.5"),
    (b"vicon:\n  latency_s: .inf\n", "vicon.latency_s: inf"),
    (b"safety:\n  link_loss_s: .inf\n", "safety.link_loss_s: inf"),
    (b"safety:\n  link_loss_s: 1.0e300\n", "safety.link_loss_s: 1e+300"),
    (b"serial:\n  baud: 100000000\n", "serial.baud: 100000000"),
    (b"vicon:\n  latency_s: 1.0e9\n", "vicon.latency_s: 1000000000.0"),
    (b"vehicle:\n  mass_kg: .nan\n", "vehicle.mass_kg: nan"),
    (b"vicon:\n  port: true\n", "vicon.port: True"),
    (b"telemetry:\n  enabled: 1\n", "telemetry.enabled: 1"),
    (b"vicon:\n  latency_s: '0.005'\n", "vicon.latency_s: '0.005'"),
    (b"vicon:\n  port: 51001\nserial:\n  baud: 57600\nvicon:\n  port: 51002\n",
     ":5: vicon: duplicate key (first at line 1"),
    (b"vicon:\n  port: 51001\n  object_name: X3D\n  port: 51002\n",
     ":4: vicon.port: duplicate key (first at line 2"),
    (b"serial:\n  port: /dev/tty\xff\xfe\n", ":2:17: not UTF-8 text (byte 0xff)"),
    (b"", "empty"),
    (b"# only a comment\n\n", "empty"),
    (b"vicon: {}\n---\nserial: {}\n", "not valid YAML: expected a single document"),
    (b"serial: [unclosed\n", "not valid YAML"),
    (b"a: &a [1, 1, 1, 1, 1, 1, 1, 1, 1, 1]\nb: &b [*a, *a, *a, *a, *a, *a, *a, *a, *a, *a]\n"
     b"c: &c [*b, *b, *b, *b, *b, *b, *b, *b, *b, *b]\nd: &d [*c, *c, *c, *c, *c, *c, *c, *c]\n"
     b"e: &e [*d, *d, *d, *d, *d, *d, *d, *d, *d, *d]\nf: [*e, *e, *e, *e, *e, *e, *e, *e]\n",
     f"more than {MAX_YAML_VALUES} values"),
    (b"telemetry:\n  control_endpoint: tcp://0.0.0.0:5557\n",
     "telemetry.control_endpoint: 'tcp://0.0.0.0:5557': reaches beyond loopback"),
    (b"telemetry:\n  control_endpoint: tcp://*:5557\n", "telemetry.control_endpoint"),
    (b"trajectory:\n  name: waypoints\n  file: /nonexistent/laps.csv\n",
     "trajectory.file: '/nonexistent/laps.csv': no such file"),
    (b"controller:\n  hinf:\n    gain_file: /nonexistent/gain.npz\n",
     "controller.hinf.gain_file: '/nonexistent/gain.npz': no such file"),
    (f"telemetry:\n  control_endpoint: tcp://*:5557\n  control_server_key: {KEYS}/absent"
     f"\n  control_client_keys: {KEYS}/clients\n".encode(),
     "telemetry.control_server_key: 'KEYS/absent': no such file"),
    (f"telemetry:\n  control_server_key: {KEYS}/server.key\n"
     f"  control_client_keys: {KEYS}/clients\n".encode(),
     "telemetry.control_server_key: 'KEYS/server.key': no secret key"),
    (f"telemetry:\n  control_server_key: {KEYS}/server.key_secret\n"
     f"  control_client_keys: {KEYS}/clients/alice.key\n".encode(),
     "telemetry.control_client_keys: 'KEYS/clients/alice.key': names a regular file, not a "
     "directory"),
    (f"telemetry:\n  control_server_key: {KEYS}/server.key_secret\n".encode(),
     "telemetry.control_client_keys: None: control_server_key and control_client_keys go "
     "together"),
]


def _write(tmp_path: Path, keys: Path, content: bytes) -> Path:
    path = tmp_path / "gs.yaml"
    path.write_bytes(content.replace(KEYS.encode(), str(keys).encode()))
    return path


@pytest.mark.parametrize(("content", "named"), BAD_FILES)
def test_check_config_refuses_with_exit_2_naming_the_field(
        tmp_path: Path, keys: Path, content: bytes, named: str) -> None:
    res = runner.invoke(app, ["check-config", str(_write(tmp_path, keys, content))])
    assert res.exit_code == 2, res.output
    assert res.exception is None or isinstance(res.exception, SystemExit), res.exception
    assert named.replace(KEYS, str(keys)) in res.output, res.output
    assert "Traceback" not in res.output


@pytest.mark.parametrize(("content", "named"), BAD_FILES)
def test_the_fly_load_path_refuses_the_same(tmp_path: Path, keys: Path, content: bytes,
                                            named: str, capsys: pytest.CaptureFixture[str]
                                            ) -> None:
    with pytest.raises(typer.Exit) as info:
        load(_write(tmp_path, keys, content))
    assert info.value.exit_code == 2
    assert named.replace(KEYS, str(keys)) in capsys.readouterr().err


def test_a_missing_waypoint_file_given_on_the_command_line(tmp_path: Path,
                                                           capsys: pytest.CaptureFixture[str]
                                                           ) -> None:
    good = tmp_path / "gs.yaml"
    good.write_text("trajectory:\n  name: hover\n")
    with pytest.raises(typer.Exit) as info:  # as `gs fly --trajectory laps.csv`
        load(good, {"trajectory.name": "waypoints", "trajectory.file": "absent/laps.csv"})
    assert info.value.exit_code == 2
    assert "trajectory.file: 'absent/laps.csv': no such file" in capsys.readouterr().err


def test_file_level_refusals_are_one_line(tmp_path: Path) -> None:
    for content in (b"\xff\xfe\x00", b"", b"vicon: 1\nvicon: 2\n", b"a: [b\n"):
        path = tmp_path / "gs.yaml"
        path.write_bytes(content)
        with pytest.raises(ValueError) as info:
            load_config(path)
        assert "\n" not in str(info.value), str(info.value)


def test_what_yaml_writes_as_numbers_still_validates(tmp_path: Path) -> None:
    path = tmp_path / "gs.yaml"
    path.write_text("vicon:\n  latency_s: 5e-3\n  expected_rate_hz: 100\n"  # YAML 1.2 float, int
                    "estimator:\n  divergence_trace: 1e1\n"
                    "safety:\n  volume_x: [-1.5, 1.5]\n")  # a list for a tuple
    cfg = load_config(path)
    assert cfg.vicon.latency_s == 0.005 and cfg.estimator.divergence_trace == 10.0
    assert cfg.vicon.expected_rate_hz == 100.0 and cfg.safety.volume_x == (-1.5, 1.5)


def test_a_curve_protected_control_socket_may_bind_beyond_loopback(tmp_path: Path,
                                                                    keys: Path) -> None:
    path = _write(tmp_path, keys, f"telemetry:\n  control_endpoint: tcp://*:5557\n"
                                  f"  control_server_key: {keys}/server.key_secret\n"
                                  f"  control_client_keys: {keys}/clients\n".encode())
    res = runner.invoke(app, ["check-config", "--show", str(path)])
    assert res.exit_code == 0, res.output
    assert "control_endpoint: tcp://*:5557" in res.output


@pytest.mark.filterwarnings("ignore:invalid value encountered:RuntimeWarning")  # scipy's DARE
def test_check_config_builds_the_flight_as_gs_fly_does(tmp_path: Path) -> None:
    """Weights that validate but admit no controller are refused before flight, not at it."""
    path = tmp_path / "gs.yaml"
    path.write_text("controller:\n  lqr_ff:\n    q_error: [1e300, 1e300, 1e300, 1e300]\n")
    res = runner.invoke(app, ["check-config", str(path)])
    assert res.exit_code == 2 and "Riccati" in res.output, res.output


def test_an_override_below_a_value_is_refused_naming_it() -> None:
    from groundstation.config import GroundStationConfig, apply_overrides
    from groundstation.errors import ConfigError

    with pytest.raises(ConfigError) as info:
        apply_overrides(GroundStationConfig(), {"serial.port.speed": 1})
    assert info.value.problems == [("serial.port", "/dev/ttyUSB0", "not a section")]
