"""A flight log as MCAP, for Foxglove, Lichtblick, PlotJuggler and Rerun (``gs export --format
mcap``).

One MCAP message per logged tick and topic, JSON-encoded with a JSON Schema per channel,
so the viewers decode every channel without a ROS installation. Poses use Foxglove's
``foxglove.PoseInFrame`` layout (frame ``ned``; orientation ``x, y, z, w``), which the
3D panel draws; everything else is a plain JSON object whose keys are the flight log's
own column names with their units in the schema's descriptions.

The channel table :data:`CHANNELS` assigns every column of the flight log
(:data:`groundstation.loop.recorder.RECORD_DTYPE`) to exactly one topic (a test checks
this), so the MCAP and ``flight.npy`` carry the same values. Log time is wall-clock
(``start_time`` plus the tick's monotonic time since ``start_monotonic``, both in
meta.json); each message keeps its monotonic ``t`` [s]. The configuration and the
version are MCAP metadata records (``config``, ``groundstation``).
"""

from __future__ import annotations

import datetime as dt
import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from groundstation import __version__
from groundstation.errors import GroundStationError, RecorderError
from groundstation.loop.recorder import COLUMN_UNITS, RECORD_DTYPE, read_flight

CHANNELS: dict[str, tuple[str, ...]] = {
    "/imu": ("imu_t", "imu_counter", "gyro_counts", "acc_counts", "gyro", "acc"),
    "/vicon": ("vicon_valid", "vicon_t", "vicon_position", "vicon_quaternion"),
    "/estimate": ("est_position", "est_quaternion", "est_velocity_body", "est_omega",
                  "est_gyro_bias", "est_acc_bias", "est_covariance_diag"),
    "/reference": ("ref_position", "ref_velocity", "ref_yaw", "ref_acceleration", "ref_jerk",
                   "ref_yaw_rate"),
    "/preview": ("preview_position", "preview_velocity", "preview_yaw",
                 "preview_acceleration", "preview_jerk", "preview_yaw_rate"),
    "/command": ("cmd_pitch", "cmd_roll", "cmd_yaw", "cmd_thrust", "cmd_mask", "cmd_sent",
                 "cmd_automatic", "ctrl_pitch", "ctrl_roll", "ctrl_yaw", "ctrl_thrust"),
    "/vehicle": ("battery_v", "vehicle_flags", "vehicle_mask", "pilot_enabled", "pilot_pitch",
                 "pilot_roll", "pilot_yaw", "pilot_thrust"),
    "/supervisor": ("state",),
    "/timing": ("t", "compute_time", "jitter", "latency"),
}
"""Topic -> the flight-log columns it carries (every column exactly once)."""

POSE_TOPICS = {"/pose/vicon": ("vicon_position", "vicon_quaternion"),
               "/pose/estimate": ("est_position", "est_quaternion"),
               "/pose/reference": ("ref_position", "ref_yaw")}
"""Poses in Foxglove's layout for the 3D panel (the same values as the topics above)."""

_POSE_SCHEMA: dict[str, Any] = {
    "title": "foxglove.PoseInFrame", "type": "object",
    "properties": {
        "timestamp": {"type": "object", "properties": {"sec": {"type": "integer"},
                                                       "nsec": {"type": "integer"}}},
        "frame_id": {"type": "string"},
        "pose": {"type": "object", "properties": {
            "position": {"type": "object", "properties": {
                k: {"type": "number", "description": "NED [m]"} for k in "xyz"}},
            "orientation": {"type": "object", "properties": {
                k: {"type": "number"} for k in "xyzw"}}}},
    },
}


def _unit(name: str) -> str:
    """The unit of a column, or of each of its components (as meta.json lists them)."""
    if name in COLUMN_UNITS:
        return COLUMN_UNITS[name]
    units = [u for key, u in COLUMN_UNITS.items() if key.startswith(name + "_")
             and key[len(name) + 1:].isalnum() and key[:len(name)] == name]
    return units[0] if len(set(units)) == 1 else ", ".join(units)


def _column_schema(topic: str, columns: tuple[str, ...]) -> dict[str, Any]:
    props: dict[str, Any] = {"t": {"type": "number", "description": "monotonic time [s]"}}
    for name in columns:
        field = RECORD_DTYPE[name]
        unit = _unit(name)
        if field.shape:
            kind = "number" if field.base.kind == "f" else "integer"
            props[name] = {"type": "array", "items": {"type": kind},
                           "description": f"[{unit}]"}
        else:
            kind = {"f": "number", "b": "boolean"}.get(field.kind, "integer")
            props[name] = {"type": kind, "description": f"[{unit}]"}
    if topic == "/supervisor":
        props["state_name"] = {"type": "string", "description": "supervisor state"}
    return {"title": f"groundstation{topic.replace('/', '.')}", "type": "object",
            "properties": props}


