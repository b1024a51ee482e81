"""Configuration values are checked for sense, not only for type.

A fuzzed configuration once passed `gs check-config` with gyro_scale -187564, a Vicon
position variance of 1.2e29, an Euler angle of -6.3e11 deg, /dev/urandom as the flight-log
directory and /dev/stdin as the Vicon bind address, and a NUL byte in the file gave a
traceback. Each of those is reproduced here through `load_config` and through the `gs`
console script as a subprocess (exit 2, the field on one line, no traceback); the bounds
are checked against the thesis's printed tables typed in here; and a property test puts
absurd magnitudes, NaN and infinities into every numeric field of the configuration (the
ground station's and the virtual lab's `sim:` section) and requires a ConfigError naming
that field, never another exception.
"""

from __future__ import annotations

import math
import os
import re
import socket
import subprocess
import sys
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
import typer
import yaml
import zmq
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from pydantic import BaseModel
from typer.testing import CliRunner

from groundstation.cli import app
from groundstation.config import (
    GroundStationConfig,
    check_files,
    load_config,
    validate_config,
    zmq_endpoint,
)
from groundstation.errors import ConfigError
from groundstation.flight.assembly import check_config
from sim_device.config import SimConfig

REPO = Path(__file__).resolve().parents[1]
GS = Path(sys.executable).parent / "gs"  # the console script, as a user runs it

# Thesis values typed from the thesis (the independent answers for the bands)
K_GYRO = (0.0144, 0.0143, 0.0127)  # Table 6.2 [rad/s per count]
K_ACC = (0.0086, 0.0077, 0.0111)  # Table 6.2 [m/s^2 per count]
VICON_POSITION_VARIANCE = (4.16e-7, 3.28e-9, 2.91e-7)  # Table 6.1 [m^2]


def _problems(data: dict[str, Any]) -> list[tuple[str, object, str]]:
    """The problems a command reports for ``data``: validated, then checked where it is
    assembled (the virtual lab validates its ``sim:`` section there)."""
    with pytest.raises(ConfigError) as info:
        check_config(validate_config(data, "test.yaml"), "test.yaml")
    return list(info.value.problems)


def _only_problem(data: dict[str, Any]) -> tuple[str, object, str]:
    problems = _problems(data)
    assert len(problems) == 1, problems
    return problems[0]


# --------------------------------------------------------------------------- the findings
# (file content as an editor saves it, the field (or file position) named, words of the
# reason). The file-level ones name the file, the line and the column.
FINDINGS: list[tuple[str, bytes, str, str]] = [
    ("nul-byte", b"vicon:\n  object_name: X3D\x00\n", "2:19",
     "character U+0000 (a NUL byte) is not allowed"),
    ("not-utf8", b"vicon:\n  object_name: X3D\xe9\n", "2:19", "not UTF-8 text (byte 0xe9)"),
    ("gyro-scale", b"vehicle:\n  gyro_scale: [-187564, 0.0143, 0.0127]\n",
     "vehicle.gyro_scale.0", "magnitude outside [1.27e-05, 0.72]"),
    ("vicon-variance", b"vehicle:\n  vicon_position_variance: [1.2e29, 3.28e-9, 2.91e-7]\n",
     "vehicle.vicon_position_variance.0", "outside [3.28e-12, 0.00416]"),
    ("euler-angle", b"vicon:\n  world_to_ned: {euler_xyz_deg: [-6.3e11, 0, 0]}\n",
     "vicon.world_to_ned.euler_xyz_deg.0", "outside [-360, 360]"),
    ("log-dir-device", b"logging:\n  flight_log_dir: /dev/urandom\n",
     "logging.flight_log_dir", "names a character device, not a directory"),
    ("bind-stdin", b"vicon:\n  bind_address: /dev/stdin\n",
     "vicon.bind_address", "not an IPv4 address"),
]
FILE_LEVEL = {"nul-byte", "not-utf8"}


@pytest.mark.parametrize(("name", "content", "named", "reason"), FINDINGS,
                         ids=[f[0] for f in FINDINGS])
def test_load_config_refuses_each_finding(tmp_path: Path, name: str, content: bytes,
                                          named: str, reason: str) -> None:
    path = tmp_path / "fuzzed.yaml"
    path.write_bytes(content)
    with pytest.raises(ConfigError) as info:
        load_config(path)
    message = str(info.value)
    if name in FILE_LEVEL:
        assert message == message.strip() and "\n" not in message, message
        assert message.startswith(f"{path}:{named}: "), message
        assert reason in message
    else:
        (field, _value, why), = info.value.problems
        assert field == named and reason in why, info.value.problems


