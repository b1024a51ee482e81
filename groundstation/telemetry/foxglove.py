"""``gs foxglove``: the telemetry as a live Foxglove WebSocket server.

A separate subscriber process (the flight loop never waits for it): it subscribes to
the daemon's telemetry (:mod:`groundstation.telemetry.schema`) and serves the Foxglove
WebSocket protocol with the official ``foxglove-sdk``, so Foxglove and Lichtblick show
the vehicle in 3D, the reference path, the supervisor state and live plots. Needs the
``foxglove`` extra: ``pip install 'groundstation[foxglove]'``. The SDK (0.30) speaks
the protocol under its current subprotocol name ``foxglove.sdk.v1`` only and refuses a
client that offers only the former name ``foxglove.websocket.v1`` (the same messages;
Lichtblick's releases): so the SDK's server listens on loopback only and viewers connect
to a relay (:mod:`groundstation.telemetry.ws_relay`) that accepts either name.

The JSON channels' schemas are ones every viewer parses: one type per field, objects
with their properties (:func:`groundstation.telemetry.schema.state_json_schema`).

Two layers:

* :class:`LiveView` is pure: :meth:`LiveView.messages_for` turns one telemetry message
  into ``(channel, message)`` pairs, each message a plain dict in the layout of the
  channel's schema (Foxglove's own field names for the ``foxglove.*`` schemas, as their
  JSON encoding spells them). It keeps the paths of the last ``path_window_s`` seconds.
* :func:`run_foxglove` is the server loop: it creates the channels (:data:`CHANNELS`)
  in a private SDK context, builds the SDK's typed messages from those dicts (protobuf
  on the wire) and logs them with the telemetry's ``time_unix`` as log time [ns].

Frames (the package's conventions): ``ned`` is the earth frame (x north, y east,
z down) [m]; ``base_link`` is the body frame (FRD: x forward, y right, z down);
``world`` is ``ned`` turned 180° about its x axis (x north, y west, z up), added only
so the 3D panel, which treats z as up, shows the lab upright by default. Telemetry
quaternions are scalar-first ``[w, x, y, z]`` with R(q) = eCb (body to earth); Foxglove
wants ``{x, y, z, w}``, the same rotation, so ``ned -> base_link`` carries it unchanged.
"""

from __future__ import annotations

import math
import signal
import threading
import time
from collections import deque
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any

from groundstation.errors import TelemetryError
from groundstation.telemetry.schema import (
    SCHEMA_VERSION,
    TOPIC_HEALTH,
    TOPIC_STATE,
    health_json_schema,
    state_json_schema,
)
from groundstation.telemetry.subscriber import TelemetrySubscriber

NED_FRAME = "ned"
"""The earth frame (NED) the poses and paths are expressed in."""
BODY_FRAME = "base_link"
"""The vehicle's body frame (FRD), child of :data:`NED_FRAME` in ``/tf``."""
WORLD_FRAME = "world"
"""Parent of :data:`NED_FRAME`: x north, y west, z up (the 3D panel's upright view)."""

POSE_ESTIMATE = "/pose/estimate"
POSE_REFERENCE = "/pose/reference"
TF = "/tf"
PATH_ESTIMATE = "/path/estimate"
PATH_REFERENCE = "/path/reference"
SUPERVISOR = "/supervisor"
STATE = "/state"
HEALTH = "/health"

CHANNELS: dict[str, str] = {
    POSE_ESTIMATE: "foxglove.PoseInFrame",    # estimated pose in ned [m], attitude eCb
    POSE_REFERENCE: "foxglove.PoseInFrame",   # reference position in ned [m], yaw about z
    TF: "foxglove.FrameTransforms",           # world -> ned (fixed), ned -> base_link
    PATH_ESTIMATE: "foxglove.SceneUpdate",    # line strip of the last path_window_s [m]
    PATH_REFERENCE: "foxglove.SceneUpdate",
    SUPERVISOR: "groundstation.Supervisor",   # JSON {state, name, final, flight_time_s}
    STATE: "groundstation.telemetry.state",   # JSON: the whole state payload
    HEALTH: "groundstation.telemetry.health",  # JSON: the whole health payload
}
"""Channel topic -> schema name. ``foxglove.*`` channels are the SDK's typed (protobuf)
channels; the others are JSON with a JSON Schema of that title."""

