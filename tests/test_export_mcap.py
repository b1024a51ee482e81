"""`gs export --format mcap`: a flight log the robotics viewers open.

Read back with the `mcap` package's own reader: every JSON channel decodes against its
JSON Schema's properties, every tick is there on every column topic with the flight log's
own values, log times are wall-clock from meta.json's anchor, and the configuration
travels as metadata. The column set of flight.npy and of the MCAP cannot drift apart:
every column belongs to exactly one topic. (The poses and transforms, Foxglove's protobuf
schemas, are read in `test_export_mcap_viewers.py`.)
"""

from __future__ import annotations

import datetime as dt
import json
import subprocess
import sys
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
from lab_helpers import fly_logged, sim_config
from mcap.reader import make_reader

from groundstation.app.recorder import RECORD_DTYPE, read_flight
from groundstation.export import CHANNELS, FOXGLOVE_TOPICS

REPO = Path(__file__).resolve().parents[1]


def test_every_column_is_on_exactly_one_topic() -> None:
    columns = Counter(c for topic in CHANNELS.values() for c in topic)
    assert set(columns) == set(RECORD_DTYPE.names or ())
    assert max(columns.values()) == 1


@pytest.fixture(scope="module")
def log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return fly_logged(sim_config(**{"trajectory.name": "hover"}),
                      tmp_path_factory.mktemp("mcap"), 2.0)[0]


@pytest.mark.slow
def test_the_mcap_reads_back_with_the_logs_values(log: Path, tmp_path: Path) -> None:
    out = tmp_path / "flight.mcap"
    done = subprocess.run([sys.executable, "-m", "groundstation", "export", str(log),
                           "--format", "mcap", "--out", str(out)],
                          capture_output=True, text=True, timeout=120, cwd=REPO)
    assert done.returncode == 0, done.stderr
    rows, meta, config = read_flight(log)
    per_topic: dict[str, list[dict[str, object]]] = {}
    times: dict[str, list[int]] = {}
    with out.open("rb") as fh:
        reader = make_reader(fh)
        metadata = {m.name: m.metadata for m in reader.iter_metadata()}
        for schema, channel, message in reader.iter_messages():
            assert schema is not None
            if channel.topic in FOXGLOVE_TOPICS:
                assert channel.message_encoding == "protobuf"
                times.setdefault(channel.topic, []).append(message.log_time)
                continue
            assert channel.message_encoding == "json"
            body = json.loads(message.data)
            properties = json.loads(schema.data)["properties"]
            assert set(body) == set(properties), channel.topic  # decodes against its schema
            per_topic.setdefault(channel.topic, []).append(body)
            times.setdefault(channel.topic, []).append(message.log_time)
    assert set(per_topic) == set(CHANNELS)
    assert set(times) == set(CHANNELS) | set(FOXGLOVE_TOPICS)
    for topic in CHANNELS:
        assert len(per_topic[topic]) == len(rows), topic  # every tick on every column topic
    np.testing.assert_allclose([m["battery_v"] for m in per_topic["/vehicle"]],
                               rows["battery_v"])
    np.testing.assert_allclose([m["gyro"] for m in per_topic["/imu"]], rows["gyro"])
    names = [m["state_name"] for m in per_topic["/supervisor"]]
    assert names[-1] == meta["supervisor_states"][rows["state"][-1]] == "DONE"
    # a Vicon pose wherever the log holds a finite one
    assert len(times["/pose/vicon"]) == int(np.isfinite(rows["vicon_position"]).all(1).sum())
    # wall-clock log time: start_time plus the monotonic time since start_monotonic
    start = dt.datetime.fromisoformat(meta["start_time"]).timestamp()
    expected = start + (rows["t"][0] - meta["start_monotonic"])
    assert times["/timing"][0] / 1e9 == pytest.approx(expected, abs=1e-6)
    assert all(np.diff(times["/timing"]) > 0)
    assert metadata["config"]["yaml"] == config
    assert metadata["groundstation"]["schema_version"] == str(meta["schema_version"])


@pytest.mark.slow
def test_mcap_needs_an_output_file(log: Path) -> None:
    done = subprocess.run([sys.executable, "-m", "groundstation", "export", str(log),
                           "--format", "mcap"], capture_output=True, text=True, timeout=60,
                          cwd=REPO)
    assert done.returncode == 2 and "--out" in done.stderr


@pytest.mark.slow
def test_the_readmes_pandas_one_liner_works(log: Path) -> None:
    import pandas as pd

    frame = pd.DataFrame(np.load(log / "flight.npy"))
    assert "battery_v" in frame.columns and len(frame) == len(read_flight(log)[0])