@pytest.mark.slow
@pytest.mark.parametrize(("name", "content", "named", "reason"), FINDINGS,
                         ids=[f[0] for f in FINDINGS])
def test_gs_check_config_refuses_each_finding_with_exit_2_on_one_line(
        tmp_path: Path, name: str, content: bytes, named: str, reason: str) -> None:
    path = tmp_path / "fuzzed.yaml"
    path.write_bytes(content)
    run = subprocess.run([str(GS), "check-config", str(path)], capture_output=True,
                         text=True, timeout=120, cwd=tmp_path)
    assert run.returncode == 2, run
    assert "Traceback" not in run.stderr + run.stdout and run.stdout == "", run
    lines = run.stderr.splitlines()
    naming = [line for line in lines if named in line]
    assert len(naming) == 1 and reason in naming[0], run.stderr
    # one line naming the problem, then check-config's verdict
    assert len(lines) == 2 and lines[1] == f"{path}: invalid, 1 problem", run.stderr
    if name in FILE_LEVEL:  # the file, the line and column, the reason
        assert lines[0].startswith(f"error: {path}:{named}: ")
    else:  # the file and the field's line, the field: path, value, bound and why
        assert re.match(rf"error: {re.escape(str(path))}:\d+: {re.escape(named)}: ", lines[0])


def _commands_reading_a_config() -> Iterator[tuple[list[str], Any]]:
    """Every `gs` command with a --config option, as (command words, click command)."""
    def walk(command: Any, words: list[str]) -> Iterator[tuple[list[str], Any]]:
        subcommands = getattr(command, "commands", None)
        if subcommands is None:
            if any(param.name == "config" for param in command.params):
                yield words, command
            return
        for name, sub in subcommands.items():
            yield from walk(sub, [*words, name])

    yield from walk(typer.main.get_command(app), [])


@pytest.mark.slow
def test_every_command_that_reads_a_config_refuses_a_nul_byte_in_one_line(
        tmp_path: Path) -> None:
    """The commands share one loader: each refuses the NUL byte with the same line."""
    path = tmp_path / "gs.yaml"
    path.write_bytes(b"vicon:\n  object_name: X3D\x00\n")
    expected = (f"error: {path}:2:19: not valid YAML: character U+0000 (a NUL byte) is not "
                "allowed")
    found = []
    for words, command in _commands_reading_a_config():
        argv = list(words)
        for param in command.params:  # placeholders for what each command requires
            if param.required and param.name != "config":
                value = {"action": "start", "stick": "1500"}.get(  # the numeric ones
                    param.name or "", str(tmp_path / "out"))
                argv += [value] if param.param_type_name == "argument" else \
                    [f"--{param.name.replace('_', '-')}", value]
        result = CliRunner().invoke(app, [*argv, "--config", str(path)])
        assert result.exit_code == 2, (argv, result.output)
        verdict = 1 if words == ["check-config"] else 0  # check-config adds its verdict line
        assert result.output.startswith(expected) and \
            result.output.count("\n") == 1 + verdict, (argv, result.output)
        found.append(" ".join(words))
    # the commands this machine has: the lab's too when it is installed (it is in tests)
    assert {"fly", "calibrate imu", "calibrate vicon", "synth hinf", "replay",
            "sim-device", "eval"} <= set(found), found


@pytest.mark.parametrize("character", ["\x00", "\x1b", "\x7f", "\x85\x86", "\ufffe"])
def test_each_character_yaml_refuses_is_one_line_with_its_position(
        tmp_path: Path, character: str) -> None:
    # U+0085 (NEL) is a YAML line break and allowed; U+0086 after it is the refused one
    path = tmp_path / "gs.yaml"
    path.write_bytes(f"# comment\nvicon:\n  object_name: 'ab{character}'\n".encode())
    refused = character[-1]
    with pytest.raises(ConfigError) as info:
        load_config(path)
    column = len("  object_name: 'ab") + len(character)  # 1-based column of the character
    assert str(info.value).startswith(
        f"{path}:3:{column}: not valid YAML: character U+{ord(refused):04X}"), info.value


