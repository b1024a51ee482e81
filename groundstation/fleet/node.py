"""The daemon's side of the fleet: what it publishes, what it answers, what it watches.

One :class:`FleetNode` per daemon with a ``fleet:`` section (``app/daemon.py`` opens it
with the flight's parameters: :attr:`~groundstation.flight.params.FlightParams.fleet`):

* **Publishes** under ``<fleet>/<vehicle>/`` (:mod:`.keys`): ``state`` and ``health``
  (today's telemetry payloads, ``telemetry/schema.py``, with the same envelope; health
  gets a ``fleet`` section) and ``reference`` at ``telemetry.rate_hz``; ``pose``
  (:class:`~.messages.PeerPose`) at ``fleet.pose_rate_hz`` for the peers' separation
  checks; ``intent`` (:class:`~.messages.Intent`: the path of the motion in force) when a
  motion is accepted and once a second. The flight's last ``state`` carries ``final``,
  its outcome and reason, as on pyzmq. Publishing never blocks the loop: Zenoh drops a
  sample it cannot queue (counted as nothing lost to the flight).
* **Answers** ``<fleet>/<vehicle>/cmd/<request>`` (status, go_to, takeoff, follow, hold,
  land, channels): the query's payload is the request's fields as one JSON object (at
  most :data:`MAX_REQUEST_BYTES`), answered by the daemon's own
  :meth:`~groundstation.app.daemon.FlightDaemon.handle_request`, the request socket's
  handler: the same checks, refusals and replies. Requests are answered one at a time
  in a thread of their own, never in the loop.
* **Watches** the peers (:class:`~.peers.PeerTable`): each tick the distance to the
  nearest one goes to the supervisor with the input health (``InputHealth.peer_*``);
  each motion is checked against the peers before it is flown (:meth:`check`, the run-
  time API's guard, :mod:`.separation`).
"""

from __future__ import annotations

import json
import math
import queue
import threading
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import replace
from typing import TYPE_CHECKING, Any

import numpy as np
import structlog

from groundstation.errors import FleetError
from groundstation.fleet import keys
from groundstation.fleet.messages import MAX_INTENT_POINTS, Intent, PeerPose
from groundstation.fleet.peers import PeerTable
from groundstation.fleet.posesource import ZenohPoseSource
from groundstation.fleet.separation import check_path, nearest, sample_path
from groundstation.fleet.session import Membership, open_session
from groundstation.flight.commander import CommandRefusedError, Planned, sample_plan, splice
from groundstation.flight.inputs import InputHealth
from groundstation.flight.params import FlightParams
from groundstation.model.quaternion import rotate
from groundstation.telemetry.requests import MAX_PARSED_BYTES
from groundstation.telemetry.schema import SCHEMA_VERSION, jsonable
from groundstation.timing import TimingHistogram
from groundstation.types import FloatArray, Pose, StateEstimate

if TYPE_CHECKING:
    import zenoh

    from groundstation.flight.core import TickResult

log = structlog.get_logger(__name__)

MAX_REQUEST_BYTES = MAX_PARSED_BYTES
"""Largest request payload parsed [bytes]: the request socket's."""

QUEUED_REQUESTS = 16
"""Requests waiting for the serving thread; more are answered ``busy`` at once."""

INTENT_PERIOD_S = 1.0
"""How often the intent is published again [s] (a peer that starts late hears it)."""

INTENT_KEEP_S = 0.5
"""A point of the path stays in the intent this long after its planned time [s]."""

Handler = Callable[[dict[str, Any]], dict[str, Any]]


def parse_request(request: str, payload: bytes | None) -> dict[str, Any]:
    """The request ``{"request": request, **fields}`` from a query's payload (the fields
    as one JSON object; none: no fields). ValueError naming what is wrong otherwise."""
    if request not in keys.REQUESTS:
        raise ValueError(f"unknown request {request[:40]!r} (known: {', '.join(keys.REQUESTS)})")
    if not payload:
        return {"request": request}
    if len(payload) > MAX_REQUEST_BYTES:
        raise ValueError(f"{len(payload)} bytes, a request is at most {MAX_REQUEST_BYTES}")
    try:
        fields = json.loads(payload.decode("utf-8"))
    except (UnicodeDecodeError, ValueError, RecursionError) as exc:
        raise ValueError(f"not one UTF-8 JSON object: {str(exc)[:80]}") from None
    if not isinstance(fields, dict):
        raise ValueError("the request's fields must be one JSON object")
    if fields.get("request", request) != request:
        raise ValueError(f"sent to {request!r} but says {str(fields['request'])[:40]!r}")
    return {**fields, "request": request}


