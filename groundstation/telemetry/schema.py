"""Telemetry message schema, version 1.

Every message is a two-frame ZeroMQ multipart message ``[topic, payload]``:
``topic`` is the ASCII topic name (subscribers filter on it by prefix) and
``payload`` a UTF-8 JSON object. JSON is strict: no NaN or Infinity (a value that
is not finite is sent as ``null``). Vectors are JSON arrays, frames and units
as in the rest of the package (NED earth, FRD body, scalar-first quaternions,
SI units, RC units for sticks).

Every payload starts with the envelope::

    schema     int    SCHEMA_VERSION (1); a subscriber should check it
    topic      str    the topic again (for logs that drop the first frame)
    seq        int    publisher message counter (gaps = messages dropped on the way)
    t          float  the loop's time.monotonic() for the snapshot [s]
    time_unix  float  wall-clock time.time() when sent [s]

Topic ``state``::

    supervisor  {state: int, name: str}
    estimate    {position [3] m NED, quaternion [4], velocity_body [3] m/s FRD,
                 omega [3] rad/s FRD, gyro_bias [3] rad/s, acc_bias [3] m/s^2} | null
    reference   {position [3] m NED, velocity [3] m/s NED, yaw rad} | null
    error       {position [3] m NED (reference - estimate), distance m} | null
    command     {pitch, roll, yaw, thrust: RC units; mask: ctrl-mask bits; sent: bool}
    vehicle     what the X-3D last reported (STATUS and RC blocks): {battery_v V (null
                before the first STATUS), serial_active bool (it applies our commands),
                motors_on bool, rc_valid bool, applied_mask ctrl-mask bits,
                pilot_enabled bool (the serial-enable switch)} | null
    flight_time_s  float  seconds since the flight loop started [s]
    final       bool  true on the one last ``state`` message of a flight, sent when it
                has ended: ``supervisor`` holds the terminal state
    outcome     str | null  with ``final``: the flight's outcome (``COMPLETED``, ``FAILSAFE``
                or ``STOPPED``, as ``gs fly``'s exit code names it)
    reason      str  with ``final``: why the flight ended (the last transition's reason)

Topic ``health`` (each section an object, or null when that part is not running)::

    link        serial link: rate_hz (DATA frames/s), rejected {reason: count},
                time_since_data_s, and any further counters
    vicon       Vicon input: rate_hz (accepted poses/s), rejected {reason: count},
                time_since_pose_s, and any further counters (ViconHealth's fields)
    estimator   estimator counters, e.g. rejected updates (free-form object)
    loop        loop timing, e.g. overruns, compute_time_s, jitter_s (free-form)
    control     the request socket (``gs channels``): {answered, malformed, failed,
                frames_discarded, refused, socket_errors, reopened} | null
    telemetry   {sent, dropped, errors}: this publisher's own counters

:func:`state_payload` and :func:`health_payload` build the bodies; the publisher
adds the envelope. Extra keys may be added within a schema version; removing or
changing a key bumps :data:`SCHEMA_VERSION`.
"""

from __future__ import annotations

import dataclasses
import enum
import json
import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from groundstation.types import Reference, StateEstimate, Sticks

SCHEMA_VERSION = 1

TOPIC_STATE = "state"
TOPIC_HEALTH = "health"

ENVELOPE_FIELDS = ("schema", "topic", "seq", "t", "time_unix")
REQUIRED_FIELDS: dict[str, tuple[str, ...]] = {
    TOPIC_STATE: (*ENVELOPE_FIELDS, "supervisor", "estimate", "reference", "error", "command"),
    TOPIC_HEALTH: (*ENVELOPE_FIELDS, "link", "vicon", "estimator", "loop", "telemetry"),
}
"""Top-level keys every payload of a topic carries."""


def jsonable(value: Any) -> Any:
    """``value`` as plain JSON types: arrays and tuples -> lists, numpy scalars -> Python,
    dataclasses and mappings -> dicts, enums -> their names, non-finite floats -> None."""
    if isinstance(value, float | np.floating):
        return float(value) if math.isfinite(value) else None
    if isinstance(value, bool | int | str) or value is None:
        return value.name if isinstance(value, enum.Enum) else value
    if isinstance(value, np.ndarray):
        return [jsonable(v) for v in value.tolist()]
    if isinstance(value, np.integer | np.bool_):
        return value.item()
    if isinstance(value, enum.Enum):
        return value.name
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        value = {f.name: getattr(value, f.name) for f in dataclasses.fields(value)}
    if isinstance(value, Mapping):
        return {str(k): jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple | set | frozenset):
        return [jsonable(v) for v in value]
    return str(value)