def test_an_undecodable_byte_names_its_line_and_character_column(tmp_path: Path) -> None:
    path = tmp_path / "gs.yaml"  # a Latin-1 editor's file: "é" is one byte 0xE9
    path.write_bytes("vicon:\n  object_name: 'Ålborg".encode() + b" caf\xe9'\n")
    column = len("  object_name: 'Ålborg caf") + 1  # 27: Å is one column, two UTF-8 bytes
    with pytest.raises(ConfigError, match=rf":2:{column}: not UTF-8 text \(byte 0xe9\)"):
        load_config(path)
    assert column == 27


# --------------------------------------------------------------------------- the bands
def test_the_scale_bands_come_from_table_6_2_and_keep_the_sign_free() -> None:
    # a reversed axis and a 16-bit LL vehicle (+-500 deg/s over int16: 2.66e-4) pass
    reversed_axis = {"vehicle": {"gyro_scale": [-0.0144, 0.0143, 2.66e-4],
                                 "acc_scale": [0.0086, -0.0077, 6.0e-4]}}
    assert validate_config(reversed_axis).vehicle.gyro_scale[0] == -0.0144
    low, high = min(K_GYRO) / 1000, max(K_GYRO) * 50
    for value, ok in ((high, True), (-high, True), (high * 1.01, False), (low, True),
                      (low * 0.99, False), (0.0, False)):
        data = {"vehicle": {"gyro_scale": [value, 0.0143, 0.0127]}}
        if ok:
            validate_config(data)
        else:
            assert _only_problem(data)[0] == "vehicle.gyro_scale.0"
    field, _, why = _only_problem({"vehicle": {"acc_scale": [0.0086, 0.0077, 1e3]}})
    assert field == "vehicle.acc_scale.2"
    assert f"[{min(K_ACC) / 1000:g}, {max(K_ACC) * 50:g}]" in why and "Table 6.2" in why


def test_the_variance_bands_come_from_table_6_1_and_6_3() -> None:
    low, high = min(VICON_POSITION_VARIANCE) / 1e3, max(VICON_POSITION_VARIANCE) * 1e4
    for value in (low * 0.99, high * 1.01, 0.0, -1e-7):
        field, shown, why = _only_problem(
            {"vehicle": {"vicon_position_variance": [4.16e-7, value, 2.91e-7]}})
        assert (field, shown) == ("vehicle.vicon_position_variance.1", value)
        assert f"[{low:g}, {high:g}]" in why and "Table 6.1" in why
    field, _, why = _only_problem({"vehicle": {"gyro_variance": [1.24e-4, 1.94e-4, 9.0]}})
    assert field == "vehicle.gyro_variance.2" and "Table 6.3" in why
    # an R override is held to the same bands, entry by entry of its diagonal
    field, _, why = _only_problem({"estimator": {"r_override": [1e-6] * 3 + [1e-6, 5.0,
                                                                             1e-6, 1e-6]}})
    assert field == "estimator.r_override" and "diagonal entry 4 = 5" in why


@pytest.mark.parametrize(("data", "field"), [
    ({"vicon": {"world_to_ned": {"euler_xyz_deg": [360.5, 0, 0]}}},
     "vicon.world_to_ned.euler_xyz_deg.0"),
    ({"vicon": {"body_to_object": {"euler_xyz_deg": [0, 0, -361]}}},
     "vicon.body_to_object.euler_xyz_deg.2"),
    ({"trajectory": {"yaw_deg": 720.0}}, "trajectory.yaw_deg"),
    ({"sim": {"initial_yaw_deg": -400.0}}, "sim.initial_yaw_deg"),
])
def test_angles_and_headings_are_within_one_turn(data: dict[str, Any], field: str) -> None:
    path, _, why = _only_problem(data)
    assert path == field and "[-360, 360]" in why and "one turn" in why


def test_a_whole_turn_either_way_is_still_an_angle() -> None:
    cfg = validate_config({"vicon": {"world_to_ned": {"euler_xyz_deg": [-360, 360, 0]}},
                           "trajectory": {"yaw_deg": -180.0}})
    assert cfg.vicon.world_to_ned.euler_xyz_deg == [-360.0, 360.0, 0.0]