def _refusal(reason: str, kind: str) -> bytes:
    return json.dumps({"ok": False, "error": reason[:400], "kind": kind}).encode()


class FleetNode:
    """One daemon in the fleet (see the module docstring). Build with :meth:`open`."""

    def __init__(self, session: zenoh.Session, params: FlightParams, *,
                 clock: Callable[[], float] = time.monotonic,
                 owns_session: bool = True) -> None:
        if params.fleet is None:
            raise FleetError("a fleet node needs the fleet: section")
        self.params = params
        self.fleet = params.fleet
        self._session = session
        self._owns = owns_session
        self._clock = clock
        f, v = self.fleet.name, self.fleet.vehicle
        self.peers = PeerTable(self.fleet.peers, clock).subscribe(session, f)
        self._publishers = {topic: session.declare_publisher(keys.vehicle_key(f, v, topic))
                            for topic in keys.TOPICS}
        self._pose_period = 1.0 / self.fleet.pose_rate_hz
        self._telemetry_period = 1.0 / params.telemetry.rate_hz
        self._next_pose = self._next_telemetry = self._next_intent = -math.inf
        self._seq = 0
        self._pose_seq = 0
        self._intent_seq = 0
        self._own: FloatArray | None = None
        self._intent: tuple[FloatArray, FloatArray, float] | None = None  # points, times, step
        self._intent_lock = threading.Lock()
        self._pending: dict[int, tuple[FloatArray, FloatArray, float]] = {}
        self.fuse = TimingHistogram()
        """Vicon pose received (the relay's stamp, or the socket's) to fused [s]."""
        self._source: ZenohPoseSource | None = None
        self._counts = {"answered": 0, "malformed": 0, "busy": 0, "publish_errors": 0,
                        "refused_separation": 0, "refused_silent": 0}
        self._queryables: list[Any] = []

    @classmethod
    def open(cls, params: FlightParams) -> FleetNode:
        """Open the session of ``params.fleet`` and the node on it. FleetError if it cannot
        be opened."""
        fleet = params.fleet
        if fleet is None:
            raise FleetError("a fleet node needs the fleet: section")
        membership = Membership(fleet.name, (fleet.vehicle, *fleet.peers),
                                operators=fleet.zenoh.operators)
        session = open_session(fleet.zenoh, membership)
        try:
            return cls(session, params)
        except BaseException:
            session.close()  # type: ignore[no-untyped-call]  # zenoh's stub: unannotated
            raise

    def close(self) -> None:
        """Undeclare everything and close the session (idempotent)."""
        self.peers.close()
        for queryable in self._queryables:
            queryable.undeclare()
        self._queryables = []
        if self._owns and not self._session.is_closed():
            self._session.close()  # type: ignore[no-untyped-call]  # zenoh's stub: unannotated

    def __enter__(self) -> FleetNode:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    # ------------------------------------------------------------------ Vicon
    def pose_source(self) -> ZenohPoseSource:
        """This vehicle's Vicon poses from the relay (``vicon.source: zenoh``), not started."""
        self._source = ZenohPoseSource.for_fleet(self._session, self.fleet.name,
                                                 self.params.vicon)
        return self._source

    # ------------------------------------------------------------------ each tick
    def with_peers(self, health: InputHealth, now: float,
                   estimate: StateEstimate | None) -> InputHealth:
        """``health`` with the distance to the nearest peer (inf without one) from this
        vehicle's estimate, for the supervisor's separation rule."""
        if estimate is None:
            return health
        try:
            distance, name = nearest(estimate.position, self.peers.views(now),
                                     self.fleet.peer_timeout_s)
        except Exception:  # a fault of ours: no peer this tick, logged once; never the loop
            self._failed("the peers could not be read")
            return health
        return replace(health, peer_distance_m=distance, peer_name=name)

    def after_tick(self, t: float, result: TickResult, poses: Sequence[Pose],
                   snapshot: Callable[[], Mapping[str, Mapping[str, Any]]]) -> None:
        """After the loop's tick at ``t`` (monotonic [s]): note the poses it fused and the
        estimate, publish what is due. Never raises (a failure is counted and logged once)."""
        try:
            latency = self.params.vicon.filter.latency_s
            for pose in poses:
                self.fuse.add(t - (pose.t + latency))
            estimate = result.estimate
            self._own = None if estimate is None else estimate.position.copy()
            if t >= self._next_pose:
                self._next_pose = max(self._next_pose + self._pose_period, t)
                self._publish_pose(int(result.state), estimate)
            if t >= self._next_telemetry:
                self._next_telemetry = max(self._next_telemetry + self._telemetry_period, t)
                self._publish_telemetry(t, snapshot(), result)
            if t >= self._next_intent:
                self._next_intent = t + INTENT_PERIOD_S
                self._publish_intent()
        except Exception:  # telemetry never stops a flight
            self._failed("fleet publication failed")

    def publish_end(self, snapshot: Mapping[str, Mapping[str, Any]], state: int) -> None:
        """The flight's last ``state`` (``final``) and ``health``, and its pose in its
        terminal ``state`` (peers then keep it as an obstacle, not a silent peer)."""
        import zenoh

        try:
            t = self._clock()
            self._publish_pose(state, None, position=self._own)
            for topic, body in snapshot.items():
                self._put(topic, self._envelope(topic, t, body),
                          congestion=zenoh.CongestionControl.BLOCK)
        except Exception:
            self._failed("final fleet telemetry not published")

    def stats(self) -> dict[str, Any]:
        """Counters and figures for the ``health`` payload's ``fleet`` section."""
        views = self.peers.views()
        out: dict[str, Any] = {
            **self._counts, "peers": {p.name: {"age_s": p.age_s, "ended": p.ended}
                                      for p in views},
            "fuse_p50_s": self.fuse.percentile(50.0), "fuse_p99_s": self.fuse.percentile(99.0),
            "fused": self.fuse.n}
        if self._source is not None:
            out.update(relay_hop_p50_s=self._source.hop.percentile(50.0),
                       relay_hop_p99_s=self._source.hop.percentile(99.0),
                       relay_malformed=self._source.malformed)
        return out

    # ------------------------------------------------------------------ publishing
    def _publish_pose(self, state: int, estimate: StateEstimate | None,
                      position: FloatArray | None = None) -> None:
        nan3 = (math.nan, math.nan, math.nan)
        self._pose_seq += 1
        if estimate is not None:
            p = estimate.position
            q = estimate.quaternion
            v = rotate(q, estimate.velocity_body)
            message = PeerPose(state, self._pose_seq, (float(p[0]), float(p[1]), float(p[2])),
                               (float(q[0]), float(q[1]), float(q[2]), float(q[3])),
                               (float(v[0]), float(v[1]), float(v[2])))
        else:
            where = nan3 if position is None else (float(position[0]), float(position[1]),
                                                   float(position[2]))
            message = PeerPose(state, self._pose_seq, where, (1.0, 0.0, 0.0, 0.0), nan3)
        self._put("pose", message.pack())

    def _envelope(self, topic: str, t: float, body: Mapping[str, Any]) -> bytes:
        self._seq += 1
        payload: dict[str, Any] = {"schema": SCHEMA_VERSION, "topic": topic, "seq": self._seq,
                                   "t": t, "time_unix": time.time(), **body}
        if topic == "health":
            payload["fleet"] = self.stats()
        return json.dumps(jsonable(payload), separators=(",", ":"), allow_nan=False).encode()

    def _publish_telemetry(self, t: float, snapshot: Mapping[str, Mapping[str, Any]],
                           result: TickResult) -> None:
        for topic, body in snapshot.items():
            if topic in self._publishers:
                self._put(topic, self._envelope(topic, t, body))
        ref = result.reference
        self._put("reference", self._envelope("reference", t, {
            "state": result.state.name, "position": ref.position, "velocity": ref.velocity,
            "acceleration": ref.acceleration, "yaw": ref.yaw}))

    def _publish_intent(self) -> None:
        with self._intent_lock:
            intent = self._intent
        if intent is None:
            return
        points, times, step = intent
        keep = points[times >= self._clock() - INTENT_KEEP_S]
        self._intent_seq += 1
        self._put("intent", Intent(self._intent_seq, step, keep[-MAX_INTENT_POINTS:]).pack())

    def _put(self, topic: str, payload: bytes, congestion: Any = None) -> None:
        try:
            if congestion is None:
                self._publishers[topic].put(payload)
            else:
                self._session.put(keys.vehicle_key(self.fleet.name, self.fleet.vehicle, topic),
                                  payload, congestion_control=congestion)
        except Exception:
            self._failed(f"fleet {topic} not published")

    def _failed(self, what: str) -> None:
        self._counts["publish_errors"] += 1
        if self._counts["publish_errors"] == 1:
            log.warning(what, exc_info=True)

    # ------------------------------------------------------------------ the API's guard
    def check(self, planned: Planned) -> None:
        """Refuse ``planned`` if it breaks the separation from a peer (``separation``), or
        if a peer is silent (``state``: not now); else keep its path for :meth:`installed`.
        Without ``fleet.separation_m`` every motion passes. Runs in a request's thread."""
        separation = self.fleet.separation_m
        if separation is None:
            return
        base = planned.base
        plan = splice(base.plan, planned.pieces)
        end = max(planned.motion.end, base.start)
        path, step = sample_path(lambda tau: sample_plan(plan, tau).position, base.start, end)
        own = self._own if self._own is not None else path[0]
        verdict = check_path(path, step, own, self.peers.views(), separation,
                             self.fleet.peer_timeout_s)
        if verdict.verdict == "silent":
            self._counts["refused_silent"] += 1
            raise CommandRefusedError("state", verdict.reason)
        if verdict.verdict == "separation":
            self._counts["refused_separation"] += 1
            raise CommandRefusedError("separation", verdict.reason)
        now = self._clock()
        times = now + np.linspace(base.start, end, len(path)) - base.now
        self._pending[id(planned)] = (path, times, step)

    def installed(self, planned: Planned) -> None:
        """``planned`` flies: its path is this vehicle's intent from now (published at
        once). Runs in a request's thread."""
        entry = self._pending.pop(id(planned), None)
        self._pending.clear()
        if entry is None:
            return
        with self._intent_lock:
            self._intent = entry
        self._publish_intent()

    # ------------------------------------------------------------------ requests
    @contextmanager
    def serving(self, handler: Handler) -> Iterator[None]:
        """Answer the requests' queries with ``handler`` in a thread of its own while the
        block runs."""
        waiting: queue.Queue[tuple[str, Any]] = queue.Queue(QUEUED_REQUESTS)
        stop = threading.Event()
        f, v = self.fleet.name, self.fleet.vehicle

        def enqueue(request: str) -> Callable[[Any], None]:
            def on_query(query: Any) -> None:
                try:
                    waiting.put_nowait((request, query))
                except queue.Full:
                    self._counts["busy"] += 1
                    query.reply(keys.request_key(f, v, request), _refusal(
                        "the vehicle has too many requests waiting: try again", "busy"))
            return on_query

        self._queryables = [self._session.declare_queryable(keys.request_key(f, v, r),
                                                            enqueue(r))
                            for r in keys.REQUESTS]
        worker = threading.Thread(target=self._serve, args=(waiting, stop, handler),
                                  name="gs-fleet-requests", daemon=True)
        worker.start()
        try:
            yield
        finally:
            for queryable in self._queryables:
                queryable.undeclare()
            self._queryables = []
            stop.set()
            worker.join(5.0)

    def _serve(self, waiting: queue.Queue[tuple[str, Any]], stop: threading.Event,
               handler: Handler) -> None:
        while not stop.is_set():
            try:
                request, query = waiting.get(timeout=0.05)
            except queue.Empty:
                continue
            try:
                payload = query.payload.to_bytes() if query.payload is not None else None
                try:
                    body = parse_request(request, payload)
                except ValueError as exc:
                    self._counts["malformed"] += 1
                    reply = _refusal(f"malformed request: {exc}", "request")
                else:
                    reply = json.dumps(jsonable(handler(body))).encode()
                # on its own key: a query for every vehicle (*) gets one reply from each
                query.reply(keys.request_key(self.fleet.name, self.fleet.vehicle, request),
                            reply)
                self._counts["answered"] += 1
            except Exception:  # a fault of ours: the client times out, the flight goes on
                log.exception("fleet request failed", request=request)
            finally:
                del query  # the reply is final once the query is dropped
