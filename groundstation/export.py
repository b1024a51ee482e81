"""A flight log as CSV, Parquet or MCAP (``gs export LOG --format csv|parquet|mcap``).

All three carry the columns of ``flight.npy`` (:data:`~groundstation.app.recorder.FLAT_DTYPE`,
derived from :data:`~groundstation.app.recorder.RECORD_DTYPE`), so the formats cannot
drift apart from the log or from each other (tests check every column is in each).

CSV (:func:`export_csv`)
    One header line ``name [unit]`` per column (``t [s]``, ``vicon_position_x [m]``;
    dimensionless columns -- unit ``1``, ``bool``, ``enum`` -- without brackets), then one
    line per tick. ``state_name`` (the supervisor state's name) follows ``state``. Integer
    columns (IMU counts, sticks, masks, bools as 0/1) are exact; every float column is
    rounded to its sensor's precision (:data:`CSV_PRECISION`, trailing zeros dropped); a
    missing value (NaN) is an empty field. ``pandas.read_csv(f)`` reads it as written.
Parquet (:func:`export_parquet`, the ``analysis`` extra's pyarrow)
    One column per ``flight.npy`` column at full precision in its own dtype, the unit in
    each field's metadata (``unit``), ``state_name`` as a dictionary (pandas: categorical)
    column after ``state``, and meta.json, the configuration and the exporter's version as
    JSON in the schema metadata (key ``groundstation``).
MCAP (:func:`export_mcap`, written by foxglove-sdk's MCAP writer: the ``analysis``
extra), for Foxglove, Lichtblick, PlotJuggler and Rerun
    One MCAP message per logged tick and topic. The columns travel as JSON with a JSON
    Schema per channel that every viewer parses (one type per field, real properties):
    plain objects whose keys are the flight log's own column names, with their units in
    the schema's descriptions; the channel table :data:`CHANNELS` assigns every column of
    the flight log to exactly one topic. The 3D view's channels are Foxglove's own
    schemas in protobuf, as the live ``gs foxglove`` sends them, which Foxglove,
    Lichtblick and Rerun all decode: ``foxglove.PoseInFrame`` poses (``/pose/vicon``,
    ``/pose/estimate``, ``/pose/reference``, frame ``ned``) and ``foxglove.FrameTransforms``
    on ``/tf``: the fixed ``world -> ned`` (``world`` is z up, so a viewer whose z is up
    draws the flight above its grid, not below it) and ``ned -> base_link`` (the FRD body
    at the estimate). Log time is wall-clock (``start_time`` plus the tick's monotonic
    time since ``start_monotonic``, both in meta.json); each JSON message keeps its
    monotonic ``t`` [s]. The configuration and the version are MCAP metadata records
    (``config``, ``groundstation``).
"""

from __future__ import annotations

import datetime as dt
import json
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any, NamedTuple, TextIO

import numpy as np
import numpy.typing as npt
import structlog

from groundstation import __version__
from groundstation.app.recorder import COLUMN_UNITS, FLAT_DTYPE, RECORD_DTYPE, read_flight
from groundstation.errors import GroundStationError, RecorderError
from groundstation.telemetry.foxglove import (
    TF,
    foxglove_quaternion,
    frame_transforms,
    pose_in_frame,
    sdk_message,
    timestamp_ns,
    yaw_quaternion,
)