@pytest.mark.parametrize(("data", "field", "words"), [
    ({"vehicle": {"gravity": 9.0}}, "vehicle.gravity", "[9.76, 9.84]"),
    ({"vehicle": {"mass_kg": 600.0}}, "vehicle.mass_kg", "[0.01, 20]"),
    ({"vehicle": {"acc_saturation": 5.0}}, "vehicle.acc_saturation", "above 1 g"),
    ({"vehicle": {"thrust_poly": [1e300, -1e300, 0.0, -0.903]}}, "vehicle.thrust_poly",
     "N within the stick range"),
    ({"vehicle": {"induced_inflow": 0.423}}, "vehicle.induced_inflow", "negative"),
    ({"safety": {"volume_z": [-2e6, 0.05]}}, "safety.volume_z.0", "[-100, 100]"),
    ({"safety": {"max_tilt_deg": 95.0}}, "safety.max_tilt_deg", "push down"),
    ({"trajectory": {"period_s": 1e7}}, "trajectory.period_s", "battery"),
    ({"trajectory": {"center": [0.0, 0.0, -1e4]}}, "trajectory.center.2", "lab"),
    ({"controller": {"pid": {"attitude_kp": [4.0, 4.0, 1e4]}}},
     "controller.pid.attitude_kp.2", "Nyquist"),
    ({"controller": {"lqr_ff": {"q_integral": [20.0, 20.0, -1.0, 2.0]}}},
     "controller.lqr_ff.q_integral.2", "0 turns one off"),
    ({"serial": {"baud": 300}}, "serial.baud", "XBee"),
    ({"serial": {"ll": {"rc_channels": [0, 1, 2, 9]}}}, "serial.ll.rc_channels.3",
     "channels_out[8]"),
    ({"serial": {"ll": {"rc_channels": [0, 1, 1, 3]}}}, "serial.ll.rc_channels",
     "given twice"),
    ({"vicon": {"object_name": "X3D\x00"}}, "vicon.object_name", "control character"),
    ({"sim": {"vicon": {"volume_x": [1.0, -1.0]}}}, "sim.vicon.volume_x", "min < max"),
    ({"sim": {"seed": -1}}, "sim.seed", "no negative seed"),
    ({"sim": {"battery_mv": 70_000}}, "sim.battery_mv", "uint16"),
    ({"estimator": {"divergence_trace": 0.1}}, "estimator", "diverged before it started"),
])
def test_each_bound_names_field_value_range_and_why(data: dict[str, Any], field: str,
                                                    words: str) -> None:
    path, _value, why = _only_problem(data)
    assert path == field and words in why, (path, why)


# --------------------------------------------------------------------------- paths
def test_a_log_directory_is_a_directory_or_can_be_made(tmp_path: Path) -> None:
    afile = tmp_path / "notes.txt"
    afile.write_text("not a directory\n")
    for fine in (tmp_path, tmp_path / "new", tmp_path / "new" / "deeper"):
        assert validate_config({"logging": {"flight_log_dir": str(fine)}}).logging \
            .flight_log_dir == fine
    for bad, why in ((afile, "names a regular file, not a directory"),
                     (afile / "logs", "cannot be made"), (Path("/dev/null"), "character")):
        field, value, reason = _only_problem({"logging": {"flight_log_dir": str(bad)}})
        assert (field, value) == ("logging.flight_log_dir", str(bad)) and why in reason


def test_a_file_key_is_a_regular_file(tmp_path: Path) -> None:
    fifo = tmp_path / "laps.csv"
    os.mkfifo(fifo)  # a named pipe would block the flight's read
    for bad, why in ((fifo, "named pipe"), (tmp_path, "a directory"),
                     (Path("/dev/stdin"), "not a regular file")):
        field, _, reason = _only_problem({"trajectory": {"name": "waypoints",
                                                         "file": str(bad)}})
        assert field == "trajectory.file" and why in reason, reason
    field, _, reason = _only_problem({"sim": {"truth_file": str(tmp_path)}})
    assert field == "sim.truth_file" and "a directory" in reason
    # a truth file that does not exist yet is fine where it can be written
    check_config(validate_config({"sim": {"truth_file": str(tmp_path / "later" / "truth.npz")}}))


# --------------------------------------------------------------------------- addresses
def _udp_binds(host: str) -> bool:
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)  # as the Vicon client binds
    try:
        sock.bind((host, 0))
    except OSError:
        return False
    finally:
        sock.close()
    return True


@pytest.mark.parametrize("address", ["0.0.0.0", "127.0.0.1", "localhost"])
def test_bind_addresses_that_a_udp_socket_binds_are_accepted(address: str) -> None:
    assert _udp_binds(address)
    assert validate_config({"vicon": {"bind_address": address}}).vicon.bind_address == address