def encode(topic: str, payload: Mapping[str, Any]) -> list[bytes]:
    """The two frames of a message; ``payload`` must already carry the envelope."""
    body = json.dumps(jsonable(payload), separators=(",", ":"), allow_nan=False)
    return [topic.encode("ascii"), body.encode("utf-8")]


def decode(frames: list[bytes]) -> tuple[str, dict[str, Any]]:
    """``(topic, payload)`` from received frames; ValueError if they are not a message."""
    if len(frames) != 2:
        raise ValueError(f"expected 2 frames, got {len(frames)}")
    topic = frames[0].decode("ascii")
    payload = json.loads(frames[1].decode("utf-8"))
    if not isinstance(payload, dict) or not isinstance(payload.get("schema"), int):
        raise ValueError("payload is not an object with an integer 'schema'")
    return topic, payload


def missing_fields(topic: str, payload: Mapping[str, Any]) -> list[str]:
    """Required top-level keys of ``topic`` absent from ``payload`` (empty if complete)."""
    return [key for key in REQUIRED_FIELDS.get(topic, ENVELOPE_FIELDS) if key not in payload]


def state_payload(
    *, state: int, state_name: str, estimate: StateEstimate | None,
    reference: Reference | None, sticks: Sticks, ctrl_mask: int, sent: bool,
    vehicle: Mapping[str, Any] | None = None, flight_time_s: float = math.nan,
    final: bool = False, outcome: str | None = None, reason: str | None = None,
) -> dict[str, Any]:
    """Body of a ``state`` message (see the module docstring for fields and units),
    already in plain JSON types. ``final`` marks the last message of a flight, which
    carries its ``outcome`` and ``reason``."""
    error = None
    if estimate is not None and reference is not None:
        e = np.asarray(reference.position) - np.asarray(estimate.position)
        error = {"position": e, "distance": float(np.linalg.norm(e))}
    body: dict[str, Any] = jsonable({
        "supervisor": {"state": int(state), "name": state_name},
        "estimate": None if estimate is None else {
            "position": estimate.position, "quaternion": estimate.quaternion,
            "velocity_body": estimate.velocity_body, "omega": estimate.omega,
            "gyro_bias": estimate.gyro_bias, "acc_bias": estimate.acc_bias,
        },
        "reference": None if reference is None else {
            "position": reference.position, "velocity": reference.velocity,
            "yaw": reference.yaw,
        },
        "error": error,
        "command": {"pitch": sticks.pitch, "roll": sticks.roll, "yaw": sticks.yaw,
                    "thrust": sticks.thrust, "mask": int(ctrl_mask), "sent": bool(sent)},
        "vehicle": vehicle,
        "flight_time_s": flight_time_s,
        "final": final,
    })
    if final:
        body["outcome"] = outcome
        body["reason"] = reason
    return body


def health_payload(
    *, link: Any = None, vicon: Any = None, estimator: Any = None, loop: Any = None,
    control: Any = None,
) -> dict[str, Any]:
    """Body of a ``health`` message. Each section is a mapping or a dataclass
    (e.g. :class:`groundstation.vicon.health.ViconHealth`) or None; ``link`` and
    ``vicon`` should carry ``rate_hz`` and ``rejected`` for the monitor. The
    publisher fills in the ``telemetry`` section."""
    return {"link": jsonable(link), "vicon": jsonable(vicon),
            "estimator": jsonable(estimator), "loop": jsonable(loop),
            "control": jsonable(control)}


# --------------------------------------------------------------------------- JSON Schemas
# What a viewer needs to offer the fields for plots and panels (Foxglove, Lichtblick): every
# field with one type (viewers refuse unions such as ["number", "null"]: a value that is
# not there is null or absent, which no viewer checks against the schema), an object's
# fields as properties, arrays of scalars. Lichtblick's parser (mcap-support's
# parseJsonSchema) takes exactly: boolean, string, number, integer, object with
# properties, and arrays of those.

def _field(kind: str, description: str) -> dict[str, Any]:
    return {"type": kind, "description": description}


def _vector(n: int, description: str) -> dict[str, Any]:
    return {"type": "array", "items": {"type": "number"},
            "description": f"{description} ({n} numbers)"}


def _object(description: str, properties: Mapping[str, dict[str, Any]]) -> dict[str, Any]:
    return {"type": "object", "description": description, "properties": dict(properties)}