JSON_SCHEMAS: dict[str, dict[str, Any]] = {
    SUPERVISOR: {
        "title": CHANNELS[SUPERVISOR], "type": "object",
        "properties": {
            "state": {"type": "integer", "description": "supervisor state number"},
            "name": {"type": "string", "description": "state name, e.g. TRACK"},
            "final": {"type": "boolean",
                      "description": "true on the last state message of a flight"},
            "flight_time_s": {"type": "number",  # absent when not published: no union
                              "description": "time since the flight loop started [s]"},
        },
    },
    STATE: state_json_schema(CHANNELS[STATE]),
    HEALTH: health_json_schema(CHANNELS[HEALTH]),
}
"""JSON Schemas of the JSON channels (the viewers use them for field names and plots):
one type per field and real properties, as every viewer's parser needs."""

MISSING_EXTRA = ("gs foxglove needs the optional package foxglove-sdk: "
                 "pip install 'groundstation[foxglove]'")

_LINE_STRIP = 0  # foxglove.LinePrimitive.type LINE_STRIP
_PATH_STYLE = {  # channel -> (entity id, RGBA colour, thickness [px])
    PATH_ESTIMATE: ("estimate", {"r": 0.1, "g": 0.6, "b": 1.0, "a": 1.0}, 2.0),
    PATH_REFERENCE: ("reference", {"r": 1.0, "g": 0.5, "b": 0.0, "a": 0.8}, 2.0),
}
_WORLD_TO_NED = {"x": 1.0, "y": 0.0, "z": 0.0, "w": 0.0}  # 180° about x
_PERIOD_SLACK_S = 1e-3  # 4 telemetry periods of 0.05 s make one 0.2 s path period


def foxglove_quaternion(q_wxyz: Sequence[float]) -> dict[str, float]:
    """A scalar-first unit quaternion ``[w, x, y, z]`` as Foxglove's ``{x, y, z, w}``
    (normalised; the same rotation). ValueError for a zero or non-finite quaternion."""
    w, x, y, z = (float(v) for v in q_wxyz)
    norm = math.sqrt(w * w + x * x + y * y + z * z)
    if not (math.isfinite(norm) and norm > 0.0):
        raise ValueError(f"not a rotation quaternion: {list(q_wxyz)}")
    return {"x": x / norm, "y": y / norm, "z": z / norm, "w": w / norm}


def yaw_quaternion(yaw: float) -> dict[str, float]:
    """Foxglove ``{x, y, z, w}`` of a rotation by ``yaw`` [rad] about the NED z axis
    (down; positive yaw turns north towards east)."""
    return {"x": 0.0, "y": 0.0, "z": math.sin(yaw / 2.0), "w": math.cos(yaw / 2.0)}


def timestamp(time_unix: float) -> dict[str, int]:
    """Foxglove ``{sec, nsec}`` of a wall-clock time [s since the epoch]."""
    return timestamp_ns(log_time_ns(time_unix))