@pytest.mark.parametrize("address", ["/dev/stdin", "::1", "999.1.1.1", "host name",
                                     "tcp://127.0.0.1:51001", "-x"])
def test_bind_addresses_no_udp_socket_binds_are_refused(address: str) -> None:
    assert not _udp_binds(address)
    assert _only_problem({"vicon": {"bind_address": address}})[0] == "vicon.bind_address"
    assert _only_problem({"sim": {"vicon": {"target_address": address}}})[0] \
        == "sim.vicon.target_address"


def _zmq_bound(endpoint: str) -> str | None:
    """The endpoint a real ZeroMQ PUB socket binds for ``endpoint``, None if it refuses."""
    context = zmq.Context.instance()
    sock = context.socket(zmq.PUB)
    sock.setsockopt(zmq.LINGER, 0)
    try:
        sock.bind(endpoint)
        return str(sock.getsockopt_string(zmq.LAST_ENDPOINT))
    except zmq.ZMQError:
        return None
    finally:
        sock.close()


@pytest.fixture
def short_tmp() -> Iterator[Path]:
    """A directory with a short path (pytest's tmp_path can exceed a Unix socket's)."""
    import tempfile

    with tempfile.TemporaryDirectory(prefix="gs") as folder:
        yield Path(folder)


def test_endpoints_zeromq_binds_are_accepted(short_tmp: Path) -> None:
    for endpoint in ("tcp://127.0.0.1:*", "tcp://*:*", "tcp://lo:*", "tcp://localhost:*",
                     f"ipc://{short_tmp}/gs.sock", "inproc://gs-telemetry"):
        assert _zmq_bound(endpoint) is not None, endpoint
        assert zmq_endpoint(endpoint) == endpoint
        cfg = validate_config({"telemetry": {"endpoint": endpoint}})
        assert cfg.telemetry.endpoint == endpoint


def test_endpoints_zeromq_refuses_or_misreads_are_refused() -> None:
    refused = ["/dev/stdin", "tcp://127.0.0.1", "tcp://:5556", "udp://127.0.0.1:5556",
               "ipc:///tmp/" + "x" * 120, "tcp://[zz]:5556", "tcp://999.1.1.1:*", "ipc://",
               "inproc://", "tcp://127.0.0.1:abc"]
    for endpoint in refused:
        assert _zmq_bound(endpoint) is None, endpoint
    # ZeroMQ takes these, but binds another port than the one written
    misread = ["tcp://127.0.0.1:70000", "tcp://127.0.0.1:-1"]
    for endpoint in misread:
        bound = _zmq_bound(endpoint)
        assert bound is not None and bound.rpartition(":")[2] != endpoint.rpartition(":")[2]
    for endpoint in refused + misread:
        for key in ("endpoint", "control_endpoint"):
            field, value, _ = _only_problem({"telemetry": {key: endpoint}})
            assert (field, value) == (f"telemetry.{key}", endpoint)


# --------------------------------------------------------------------------- bundled files
@pytest.mark.parametrize("path", sorted(p for p in (REPO / "config").glob("*.yaml")
                                         if p.name != "fleet.yaml"),  # test_fleet_config.py
                         ids=lambda p: p.name)
def test_the_bundled_configurations_pass(path: Path) -> None:
    config = load_config(path)
    check_files(config, str(path))
    assert isinstance(config, GroundStationConfig)


# --------------------------------------------------------------------------- property
@dataclass(frozen=True)
class Leaf:
    """One number of the configuration: ``path`` of its field, ``index`` within it (or
    None), and what YAML must hold around it to reach it."""

    path: str
    index: tuple[int, ...]
    integer: bool
    base: Any  # the field's valid value the number is put into

    def data(self, value: object) -> dict[str, Any]:
        """A configuration mapping with ``value`` at this number."""
        field = value
        if self.index:
            field = _replaced(self.base, self.index, value)
        out: dict[str, Any] = {}
        node = out
        *parents, leaf = self.path.split(".")
        for key in parents:
            node = node.setdefault(key, {})
        node[leaf] = field
        return out


def _replaced(base: Any, index: tuple[int, ...], value: object) -> Any:
    copy = [list(x) if isinstance(x, list | tuple) else x for x in base]
    if len(index) == 1:
        copy[index[0]] = value
    else:
        copy[index[0]] = _replaced(copy[index[0]], index[1:], value)
    return copy