def _counters(cls: type, description: str) -> dict[str, Any]:
    """The schema of a dataclass of counters and figures (its scalar fields; free-form
    mappings such as ``rejected {reason: count}`` left out: no fixed properties)."""
    import typing

    kinds = {bool: "boolean", int: "integer", float: "number", str: "string"}
    properties = {}
    for name, hint in typing.get_type_hints(cls).items():
        options = [a for a in typing.get_args(hint) if a is not type(None)] or [hint]
        if len(options) == 1 and options[0] in kinds:
            properties[name] = _field(kinds[options[0]], name.replace("_", " "))
    return _object(description, properties)


_ENVELOPE: dict[str, dict[str, Any]] = {
    "schema": _field("integer", "telemetry schema version"),
    "topic": _field("string", "the topic again"),
    "seq": _field("integer", "publisher message counter"),
    "t": _field("number", "the loop's monotonic time of the snapshot [s]"),
    "time_unix": _field("number", "wall-clock time when sent [s since the epoch]"),
}


def state_json_schema(title: str = "groundstation.telemetry.state") -> dict[str, Any]:
    """JSON Schema of a ``state`` message (units in the descriptions)."""
    sticks = {k: _field("integer", f"{k} stick [RC units]")
              for k in ("pitch", "roll", "yaw", "thrust")}
    return {"title": title, **_object("telemetry topic 'state' (NED earth, FRD body, SI)", {
        **_ENVELOPE,
        "supervisor": _object("supervisor state", {
            "state": _field("integer", "state number"),
            "name": _field("string", "state name, e.g. TRACK")}),
        "estimate": _object("the estimate (null before the estimator runs)", {
            "position": _vector(3, "position NED [m]"),
            "quaternion": _vector(4, "attitude body to NED, scalar first [w, x, y, z]"),
            "velocity_body": _vector(3, "velocity FRD [m/s]"),
            "omega": _vector(3, "body rates FRD [rad/s]"),
            "gyro_bias": _vector(3, "gyro bias [rad/s]"),
            "acc_bias": _vector(3, "accelerometer bias [m/s^2]")}),
        "reference": _object("the reference tracked", {
            "position": _vector(3, "position NED [m]"),
            "velocity": _vector(3, "velocity NED [m/s]"),
            "yaw": _field("number", "heading from north [rad]")}),
        "error": _object("reference - estimate", {
            "position": _vector(3, "NED [m]"),
            "distance": _field("number", "[m]")}),
        "command": _object("the COMMAND sent", {
            **sticks, "mask": _field("integer", "ctrl-mask bits"),
            "sent": _field("boolean", "sent this tick")}),
        "vehicle": _object("what the vehicle last reported", {
            "battery_v": _field("number", "battery [V]"),
            "serial_active": _field("boolean", "it applies our commands"),
            "motors_on": _field("boolean", "motors on"),
            "rc_valid": _field("boolean", "the pilot's radio is received"),
            "applied_mask": _field("integer", "channels it applies (ctrl-mask bits)"),
            "pilot_enabled": _field("boolean", "the serial-enable switch")}),
        "flight_time_s": _field("number", "since the flight loop started [s]"),
        "final": _field("boolean", "the flight's last state message"),
        "outcome": _field("string", "with final: COMPLETED, FAILSAFE or STOPPED"),
        "reason": _field("string", "with final: why the flight ended"),
    })}


def health_json_schema(title: str = "groundstation.telemetry.health") -> dict[str, Any]:
    """JSON Schema of a ``health`` message (units in the descriptions)."""
    from groundstation.estimation.records import EkfHealth
    from groundstation.telemetry.requests import RequestStats
    from groundstation.vicon.health import ViconHealth

    return {"title": title, **_object("telemetry topic 'health'", {
        **_ENVELOPE,
        "link": _object("serial link", {
            "rate_hz": _field("number", "DATA frames per second [Hz]"),
            "time_since_data_s": _field("number", "since the last DATA frame [s]")}),
        "vicon": _counters(ViconHealth, "Vicon input: rates [Hz], counters, times [s]"),
        "estimator": _counters(EkfHealth, "estimator counters and consistency"),
        "loop": _object("loop", {"ticks": _field("integer", "loop ticks"),
                                 "commands": _field("integer", "COMMANDs sent")}),
        "control": _counters(RequestStats, "the request socket's counters"),
        "telemetry": _object("this publisher", {
            k: _field("integer", f"messages {k}") for k in ("sent", "dropped", "errors")}),
    })}