def _value(v: Any) -> Any:
    if isinstance(v, np.ndarray):
        return [_value(x) for x in v.tolist()]
    if isinstance(v, float) and not math.isfinite(v):
        return None  # JSON has no NaN
    if isinstance(v, (np.floating, np.integer, np.bool_)):
        return _value(v.item())
    return v


def _quaternion_xyzw(q: Any) -> dict[str, float]:
    return {"x": float(q[1]), "y": float(q[2]), "z": float(q[3]), "w": float(q[0])}


def export_mcap(log: str | Path, out: str | Path) -> int:
    """Write the flight log ``log`` as the MCAP file ``out``; return the messages written.

    RecorderError if the log cannot be read; GroundStationError if the ``mcap`` package
    (the ``analysis`` extra) is missing or the file cannot be written.
    """
    try:
        from mcap.writer import CompressionType, Writer
    except ImportError as exc:
        raise GroundStationError("MCAP export needs the mcap package: pip install "
                                 "'groundstation[analysis]'") from exc
    rows, meta, config = read_flight(log)
    start = dt.datetime.fromisoformat(str(meta.get("start_time", "1970-01-01T00:00:00+00:00")))
    start_ns = int(start.timestamp() * 1e9)
    mono0 = float(meta.get("start_monotonic", rows["t"][0] if len(rows) else 0.0))
    names = list(meta.get("supervisor_states", []))
    count = 0
    try:
        with open(out, "wb") as fh:
            writer = Writer(fh, compression=CompressionType.ZSTD)
            writer.start(profile="", library=f"groundstation {__version__}")
            channel_ids = {}
            for topic, columns in CHANNELS.items():
                schema = writer.register_schema(
                    name=f"groundstation{topic.replace('/', '.')}", encoding="jsonschema",
                    data=json.dumps(_column_schema(topic, columns)).encode())
                channel_ids[topic] = writer.register_channel(topic, "json", schema)
            pose_schema = writer.register_schema(name="foxglove.PoseInFrame",
                                                 encoding="jsonschema",
                                                 data=json.dumps(_POSE_SCHEMA).encode())
            for topic in POSE_TOPICS:
                channel_ids[topic] = writer.register_channel(topic, "json", pose_schema)
            for row in rows:
                t = float(row["t"])
                log_ns = start_ns + round((t - mono0) * 1e9)
                stamp = {"sec": log_ns // 1_000_000_000, "nsec": log_ns % 1_000_000_000}
                q: tuple[float, ...]
                for topic, columns in CHANNELS.items():
                    msg: dict[str, Any] = {"t": t}
                    msg.update({name: _value(row[name]) for name in columns})
                    if topic == "/supervisor":
                        state = int(row["state"])
                        msg["state_name"] = names[state] if state < len(names) else str(state)
                    writer.add_message(channel_ids[topic], log_time=log_ns, publish_time=log_ns,
                                       data=json.dumps(msg).encode())
                    count += 1
                for topic, (pos, att) in POSE_TOPICS.items():
                    p = row[pos]
                    if not np.all(np.isfinite(p)):
                        continue
                    if att.endswith("_yaw"):
                        yaw = float(row[att])
                        if not math.isfinite(yaw):
                            continue
                        q = (math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2))
                    else:
                        q = tuple(float(v) for v in row[att])
                        if not all(math.isfinite(v) for v in q):
                            continue
                    pose = {"timestamp": stamp, "frame_id": "ned", "pose": {
                        "position": {"x": float(p[0]), "y": float(p[1]), "z": float(p[2])},
                        "orientation": _quaternion_xyzw(q)}}
                    writer.add_message(channel_ids[topic], log_time=log_ns, publish_time=log_ns,
                                       data=json.dumps(pose).encode())
                    count += 1
            writer.add_metadata("config", {"yaml": config})
            writer.add_metadata("groundstation", {
                "version": str(meta.get("version", "")), "exporter_version": __version__,
                "schema_version": str(meta.get("schema_version", "")),
                "start_time": str(meta.get("start_time", "")),
                "start_monotonic": str(mono0)})
            writer.finish()  # type: ignore[no-untyped-call]
    except OSError as exc:
        raise RecorderError(f"cannot write {out}: {exc}") from exc
    return count