# numeric fields whose default holds no number to replace: a valid value to put one in
WITHOUT_NUMBERS: dict[str, Any] = {
    "estimator.r_override": [1e-6] * 7,
    "controller.lqr.q_integral": [1.0] * 4,
    "trajectory.yaw_deg": 0.0,
    "sim.fifo_priority": 20,
    "sim.rate_loop_tau_s": 0.064,
    "sim.command_delay_s": 0.02,
    "sim.faults.stall_at_s": 5.0,
    "sim.vicon.outages": [[1.0, 2.0]],
    "sim.faults.thrust_faults": [[12.0, 0.3, 2.0]],
    "sim.payload_steps": [[20.0, 1.2]],
}
UNBOUNDED_ABOVE = {"sim.seed": "numpy takes any non-negative seed"}


def _numbers(value: Any, index: tuple[int, ...] = ()) -> Iterator[tuple[tuple[int, ...], bool]]:
    if isinstance(value, bool):
        return
    if isinstance(value, int | float):
        yield index, isinstance(value, int)
    elif isinstance(value, list | tuple):
        for i, item in enumerate(value):
            yield from _numbers(item, (*index, i))


def _leaves(model: type[BaseModel], prefix: str) -> Iterator[Leaf]:
    for name, field in model.model_fields.items():
        path = f"{prefix}{name}"
        default = field.get_default(call_default_factory=True)
        if isinstance(default, BaseModel):
            yield from _leaves(type(default), f"{path}.")
            continue
        base = WITHOUT_NUMBERS.get(path, default)
        if isinstance(base, Path | str) or base is None:
            continue
        for index, integer in _numbers(base):
            yield Leaf(path, index, integer, base)


LEAVES = [*_leaves(GroundStationConfig, ""), *_leaves(SimConfig, "sim.")]


def test_the_property_reaches_every_numeric_field() -> None:
    """Every field whose type holds a number is fuzzed (or listed above, with a reason)."""
    def numeric(kind: Any) -> bool:
        if kind in (int, float) or (isinstance(kind, int | float)
                                    and not isinstance(kind, bool)):  # Literal[-2047, 2047]
            return True
        return any(numeric(arg) for arg in getattr(kind, "__args__", ()))

    def fields(model: type[BaseModel], prefix: str) -> Iterator[str]:
        for name, field in model.model_fields.items():
            default = field.get_default(call_default_factory=True)
            if isinstance(default, BaseModel):
                yield from fields(type(default), f"{prefix}{name}.")
            elif numeric(field.annotation):
                yield f"{prefix}{name}"

    every = {*fields(GroundStationConfig, ""), *fields(SimConfig, "sim.")}
    assert every == {leaf.path for leaf in LEAVES}
    assert len(LEAVES) > 150  # the scalars and every entry of the vectors and matrices


HUGE = st.floats(min_value=1e9, max_value=1e300)
ABSURD_FLOAT = st.one_of(st.sampled_from([math.nan, math.inf, -math.inf]), HUGE, HUGE.map(
    lambda x: -x))
HUGE_INT = st.integers(min_value=10 ** 9, max_value=10 ** 30)
ABSURD_INT = st.one_of(HUGE_INT, HUGE_INT.map(lambda n: -n), ABSURD_FLOAT)


@pytest.mark.slow
@pytest.mark.parametrize("leaf", LEAVES, ids=lambda leaf: ".".join(
    [leaf.path, *map(str, leaf.index)]))
@settings(max_examples=8, deadline=None, database=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(value=st.data())
def test_an_absurd_number_anywhere_is_a_config_error_naming_its_field(
        leaf: Leaf, value: st.DataObject, tmp_path: Path) -> None:
    if leaf.path in UNBOUNDED_ABOVE:
        number = value.draw(HUGE_INT.map(lambda n: -n))
    else:
        number = value.draw(ABSURD_INT if leaf.integer else ABSURD_FLOAT)
    path = tmp_path / "fuzzed.yaml"  # written by PyYAML, as another tool would
    path.write_text(yaml.safe_dump(leaf.data(number)), encoding="utf-8")
    with pytest.raises(ConfigError) as info:  # as a command reads it (the lab checks sim:)
        check_config(load_config(path), str(path))
    fields = [field for field, _, _ in info.value.problems]
    assert any(f == leaf.path or f.startswith(f"{leaf.path}.") for f in fields), (
        leaf, number, info.value.problems)