def timestamp_ns(ns: int) -> dict[str, int]:
    """Foxglove ``{sec, nsec}`` of a wall-clock time [ns since the epoch]."""
    return {"sec": ns // 1_000_000_000, "nsec": ns % 1_000_000_000}


def log_time_ns(time_unix: float) -> int:
    """A wall-clock time [s since the epoch] as integer nanoseconds (whole seconds and
    the fraction converted apart, so the float's own resolution, about 0.2 µs today, is
    all that is lost)."""
    seconds = math.floor(time_unix)
    return int(seconds) * 1_000_000_000 + round((float(time_unix) - seconds) * 1e9)


def _vector3(values: Any) -> dict[str, float] | None:
    """``{x, y, z}`` of a 3-vector, or None if it is missing or has a null entry."""
    if not isinstance(values, Sequence) or len(values) != 3:
        return None
    if not all(isinstance(v, int | float) and math.isfinite(v) for v in values):
        return None
    return {"x": float(values[0]), "y": float(values[1]), "z": float(values[2])}


def _quaternion(values: Any) -> dict[str, float] | None:
    """Foxglove quaternion of a scalar-first 4-vector, or None if it is not one."""
    if not isinstance(values, Sequence) or len(values) != 4:
        return None
    if not all(isinstance(v, int | float) for v in values):
        return None
    try:
        return foxglove_quaternion(values)
    except ValueError:
        return None


class PathBuffer:
    """The points [m, NED] of the last ``window_s`` seconds of a path.

    ``t`` is the telemetry's monotonic time [s]; a time earlier than the newest point
    (another daemon, a restarted clock) starts a new path."""

    def __init__(self, window_s: float) -> None:
        if not window_s > 0.0:
            raise ValueError(f"path window must be positive, got {window_s!r}")
        self.window_s = window_s
        self._points: deque[tuple[float, dict[str, float]]] = deque()

    def append(self, t: float, point: Mapping[str, float]) -> None:
        """Add ``point`` ``{x, y, z}`` at time ``t`` [s]; forget points older than the window."""
        if self._points and t < self._points[-1][0]:
            self._points.clear()
        self._points.append((t, dict(point)))
        while self._points and self._points[0][0] < t - self.window_s:
            self._points.popleft()

    def clear(self) -> None:
        """Forget every point."""
        self._points.clear()

    def points(self) -> list[dict[str, float]]:
        """The points, oldest first."""
        return [p for _, p in self._points]

    def __len__(self) -> int:
        return len(self._points)


@dataclass
class LiveView:
    """Telemetry messages -> Foxglove channel messages (pure apart from the path buffers).

    path_window_s : length of the drawn paths [s of telemetry time]
    path_period_s : the path scenes are sent at most this often [s] (the poses every
                    message): a scene carries the whole path
    """

    path_window_s: float = 30.0
    path_period_s: float = 0.2

    def __post_init__(self) -> None:
        self.paths = {PATH_ESTIMATE: PathBuffer(self.path_window_s),
                      PATH_REFERENCE: PathBuffer(self.path_window_s)}
        self._last_path_t: float | None = None
        self._last_seq: int | None = None
        self.skipped = 0
        """Messages of another schema version or topic, not converted."""

    def messages_for(self, topic: str, payload: Mapping[str, Any]
                     ) -> list[tuple[str, dict[str, Any]]]:
        """The ``(channel, message)`` pairs for one telemetry message (see
        :data:`CHANNELS`); empty for a topic or schema version this view does not know."""
        if payload.get("schema") != SCHEMA_VERSION or topic not in (TOPIC_STATE, TOPIC_HEALTH):
            self.skipped += 1
            return []
        if topic == TOPIC_HEALTH:
            return [(HEALTH, dict(payload))]
        return self._state_messages(payload)

    def _state_messages(self, payload: Mapping[str, Any]) -> list[tuple[str, dict[str, Any]]]:
        seq = payload.get("seq")
        if isinstance(seq, int):
            if self._last_seq is not None and seq < self._last_seq:  # a new publisher
                for path in self.paths.values():
                    path.clear()
                self._last_path_t = None
            self._last_seq = seq
        stamp = timestamp(payload["time_unix"]) if isinstance(
            payload.get("time_unix"), int | float) else {"sec": 0, "nsec": 0}
        t = payload.get("t")
        out: list[tuple[str, dict[str, Any]]] = []

        supervisor = payload.get("supervisor")
        if isinstance(supervisor, Mapping):
            flight_time = payload.get("flight_time_s", supervisor.get("flight_time_s"))
            message = {
                "state": supervisor.get("state"), "name": supervisor.get("name"),
                "final": bool(payload.get("final", supervisor.get("final", False)))}
            if isinstance(flight_time, int | float):  # else absent (the schema: a number)
                message["flight_time_s"] = flight_time
            out.append((SUPERVISOR, message))
        out.append((STATE, dict(payload)))

        body: tuple[dict[str, float], dict[str, float]] | None = None
        estimate = payload.get("estimate")
        if isinstance(estimate, Mapping):
            position = _vector3(estimate.get("position"))
            orientation = _quaternion(estimate.get("quaternion"))
            if position is not None and orientation is not None:
                out.append((POSE_ESTIMATE, pose_in_frame(stamp, position, orientation)))
                body = (position, orientation)
                if isinstance(t, int | float):
                    self.paths[PATH_ESTIMATE].append(float(t), position)
        out.append((TF, frame_transforms(stamp, body)))

        reference = payload.get("reference")
        if isinstance(reference, Mapping):
            position = _vector3(reference.get("position"))
            yaw = reference.get("yaw")
            if position is not None and isinstance(yaw, int | float) and math.isfinite(yaw):
                out.append((POSE_REFERENCE, pose_in_frame(stamp, position, yaw_quaternion(yaw))))
                if isinstance(t, int | float):
                    self.paths[PATH_REFERENCE].append(float(t), position)

        if isinstance(t, int | float) and (
                self._last_path_t is None or t < self._last_path_t
                or t - self._last_path_t >= self.path_period_s - _PERIOD_SLACK_S):
            for channel, path in self.paths.items():
                if len(path) >= 2:
                    out.append((channel, self._path_scene(channel, stamp, path.points())))
                    self._last_path_t = float(t)
        return out

    @staticmethod
    def _path_scene(channel: str, stamp: dict[str, int],
                    points: list[dict[str, float]]) -> dict[str, Any]:
        """A ``foxglove.SceneUpdate`` with one entity (replaced by the next) holding the path
        as a line strip in :data:`NED_FRAME`."""
        entity_id, color, thickness = _PATH_STYLE[channel]
        return {"deletions": [], "entities": [{
            "timestamp": stamp, "frame_id": NED_FRAME, "id": entity_id,
            "lifetime": {"sec": 0, "nsec": 0}, "frame_locked": False,
            "lines": [{"type": _LINE_STRIP, "thickness": thickness, "scale_invariant": True,
                       "points": points, "color": dict(color)}]}]}


def frame_transforms(stamp: dict[str, int],
                     body: tuple[dict[str, float], dict[str, float]] | None
                     ) -> dict[str, Any]:
    """A ``foxglove.FrameTransforms``: the fixed ``world -> ned`` (so a viewer whose z is up
    draws the flight above its grid) and, given the body's ``(position, orientation)`` in
    :data:`NED_FRAME` (Foxglove ``{x, y, z}`` [m], ``{x, y, z, w}``), ``ned -> base_link``."""
    transforms: list[dict[str, Any]] = [{
        "timestamp": stamp, "parent_frame_id": WORLD_FRAME, "child_frame_id": NED_FRAME,
        "translation": {"x": 0.0, "y": 0.0, "z": 0.0}, "rotation": dict(_WORLD_TO_NED)}]
    if body is not None:
        transforms.append({
            "timestamp": stamp, "parent_frame_id": NED_FRAME, "child_frame_id": BODY_FRAME,
            "translation": dict(body[0]), "rotation": dict(body[1])})
    return {"transforms": transforms}


def pose_in_frame(stamp: dict[str, int], position: dict[str, float],
                   orientation: dict[str, float]) -> dict[str, Any]:
    """A ``foxglove.PoseInFrame`` in :data:`NED_FRAME`."""
    return {"timestamp": stamp, "frame_id": NED_FRAME,
            "pose": {"position": position, "orientation": orientation}}


def sdk_message(schema: str, message: Mapping[str, Any]) -> Any:
    """The foxglove-sdk object for a ``foxglove.*`` message dict of :meth:`LiveView.messages_for`
    (ImportError without the ``foxglove`` extra; KeyError for another schema)."""
    from foxglove import messages as fm

    def stamp(d: Mapping[str, int]) -> Any:
        return fm.Timestamp(int(d["sec"]), int(d["nsec"]))

    def pose(d: Mapping[str, Any]) -> Any:
        return fm.Pose(position=fm.Vector3(**d["position"]),
                       orientation=fm.Quaternion(**d["orientation"]))

    def line(d: Mapping[str, Any]) -> Any:
        if d["type"] != _LINE_STRIP:
            raise ValueError(f"line type {d['type']!r}: only line strips are built")
        return fm.LinePrimitive(
            type=fm.LinePrimitiveLineType.LineStrip, thickness=float(d["thickness"]),
            scale_invariant=bool(d["scale_invariant"]),
            points=[fm.Point3(**p) for p in d["points"]], color=fm.Color(**d["color"]))

    def entity(d: Mapping[str, Any]) -> Any:
        return fm.SceneEntity(
            timestamp=stamp(d["timestamp"]), frame_id=d["frame_id"], id=d["id"],
            lifetime=fm.Duration(int(d["lifetime"]["sec"]), int(d["lifetime"]["nsec"])),
            frame_locked=bool(d["frame_locked"]), lines=[line(x) for x in d["lines"]])

    def transform(d: Mapping[str, Any]) -> Any:
        return fm.FrameTransform(
            timestamp=stamp(d["timestamp"]), parent_frame_id=d["parent_frame_id"],
            child_frame_id=d["child_frame_id"], translation=fm.Vector3(**d["translation"]),
            rotation=fm.Quaternion(**d["rotation"]))

    builders: dict[str, Callable[[Mapping[str, Any]], Any]] = {
        "foxglove.PoseInFrame": lambda d: fm.PoseInFrame(
            timestamp=stamp(d["timestamp"]), frame_id=d["frame_id"], pose=pose(d["pose"])),
        "foxglove.FrameTransforms": lambda d: fm.FrameTransforms(
            transforms=[transform(x) for x in d["transforms"]]),
        "foxglove.SceneUpdate": lambda d: fm.SceneUpdate(
            deletions=[], entities=[entity(x) for x in d["entities"]]),
    }
    return builders[schema](message)


def _open_channels(foxglove: Any, context: Any) -> dict[str, Any]:
    """The SDK channels of :data:`CHANNELS` in ``context``."""
    from foxglove import channels as fc

    typed = {"foxglove.PoseInFrame": fc.PoseInFrameChannel,
             "foxglove.FrameTransforms": fc.FrameTransformsChannel,
             "foxglove.SceneUpdate": fc.SceneUpdateChannel}
    out: dict[str, Any] = {}
    for topic, schema in CHANNELS.items():
        if schema in typed:
            out[topic] = typed[schema](topic, context=context)
        else:
            out[topic] = foxglove.Channel(topic, schema=JSON_SCHEMAS[topic], context=context)
    return out


@contextmanager
def _until_stopped() -> Iterator[threading.Event]:
    """An event SIGINT or SIGTERM sets (in the main thread; elsewhere never), so the loop
    ends between receives and the server stops cleanly."""
    stop = threading.Event()
    if threading.current_thread() is not threading.main_thread():
        yield stop
        return
    handlers = {sig: signal.signal(sig, lambda _s, _f: stop.set())
                for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield stop
    finally:
        for sig, previous in handlers.items():
            signal.signal(sig, previous)


def run_foxglove(
    endpoint: str, *, host: str = "127.0.0.1", port: int = 8765,
    duration: float | None = None, echo: Callable[[str], None] = print,
    view: LiveView | None = None, stop: threading.Event | None = None,
) -> int:
    """Serve the telemetry of ``endpoint`` on ``ws://host:port`` until ``duration`` [s]
    passes, ``stop`` is set, or SIGINT/SIGTERM (None: until interrupted); return the
    number of telemetry messages received.

    The SDK's server listens on loopback (a free port); viewers connect to the relay on
    ``host:port`` with either subprotocol name. ``port`` 0 picks a free port; the first
    line ``echo`` gets names the URL actually served (``foxglove: serving ws://HOST:PORT
    ...``). Raises TelemetryError if the ``foxglove`` extra is missing
    (:data:`MISSING_EXTRA`), the port cannot be bound, or the endpoint is invalid."""
    try:
        import foxglove
    except ImportError as exc:
        raise TelemetryError(MISSING_EXTRA) from exc
    from groundstation.telemetry.ws_relay import SubprotocolRelay

    view = LiveView() if view is None else view
    context = foxglove.Context()
    channels = _open_channels(foxglove, context)
    try:
        server = foxglove.start_server(name="groundstation", host="127.0.0.1", port=0,
                                       context=context)
    except RuntimeError as exc:  # the SDK's FoxgloveError
        for channel in channels.values():
            channel.close()
        raise TelemetryError(f"foxglove: cannot start the server: {exc}") from exc
    relay = SubprotocolRelay(f"ws://127.0.0.1:{server.port}", host, port)
    try:
        relay.start()
    except TelemetryError:
        server.stop()
        for channel in channels.values():
            channel.close()
        raise
    received, warned = 0, False
    try:
        with TelemetrySubscriber(endpoint) as client, _until_stopped() as signalled:
            echo(f"foxglove: serving ws://{host}:{relay.port} (telemetry {endpoint}); "
                 f"open it in Foxglove or Lichtblick")
            end = None if duration is None else time.monotonic() + duration
            while not signalled.is_set() and not (stop is not None and stop.is_set()):
                left = 0.2 if end is None else min(0.2, end - time.monotonic())
                if left <= 0:
                    break
                message = client.receive(left)
                if message is None:
                    continue
                received += 1
                topic, payload = message
                time_unix = payload.get("time_unix")
                log_time = log_time_ns(time_unix) if isinstance(
                    time_unix, int | float) else None
                converted = view.messages_for(topic, payload)
                if not converted and payload.get("schema") != SCHEMA_VERSION and not warned:
                    warned = True
                    echo(f"foxglove: telemetry schema {payload.get('schema')!r}, this view "
                         f"reads schema {SCHEMA_VERSION}: such messages are skipped")
                for name, body in converted:
                    channel = channels[name]
                    schema = CHANNELS[name]
                    if schema.startswith("foxglove."):
                        channel.log(sdk_message(schema, body), log_time=log_time)
                    else:
                        channel.log(body, log_time=log_time)
    finally:
        relay.stop()
        server.stop()
        for channel in channels.values():
            channel.close()
    return received
