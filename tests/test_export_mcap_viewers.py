"""`gs export --format mcap` as the viewers read it.

Read back with the `mcap` package's reader and checked against answers found apart from
the exporter: the JSON channels' schemas against a port of Lichtblick's schema parser
(`lichtblick_schema`); the protobuf channels decoded with the schema the file carries (a
FileDescriptorSet read field by field, `test_foxglove`'s decoder); the `/tf` world frame
rotated with scipy to show a vehicle 1 m up (NED z = -1) sits above the grid (world z =
+1); poses and transforms equal to the flight log's own columns; and, where `rerun-sdk`
is installed, Rerun's own MCAP importer turning the poses and transforms into its 3D
types rather than raw blobs.
"""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from lab_helpers import fly_logged, sim_config
from lichtblick_schema import parse_json_schema
from mcap.reader import make_reader
from scipy.spatial.transform import Rotation
from test_foxglove import _decode, _descriptors

from groundstation.app.recorder import read_flight
from groundstation.export import CHANNELS, FOXGLOVE_TOPICS

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def exported(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """(the flight log, its MCAP written by `gs export` run as a user runs it)."""
    tmp = tmp_path_factory.mktemp("viewers")
    log = fly_logged(sim_config(**{"trajectory.name": "hover"}), tmp, 2.0)[0]
    out = tmp / "flight.mcap"
    done = subprocess.run([sys.executable, "-m", "groundstation", "export", str(log),
                           "--format", "mcap", "--out", str(out)],
                          capture_output=True, text=True, timeout=180, cwd=REPO)
    assert done.returncode == 0, done.stderr
    return log, out


def _read(path: Path) -> tuple[dict[str, tuple[str, str, str, bytes]],
                                dict[str, list[tuple[int, bytes]]]]:
    """(topic -> (message encoding, schema name, schema encoding, schema data),
    topic -> [(log time, data)])."""
    channels: dict[str, tuple[str, str, str, bytes]] = {}
    messages: dict[str, list[tuple[int, bytes]]] = defaultdict(list)
    with path.open("rb") as fh:
        for schema, channel, message in make_reader(fh).iter_messages():
            assert schema is not None
            channels[channel.topic] = (channel.message_encoding, schema.name, schema.encoding,
                                       schema.data)
            messages[channel.topic].append((message.log_time, message.data))
    return channels, messages


def test_the_port_of_lichtblicks_parser_refuses_what_lichtblick_refused() -> None:
    """The schemas the viewers choked on before, refused by the port (so it can fail)."""
    with pytest.raises(ValueError, match="Unsupported object field type"):
        parse_json_schema({"type": "object", "properties": {
            "flight_time_s": {"type": ["number", "null"]}}})
    with pytest.raises(ValueError, match="without properties"):
        parse_json_schema({"type": "object", "description": "the whole payload"})
    with pytest.raises(ValueError, match="array item"):
        parse_json_schema({"type": "object", "properties": {
            "m": {"type": "array", "items": {"type": "array"}}}})


@pytest.mark.slow
def test_every_json_channel_has_a_schema_the_viewers_parse(exported: tuple[Path, Path]
                                                           ) -> None:
    channels, messages = _read(exported[1])
    assert set(channels) == set(CHANNELS) | set(FOXGLOVE_TOPICS)
    for topic in CHANNELS:
        encoding, _name, schema_encoding, data = channels[topic]
        assert (encoding, schema_encoding) == ("json", "jsonschema"), topic
        datatypes = parse_json_schema(json.loads(data), topic)
        fields = {name for name, _ in datatypes[topic]}
        body = json.loads(messages[topic][0][1])
        assert set(body) == fields, topic  # every field the message has, the schema names


@pytest.mark.slow
def test_the_3d_channels_are_foxgloves_protobuf_schemas(exported: tuple[Path, Path]) -> None:
    channels, messages = _read(exported[1])
    rows = read_flight(exported[0])[0]
    for topic, schema in FOXGLOVE_TOPICS.items():
        encoding, name, schema_encoding, _ = channels[topic]
        assert (encoding, name, schema_encoding) == ("protobuf", schema, "protobuf"), topic
    assert len(messages["/tf"]) == len(rows)  # every tick
    assert len(messages["/pose/estimate"]) == int(np.isfinite(rows["est_position"]).all(1).sum())


def _decoded(channels: dict[str, tuple[str, str, str, bytes]],
             messages: dict[str, list[tuple[int, bytes]]], topic: str) -> list[dict[str, Any]]:
    _, name, _, data = channels[topic]
    descriptors = _descriptors(data)
    return [_decode(descriptors, name, payload) for _, payload in messages[topic]]


def _quaternion(d: dict[str, Any]) -> Rotation:
    """scipy's rotation of a decoded foxglove.Quaternion (proto3 leaves zeros out)."""
    return Rotation.from_quat([d.get(k, 0.0) for k in "xyzw"])  # scipy: scalar last


@pytest.mark.slow
def test_tf_puts_the_flight_above_the_grid_and_the_body_at_the_estimate(
        exported: tuple[Path, Path]) -> None:
    channels, messages = _read(exported[1])
    rows = read_flight(exported[0])[0]
    transforms = _decoded(channels, messages, "/tf")
    for k in (0, len(rows) // 2, len(rows) - 1):
        by_child = {tr["child_frame_id"]: tr for tr in transforms[k]["transforms"]}
        world = by_child["ned"]
        assert world["parent_frame_id"] == "world"
        # 1 m above the floor is NED z = -1; in the world frame a z-up viewer draws, +1
        up = _quaternion(world["rotation"]).apply([0.3, 0.2, -1.0])
        np.testing.assert_allclose(up, [0.3, -0.2, 1.0], atol=1e-12)
        row = rows[k]
        if np.isfinite(row["est_position"]).all():
            body = by_child["base_link"]
            assert body["parent_frame_id"] == "ned"
            t = body.get("translation", {})
            np.testing.assert_allclose([t.get(a, 0.0) for a in "xyz"], row["est_position"],
                                       atol=1e-9)
            w, x, y, z = row["est_quaternion"] / np.linalg.norm(row["est_quaternion"])
            expected = Rotation.from_quat([x, y, z, w])
            assert (_quaternion(body["rotation"]) * expected.inv()).magnitude() < 1e-9
    # the vehicle hovered 1 m up: every estimate, seen from the world frame, is above z = 0
    world = _quaternion(transforms[0]["transforms"][0]["rotation"])
    hovering = rows["est_position"][rows["est_position"][:, 2] < -0.5]
    assert len(hovering) > 100 and (world.apply(hovering)[:, 2] > 0.5).all()


@pytest.mark.slow
def test_the_poses_and_their_times_are_the_logs(exported: tuple[Path, Path]) -> None:
    channels, messages = _read(exported[1])
    rows = read_flight(exported[0])[0]
    poses = _decoded(channels, messages, "/pose/estimate")
    valid = rows[np.isfinite(rows["est_position"]).all(1)]
    got = np.array([[p["pose"]["position"].get(a, 0.0) for a in "xyz"] for p in poses])
    np.testing.assert_allclose(got, valid["est_position"], atol=1e-9)
    assert {p["frame_id"] for p in poses} == {"ned"}
    # a pose's log time and its header stamp are the JSON topics' log time of that tick
    json_times = {round(json.loads(data)["t"], 9): t for t, data in messages["/estimate"]}
    for (log_time, _), pose, t in zip(messages["/pose/estimate"], poses, valid["t"],
                                      strict=True):
        assert log_time == json_times[round(float(t), 9)]
        stamp = pose["timestamp"]
        assert stamp.get("seconds", 0) * 10**9 + stamp.get("nanos", 0) == log_time


@pytest.mark.slow
@pytest.mark.skipif(shutil.which("rerun", path=str(Path(sys.executable).parent)) is None,
                    reason="rerun-sdk (the dev extra) is not installed")
def test_rerun_reads_the_poses_and_transforms_as_3d_data(exported: tuple[Path, Path],
                                                         tmp_path: Path) -> None:
    """Rerun's MCAP importer: the protobuf channels become its Transform3D and
    InstancePoses3D (drawn in 3D), as many rows as the file holds transforms and poses;
    the JSON topics stay raw messages (Rerun decodes protobuf and ROS 2 only)."""
    rerun = str(Path(sys.executable).parent / "rerun")
    rrd = tmp_path / "flight.rrd"
    converted = subprocess.run([rerun, "mcap", "convert", str(exported[1]), "-o", str(rrd)],
                               capture_output=True, text=True, timeout=300)
    assert converted.returncode == 0, converted.stderr
    printed = subprocess.run([rerun, "rrd", "print", str(rrd)], capture_output=True,
                             text=True, timeout=300)
    assert printed.returncode == 0, printed.stderr
    rows: dict[tuple[str, str], int] = defaultdict(int)
    for count, entity, columns in re.findall(r"with (\d+) rows .*? - (/\S+) - data columns: "
                                             r"\[([^\]]*)\]", printed.stdout):
        rows[(entity, columns.split(":")[0].split()[-1] if ":" in columns else columns)] \
            += int(count)
    channels, messages = _read(exported[1])
    transforms = sum(len(m["transforms"]) for m in _decoded(channels, messages, "/tf"))
    assert rows[("/tf", "Transform3D")] == transforms
    for topic in ("/pose/estimate", "/pose/reference", "/pose/vicon"):
        assert rows[(topic, "CoordinateFrame")] == len(messages[topic]), topic
    assert rows[("/estimate", "McapMessage")] == len(messages["/estimate"])