CHANNELS: dict[str, tuple[str, ...]] = {
    "/imu": ("imu_t", "imu_counter", "gyro_counts", "acc_counts", "gyro", "acc"),
    "/vicon": ("vicon_valid", "vicon_t", "vicon_position", "vicon_quaternion", "vicon_nis",
               "vicon_refused"),
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

FOXGLOVE_TOPICS: dict[str, str] = {**dict.fromkeys(POSE_TOPICS, "foxglove.PoseInFrame"),
                                   TF: "foxglove.FrameTransforms"}
"""The protobuf channels (Foxglove's schemas), topic -> schema name; every tick's ``/tf``
holds ``world -> ned`` and, with an estimate, ``ned -> base_link``."""

MISSING_SDK = ("MCAP export needs foxglove-sdk (its MCAP writer and Foxglove's schemas): "
               "pip install 'groundstation[analysis]'")


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


def mcap_after_flight(log_dir: Path, truth: Path | None = None) -> list[str]:
    """``logging.mcap``: ``log_dir/flight.mcap`` from a flight's closed log, as ``gs fly``
    writes it once the vehicle is the pilot's (``truth`` is not used). The line saying
    where it is, or why it was not written (logged too: a flight's MCAP is a convenience,
    its log the record)."""
    out = log_dir / "flight.mcap"
    try:
        export_mcap(log_dir, out)
    except Exception as exc:  # the flight is over and its log safe: only the copy is lost
        structlog.get_logger(__name__).warning("flight.mcap not written", error=str(exc))
        return [f"  MCAP (logging.mcap): not written: {exc}"]
    return [f"  MCAP (logging.mcap): {out}"]


def export_mcap(log: str | Path, out: str | Path) -> int:
    """Write the flight log ``log`` as the MCAP file ``out`` (replaced if it exists);
    return the messages written.

    RecorderError if the log cannot be read or the file cannot be written;
    GroundStationError if foxglove-sdk (the ``analysis`` extra) is missing.
    """
    try:
        import foxglove
        from foxglove import channels as fc
    except ImportError as exc:
        raise GroundStationError(MISSING_SDK) from exc
    rows, meta, config = read_flight(log)
    start = dt.datetime.fromisoformat(str(meta.get("start_time", "1970-01-01T00:00:00+00:00")))
    start_ns = int(start.timestamp() * 1e9)
    mono0 = float(meta.get("start_monotonic", rows["t"][0] if len(rows) else 0.0))
    names = list(meta.get("supervisor_states", []))
    context = foxglove.Context()  # private: nothing else logged here lands in the file
    try:
        writer = foxglove.open_mcap(out, allow_overwrite=True, context=context)
    except (OSError, RuntimeError) as exc:  # RuntimeError: the SDK's FoxgloveError
        raise RecorderError(f"cannot write {out}: {exc}") from exc
    typed: dict[str, Any] = {"foxglove.PoseInFrame": fc.PoseInFrameChannel,
                             "foxglove.FrameTransforms": fc.FrameTransformsChannel}
    json_channels: dict[str, Any] = {
        topic: foxglove.Channel(topic, schema=_column_schema(topic, columns), context=context)
        for topic, columns in CHANNELS.items()}
    proto_channels: dict[str, Any] = {topic: typed[schema](topic, context=context)
                      for topic, schema in FOXGLOVE_TOPICS.items()}
    count = 0
    try:
        for row in rows:
            t = float(row["t"])
            log_ns = start_ns + round((t - mono0) * 1e9)
            for topic, columns in CHANNELS.items():
                msg: dict[str, Any] = {"t": t}
                msg.update({name: _value(row[name]) for name in columns})
                if topic == "/supervisor":
                    state = int(row["state"])
                    msg["state_name"] = names[state] if state < len(names) else str(state)
                json_channels[topic].log(msg, log_time=log_ns)
                count += 1
            for topic, schema, body in _foxglove_messages(row, timestamp_ns(log_ns)):
                proto_channels[topic].log(sdk_message(schema, body), log_time=log_ns)
                count += 1
        writer.write_metadata("config", {"yaml": config})
        writer.write_metadata("groundstation", {
            "version": str(meta.get("version", "")), "exporter_version": __version__,
            "schema_version": str(meta.get("schema_version", "")),
            "start_time": str(meta.get("start_time", "")),
            "start_monotonic": str(mono0)})
        writer.close()
    except (OSError, RuntimeError) as exc:
        raise RecorderError(f"cannot write {out}: {exc}") from exc
    finally:
        for channel in (*json_channels.values(), *proto_channels.values()):
            channel.close()
    return count


def _foxglove_messages(row: np.void, stamp: dict[str, int]
                       ) -> list[tuple[str, str, dict[str, Any]]]:
    """One tick's Foxglove messages ``(topic, schema, body)``: a pose per POSE_TOPICS whose
    values are finite rotations and positions, and the ``/tf`` transforms."""
    out: list[tuple[str, str, dict[str, Any]]] = []
    body: tuple[dict[str, float], dict[str, float]] | None = None
    for topic, (pos, att) in POSE_TOPICS.items():
        p = row[pos]
        if not np.all(np.isfinite(p)):
            continue
        try:
            orientation = yaw_quaternion(float(row[att])) if att.endswith("_yaw") \
                else foxglove_quaternion(row[att])
        except ValueError:  # a quaternion that is no rotation (NaN, zero)
            continue
        if not all(math.isfinite(v) for v in orientation.values()):
            continue  # a NaN heading
        position = {"x": float(p[0]), "y": float(p[1]), "z": float(p[2])}
        out.append((topic, FOXGLOVE_TOPICS[topic], pose_in_frame(stamp, position, orientation)))
        if topic == "/pose/estimate":
            body = (position, orientation)
    out.append((TF, FOXGLOVE_TOPICS[TF], frame_transforms(stamp, body)))
    return out


# --------------------------------------------------------------------------- CSV and Parquet


class Precision(NamedTuple):
    """What a float column keeps in the CSV: ``digits`` decimals after the point, or
    ``digits`` significant digits when ``significant``; half a step is the largest error."""

    digits: int
    significant: bool = False

    @property
    def format(self) -> str:
        """The printf format that writes a value at this precision."""
        return f"%.{self.digits}{'g' if self.significant else 'f'}"


_TIME = Precision(6)
# 1 us [s]: time.monotonic() stamps and the loop's timing. A byte on the 57600-baud link
# takes 174 us and the loop's scheduling jitter is tens to hundreds of us (a 20 s demo
# flight: median 0.2 ms), so no stamp means anything finer than 1 us.
_POSITION = Precision(5)
# 0.01 mm in metres. The Vicon UDP stream sends float64 millimetres (docs/vicon-udp.md), not
# quantised; its noise std is at least 0.057 mm (the thesis, Table 6.1: 3.28e-9 m^2 in y),
# so rounding to 0.01 mm (error <= 0.005 mm) stays a tenth below the sensor's own noise.
_QUATERNION = Precision(6)
# 1e-6: the Vicon attitude's noise std is at least 3.3e-5 (Table 6.1: q0 1.09e-9).
_ANGLE = Precision(6)
# 1e-6 rad: the quaternion's resolution as an angle (about 2e-6 rad).
_IMU = Precision(5)
# 1e-5 rad/s, m/s^2: gyro and acc are K (count - zero), K >= 0.0077 per count (the thesis,
# Table 6.2; docs/protocol.md), so 1e-5 is under 1/700 of a count step (the count stays
# recoverable; a tenth of a step for a scale as fine as 1e-4 per count).
_RATE = Precision(5)
# 1e-5 per s for the derived rates (velocity, acceleration, jerk, yaw rate): the Vicon's
# 0.01 mm over one 10 ms tick is 1e-3 m/s; the gyro's step is 0.0127 rad/s.
_BIAS = Precision(6)
# 1e-6 rad/s, m/s^2: estimated biases drift slowly; a tenth of the IMU's precision shows it.
_BATTERY = Precision(3)
# 1 mV: STATUS carries uint16 [mV], LL_STATUS int16 [mV] (docs/protocol.md): lossless.
_COVARIANCE = Precision(4, significant=True)
# 4 significant digits: the diagonal spans 1e-12..1 in mixed units; a statistic, not a
# measurement, so its relative precision (5e-4) is what matters. The same for the NIS
# (a chi-square statistic compared with a gate of about 27).

CSV_PRECISION: dict[str, Precision] = {
    "t": _TIME, "imu_t": _TIME, "vicon_t": _TIME,
    "compute_time": _TIME, "jitter": _TIME, "latency": _TIME,
    "gyro": _IMU, "acc": _IMU,
    "vicon_position": _POSITION, "vicon_quaternion": _QUATERNION,
    "est_position": _POSITION, "est_quaternion": _QUATERNION, "est_velocity_body": _RATE,
    "est_omega": _IMU, "est_gyro_bias": _BIAS, "est_acc_bias": _BIAS,
    "est_covariance_diag": _COVARIANCE, "vicon_nis": _COVARIANCE,
    **{f"{prefix}_{name}": precision for prefix in ("ref", "preview")
       for name, precision in (("position", _POSITION), ("velocity", _RATE), ("yaw", _ANGLE),
                               ("acceleration", _RATE), ("jerk", _RATE),
                               ("yaw_rate", _RATE))},
    "battery_v": _BATTERY,
}
"""The CSV precision of every float field of :data:`RECORD_DTYPE` (a test checks that
every one has one); integer and bool fields are written exactly."""

_DIMENSIONLESS = frozenset({"1", "bool", "enum"})
"""Units a CSV header leaves out (the column name says it all)."""

_STATE_NAME = "state_name"


def _field_of_column() -> dict[str, str]:
    """Flat column (``est_position_x``) -> its :data:`RECORD_DTYPE` field (``est_position``):
    both dtypes list the same values in the same order."""
    flat = list(FLAT_DTYPE.names or ())
    out: dict[str, str] = {}
    for name in RECORD_DTYPE.names or ():
        for _ in range(int(np.prod(RECORD_DTYPE[name].shape))):
            out[flat.pop(0)] = name
    assert not flat
    return out


FIELD_OF_COLUMN = _field_of_column()
"""Every ``flight.npy`` column -> the :data:`RECORD_DTYPE` field it is a component of."""


def tabular_columns() -> list[str]:
    """The CSV's and Parquet's columns: every ``flight.npy`` column in its order, with
    ``state_name`` right after ``state``."""
    columns: list[str] = []
    for name in FLAT_DTYPE.names or ():
        columns.append(name)
        if name == "state":
            columns.append(_STATE_NAME)
    return columns


def csv_header() -> list[str]:
    """The CSV's header fields: ``name [unit]``, or ``name`` for a dimensionless column."""
    return [name if name == _STATE_NAME or COLUMN_UNITS[name] in _DIMENSIONLESS
            else f"{name} [{COLUMN_UNITS[name]}]" for name in tabular_columns()]


def _state_names(meta: dict[str, Any], states: npt.NDArray[Any]) -> list[str]:
    """State names by index, from meta["supervisor_states"], extended with the number
    itself for a state the log's meta does not name."""
    names = [str(n) for n in meta.get("supervisor_states", [])]
    top = int(states.max()) + 1 if len(states) else 0
    return names + [str(i) for i in range(len(names), top)]


def _csv_text(name: str) -> str:
    """A text field, quoted if it needs to be (RFC 4180)."""
    if any(c in name for c in ',"\r\n'):
        return '"' + name.replace('"', '""') + '"'
    return name


def _csv_fields(values: npt.NDArray[Any], precision: Precision | None) -> npt.NDArray[np.str_]:
    """One column's CSV fields: integers exact (bools 0/1); floats at ``precision``
    without trailing zeros (1.500000 -> 1.5, 2.000000 -> 2), NaN empty."""
    if precision is None:
        return values.astype(np.int64).astype(np.str_)
    text = np.char.mod(precision.format, values)
    if not precision.significant:  # %g drops its trailing zeros itself
        text = np.strings.rstrip(np.strings.rstrip(text, "0"), ".")
    text = np.where(text == "-0", "0", text)  # a negative value that rounds to zero
    return np.where(np.isnan(values), "", text)


_CSV_CHUNK_ROWS = 4096
"""Rows formatted at a time (memory stays bounded on a long flight)."""


def export_csv(log: str | Path, out: str | Path | TextIO) -> int:
    """Write the flight log ``log`` as CSV to ``out``; return the rows written.

    out : a file path, or an open text stream (e.g. ``sys.stdout``)

    The first line is the header (:func:`csv_header`: ``t [s],imu_t [s],imu_counter,...``),
    then one line per tick: the ``flight.npy`` columns in order with ``state_name`` after
    ``state``. Integers exact, floats rounded to :data:`CSV_PRECISION`, NaN an empty field:
    ``pandas.read_csv(out)`` reads it back. RecorderError if the log cannot be read or the
    CSV written (its cause a BrokenPipeError when the reader went away).
    """
    rows, meta, _ = read_flight(log)
    flat = rows.view(FLAT_DTYPE)
    names = np.array([_csv_text(n) for n in _state_names(meta, flat["state"])], dtype=np.str_)
    try:
        if isinstance(out, (str, Path)):
            with open(out, "w", encoding="utf-8", newline="") as fh:
                _write_csv(fh, flat, names)
        else:
            _write_csv(out, flat, names)
    except OSError as exc:
        raise RecorderError(f"cannot write {out}: {exc}") from exc
    return len(flat)


def _write_csv(fh: TextIO, flat: npt.NDArray[np.void], state_names: npt.NDArray[np.str_]) -> None:
    fh.write(",".join(csv_header()) + "\n")
    for start in range(0, len(flat), _CSV_CHUNK_ROWS):
        chunk = flat[start:start + _CSV_CHUNK_ROWS]
        columns: list[Sequence[str]] = []
        for name in tabular_columns():
            if name == _STATE_NAME:
                columns.append(state_names[chunk["state"]].tolist())
            else:
                precision = (CSV_PRECISION[FIELD_OF_COLUMN[name]]
                             if FLAT_DTYPE[name].kind == "f" else None)
                columns.append(_csv_fields(chunk[name], precision).tolist())
        fh.write("".join(",".join(line) + "\n" for line in zip(*columns, strict=True)))


def export_parquet(log: str | Path, out: str | Path) -> int:
    """Write the flight log ``log`` as the Parquet file ``out``; return the rows written.

    One column per ``flight.npy`` column, full precision in its own dtype, its unit in the
    field metadata (``unit``); ``state_name`` (dictionary-encoded, pandas reads a
    categorical) after ``state``; the schema metadata's ``groundstation`` key holds
    ``{"meta": meta.json, "config": the YAML text, "exporter_version": ...}`` as JSON.
    RecorderError if the log cannot be read or the file written; GroundStationError if
    pyarrow (the ``analysis`` extra) is missing.
    """
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError as exc:
        raise GroundStationError("Parquet export needs the pyarrow package: pip install "
                                 "'groundstation[analysis]'") from exc
    rows, meta, config = read_flight(log)
    flat = rows.view(FLAT_DTYPE)
    arrays: list[Any] = []
    fields: list[Any] = []
    for name in tabular_columns():
        if name == _STATE_NAME:
            names = pa.array(_state_names(meta, flat["state"]), pa.string())
            array = pa.DictionaryArray.from_arrays(
                pa.array(flat["state"].astype(np.int32), pa.int32()), names)
            metadata = {"description": "supervisor state name (meta supervisor_states)"}
        else:
            array = pa.array(np.ascontiguousarray(flat[name]))
            metadata = {"unit": COLUMN_UNITS[name]}
        arrays.append(array)
        fields.append(pa.field(name, array.type, nullable=False, metadata=metadata))
    document = {"meta": meta, "config": config, "exporter_version": __version__}
    schema = pa.schema(fields, metadata={"groundstation": json.dumps(document)})
    table = pa.Table.from_arrays(arrays, schema=schema)
    try:
        pq.write_table(table, str(out), compression="zstd")
    except OSError as exc:
        raise RecorderError(f"cannot write {out}: {exc}") from exc
    return len(flat)
