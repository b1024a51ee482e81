"""The run-time API's requests: what a client (:mod:`groundstation.client`, ``gs goto``)
may ask of a flying daemon, and how each is checked and answered.

Requests are JSON objects on the request socket (:mod:`groundstation.telemetry.requests`);
each reply is ``{"ok": true, ...}`` or ``{"ok": false, "error": why, "kind": kind}``, every
refusal with one of the kinds of :class:`~groundstation.flight.commander.CommandRefusedError`:
``request``, ``state``, ``volume``, ``infeasible``, ``busy``, ``internal`` (and in a fleet
``separation``, :class:`MotionGuard`). Frames as
everywhere: NED earth [m], headings [rad] from north, times [s].

==============  ===========================================================  ==========
request         fields                                                       flight
==============  ===========================================================  ==========
``status``      none                                                         any
``go_to``       ``position`` [3], ``yaw`` (null: keep), ``duration`` (null:  commanded
                sized from ``api.speed_m_s`` and the limits)
``takeoff``     ``height`` above the take-off point [m]: a vertical go_to    commanded
``follow``      ``trajectory`` (a ``trajectory:`` section: name, center,     commanded
                size_m, period_s, ...) or ``waypoints`` ([[t, x, y, z(,
                yaw)], ...]); ``duration`` (null: one lap / the path);
                ``start_at`` (unix time [s]; null: once at its start)
``hold``        none: stop as soon as the limits allow, and stay             commanded
``land``        none: land now (a nominal end)                               any
``channels``    ``auto`` (see ``gs channels``)                               any
==============  ===========================================================  ==========

A commanded flight is one with ``trajectory.name: none`` (``gs fly --trajectory none``);
a flight with a configured trajectory answers status, land and channels and refuses
motions. Motions are accepted only in TRACK: before take-off is complete, while a
failsafe acts and after landing began they are refused with kind ``state``.

Every number is checked at the boundary (:mod:`groundstation.flight.boundary`) before any
arithmetic; every motion lasts at most :data:`~groundstation.flight.commander.MAX_MOTION_S`
however its length arises, checked before it is sampled.

Threads: :meth:`MotionApi.handle` runs where the request arrived (the request socket's
thread in the daemon). Everything that reads or changes the flight goes through
``in_loop``, which runs a function in the flight loop between two ticks and returns its
result. Planning, the expensive part, goes to the ``planner``: in the daemon a process of
its own (:mod:`groundstation.app.planner_process`), which must answer within
``api.plan_timeout_s``; the loop never waits for it.
"""

from __future__ import annotations

import queue
import threading
import time
from collections.abc import Callable, Mapping
from concurrent.futures import Future
from concurrent.futures import TimeoutError as FutureTimeout
from functools import partial
from typing import Any, ClassVar, Protocol, TypeVar

import structlog

from groundstation.control.base import heading_of
from groundstation.flight import boundary
from groundstation.flight.assembly import trajectory_spec
from groundstation.flight.commander import (
    PLAN_LEAD_S,
    Commander,
    CommandRefusedError,
    Motion,
    PlanBase,
    Planned,
)
from groundstation.flight.core import FlightCore
from groundstation.flight.params import FlightParams
from groundstation.flight.planner import (
    Follow,
    Followable,
    GoTo,
    Hold,
    InlinePlanner,
    MotionSpec,
    Planner,
    PrepareFollow,
    TakeOff,
    plan_with,
)
from groundstation.flight.supervisor import State
from groundstation.model.quaternion import rotate
from groundstation.types import CHANNELS

log = structlog.get_logger(__name__)

T = TypeVar("T")


class InLoop(Protocol):
    """Runs ``fn`` in the flight loop between two ticks and returns its result."""

    def __call__(self, fn: Callable[[], T], /) -> T: ...

Reply = dict[str, Any]


class MotionGuard(Protocol):
    """What checks a planned motion against what the flight loop does not see: the
    fleet's peers (:class:`groundstation.fleet.node.FleetNode`). Both run in the
    request's thread."""

    def check(self, planned: Planned, /) -> None:
        """Raise CommandRefusedError to refuse ``planned`` (before it is installed)."""

    def installed(self, planned: Planned, /) -> None:
        """``planned`` was installed and flies."""


INSTALL_ATTEMPTS = 3
"""Plans of one request (each with at least twice the lead of the last, and half as much
again as the last attempt took) before it is refused busy."""


IN_LOOP_TIMEOUT_S = 1.0
"""Longest wait for the flight loop to run a request's part [s]; it runs one within a
tick (10 ms) unless the loop has stopped."""

RUN_PER_TICK = 4
"""Most requests' parts the loop runs between two ticks (each well under a millisecond)."""


def _in_place(fn: Callable[[], T]) -> T:
    return fn()


class LoopInbox:
    """Hands functions from other threads to the flight loop and waits for their results.

    While the loop runs (:meth:`open` until :meth:`close`), :meth:`call` queues a function
    and the loop runs up to :data:`RUN_PER_TICK` of them between two ticks
    (:meth:`run_pending`); before and after, nothing else touches the flight, and
    :meth:`call` runs the function at once in the caller's thread.
    """

    def __init__(self, timeout_s: float = IN_LOOP_TIMEOUT_S) -> None:
        self._queue: queue.SimpleQueue[tuple[Callable[[], Any], Future[Any]]] = \
            queue.SimpleQueue()
        self._lock = threading.Lock()
        self._open = False
        self._timeout = timeout_s

    def open(self) -> None:
        """The loop starts: from now on functions run in it."""
        with self._lock:
            self._open = True

    def close(self) -> None:
        """The loop has stopped: run what is queued here, and anything later at once."""
        with self._lock:
            self._open = False
        self.run_pending(limit=None)

    def call(self, fn: Callable[[], T]) -> T:
        """``fn()``, run by the loop; its exception is raised here. CommandRefusedError
        ('state') if the loop does not run it within the timeout."""
        future: Future[T] = Future()
        with self._lock:
            queued = self._open
            if queued:
                self._queue.put((fn, future))
        if not queued:
            return fn()
        try:
            return future.result(self._timeout)
        except FutureTimeout:
            future.cancel()
            raise CommandRefusedError("state", f"the flight loop did not take the request "
                                      f"within {self._timeout:g} s") from None

    def run_pending(self, limit: int | None = RUN_PER_TICK) -> None:
        """Run up to ``limit`` queued functions (None: all) and hand over their results."""
        done = 0
        while limit is None or done < limit:
            try:
                fn, future = self._queue.get_nowait()
            except queue.Empty:
                return
            done += 1
            if not future.set_running_or_notify_cancel():
                continue  # its caller stopped waiting
            try:
                future.set_result(fn())
            except Exception as exc:  # the caller's to raise, never the loop's
                future.set_exception(exc)


class MotionApi:
    """Answers API requests for ``core``'s flight, flown with ``params``.

    in_loop : runs a function in the flight loop and returns its result (the daemon's
        queue to its loop; by default in the caller's thread, for a core nobody else steps)
    planner : plans motions (the daemon's planner process; by default in the caller's
        thread, :class:`~groundstation.flight.planner.InlinePlanner`)
    health : the daemon's input health for status replies (a JSON-able mapping)
    clock, wall_clock : monotonic and unix time [s]
    """

    def __init__(self, core: FlightCore, params: FlightParams, *,
                 in_loop: InLoop = _in_place, planner: Planner | None = None,
                 health: Callable[[], Mapping[str, Any]] = dict,
                 clock: Callable[[], float] = time.monotonic,
                 wall_clock: Callable[[], float] = time.time) -> None:
        self.core = core
        self.params = params
        self._in_loop = in_loop
        settings = params.planner
        self._planner: Planner = planner if planner is not None else InlinePlanner(settings)
        self._volume = settings.limits.volume
        self._max_yaw_rate = settings.limits.flight.max_yaw_rate_rad_s
        self._min_step = params.command_period_s
        self._plan_timeout = params.daemon.plan_timeout_s
        self._start_horizon = params.daemon.start_horizon_s
        self._health = health
        self._clock = clock
        self._wall = wall_clock
        self.guard: MotionGuard | None = None
        """Set by a fleet's daemon before it serves requests (groundstation/fleet)."""

    def handle(self, request: Mapping[str, Any]) -> Reply:
        """The reply to one request; never raises. A refusal has its kind; a failure of
        ours is answered ``internal`` (and logged with its traceback)."""
        kind = request.get("request")
        handler = self._HANDLERS.get(kind) if isinstance(kind, str) else None
        if handler is None:
            return _refusal(CommandRefusedError(
                "request", f"unknown request {str(kind)[:40]!r} "
                f"(known: {', '.join(sorted(self._HANDLERS))})"))
        try:
            return handler(self, request)
        except CommandRefusedError as exc:
            log.info("request refused", request=kind, kind=exc.kind, reason=exc.reason)
            return _refusal(exc)
        except Exception as exc:  # a fault of ours: the client hears of it, the flight goes on
            log.exception("request failed", request=kind)
            return _refusal(CommandRefusedError(
                "internal", f"internal error: {type(exc).__name__}: {exc}"))

    # ------------------------------------------------------------------ requests
    def _status(self, request: Mapping[str, Any]) -> Reply:
        _only(request)
        return self._in_loop(self.status)

    def _go_to(self, request: Mapping[str, Any]) -> Reply:
        _only(request, "position", "yaw", "duration")
        position = boundary.position(request.get("position"), self._volume)
        yaw = boundary.heading(request.get("yaw"))
        duration = boundary.duration(request.get("duration"))
        return self._motion(lambda base: GoTo(position, yaw, duration))

    def _takeoff(self, request: Mapping[str, Any]) -> Reply:
        _only(request, "height")
        height = boundary.height(request.get("height"), self._volume)
        return self._motion(lambda base: TakeOff(height))

    def _follow(self, request: Mapping[str, Any]) -> Reply:
        _only(request, "trajectory", "waypoints", "duration", "start_at")
        received_wall, received = self._wall(), self._clock()
        deadline = time.monotonic() + self._plan_timeout
        duration = boundary.duration(request.get("duration"))
        start_at = boundary.start_at(request.get("start_at"), received_wall,
                                     self._start_horizon)
        start_in = 0.0 if start_at is None else start_at - received_wall
        given = [k for k in ("trajectory", "waypoints") if request.get(k) is not None]
        if len(given) != 1:
            raise CommandRefusedError("request", "follow needs one of 'trajectory' (a "
                                      "trajectory section) or 'waypoints' ([[t, x, y, z], ...])")
        if given[0] == "waypoints":
            job = PrepareFollow(None, boundary.waypoint_rows(
                request["waypoints"], self._volume, self._min_step), duration, start_in)
        else:
            section = boundary.trajectory_section(request["trajectory"], self._volume,
                                                  self._max_yaw_rate)
            job = PrepareFollow(trajectory_spec(section), None, duration, start_in)
        self._in_loop(self._tracking)  # before the expensive part, as every motion
        followable: Followable = self._planner.run(job, deadline)

        def spec(base: PlanBase) -> MotionSpec:
            start = None
            if start_at is not None:  # unix time -> trajectory time (both advance in TRACK)
                start = base.now + start_in - (self._clock() - received)
            return Follow(followable, start)
        return self._motion(spec, received, deadline)

    def _hold(self, request: Mapping[str, Any]) -> Reply:
        _only(request)
        return self._motion(lambda base: Hold())

    def _land(self, request: Mapping[str, Any]) -> Reply:
        _only(request)

        def land() -> Reply:
            state = self.core.state
            if state not in (State.PREFLIGHT, State.TAKEOFF, State.TRACK):
                raise CommandRefusedError("state", f"cannot land in {state.name}: "
                                          + _state_reason(self.core))
            if state is State.PREFLIGHT:
                raise CommandRefusedError("state", "not flying yet (PREFLIGHT): stop the "
                                          "daemon instead (Ctrl-C, systemctl stop)")
            self.core.request_land("land requested by a client")
            log.info("land requested by a client", state=state.name)
            return {"ok": True, "state": state.name}
        return self._in_loop(land)

    def _channels(self, request: Mapping[str, Any]) -> Reply:
        _only(request, "auto")

        def channels() -> Reply:
            core = self.core
            if "auto" in request:
                auto = request["auto"]
                if not isinstance(auto, list) or not auto or \
                        any(c not in CHANNELS for c in auto) or len(set(auto)) != len(auto):
                    raise CommandRefusedError(
                        "request", f"'auto' must list one or more of {list(CHANNELS)} once "
                        f"each, got {str(auto)[:80]}")
                core.set_auto_channels(auto)
                log.info("channels", auto=auto, state=core.state.name)
            auto_now = core.auto_channels
            return {"ok": True, "auto": [c for c in CHANNELS if c in auto_now],
                    "state": core.state.name}
        return self._in_loop(channels)

    _HANDLERS: ClassVar[dict[str, Callable[[MotionApi, Mapping[str, Any]], Reply]]] = {
        "status": _status, "go_to": _go_to, "takeoff": _takeoff, "follow": _follow,
        "hold": _hold, "land": _land, "channels": _channels,
    }

    # ------------------------------------------------------------------ motions
    def _motion(self, spec: Callable[[PlanBase], MotionSpec], received: float | None = None,
                deadline: float | None = None) -> Reply:
        """Plan ``spec`` from the loop's state (in the planner, by ``deadline``: monotonic
        [s], default ``api.plan_timeout_s`` from now), install it in the loop; again with a
        longer lead if the loop moved past the start meanwhile. ``received``: when the
        request arrived (``clock`` [s], default now)."""
        if received is None:
            received = self._clock()
        if deadline is None:
            deadline = time.monotonic() + self._plan_timeout
        lead = PLAN_LEAD_S
        for _attempt in range(INSTALL_ATTEMPTS):
            began = time.monotonic()
            base = self._in_loop(partial(self._base, lead))
            planned = plan_with(self._planner, spec(base), base, deadline)
            planned.motion.received = received
            if self.guard is not None:  # a fleet: the peers' separation
                self.guard.check(planned)
            try:
                motion = self._in_loop(partial(self._install, planned))
            except CommandRefusedError as exc:
                if exc.kind != "busy":
                    raise
                lead = max(2.0 * lead, 1.5 * (time.monotonic() - began))
                continue
            if self.guard is not None:
                self.guard.installed(planned)
            log.info("motion accepted", id=motion.id, kind=motion.kind,
                     target=[round(float(v), 3) for v in motion.target],
                     duration_s=round(motion.end - motion.start, 2))
            return {"ok": True, "motion": motion.report(), "state": State.TRACK.name}
        raise CommandRefusedError("busy", "the flight changed its plan while this motion was "
                                  f"planned, {INSTALL_ATTEMPTS} times: try again")

    def _commander(self) -> Commander:
        commander = self.core.commander
        if commander is None:
            raise CommandRefusedError(
                "state", f"this flight flies its configured trajectory "
                f"({self.params.trajectory.name}); motions need `gs fly --trajectory none`")
        return commander

    def _tracking(self) -> Commander:
        """In the loop: the commander, or a refusal unless tracking."""
        commander = self._commander()
        state = self.core.state
        if state is not State.TRACK:
            if state in (State.PREFLIGHT, State.TAKEOFF):
                reason = f"not airborne yet ({state.name}): wait for TRACK"
            else:
                reason = f"{state.name}: {_state_reason(self.core)}"
            raise CommandRefusedError("state", reason)
        return commander

    def _base(self, lead: float) -> PlanBase:
        """In the loop: what to plan from, or a refusal unless tracking."""
        commander = self._tracking()
        state = self.core.state
        mission = self.core.mission
        return commander.base(mission.trajectory_time, mission.heading_offset, state.name,
                              mission.ground, lead)

    def _install(self, planned: Planned) -> Motion:
        """In the loop: fly it, if the flight is still tracking."""
        commander = self._commander()
        if self.core.state is not State.TRACK:
            raise CommandRefusedError("state", f"{self.core.state.name}: "
                                      + _state_reason(self.core))
        return commander.install(planned, self.core.mission.trajectory_time)

    # ------------------------------------------------------------------ status
    def status(self) -> Reply:
        """In the loop: the flight now (see :mod:`groundstation.client` for the fields)."""
        core = self.core
        est = core.last_estimate
        reference = core.mission.preview(self._clock(), 0.0)
        commander = core.commander
        motion = commander.current if commander is not None else None
        return {
            "ok": True, "state": core.state.name, "state_code": int(core.state),
            "reason": _state_reason(core), "commanded": commander is not None,
            "estimate": None if est is None else {
                "position": est.position.tolist(),
                "velocity": rotate(est.quaternion, est.velocity_body).tolist(),
                "yaw": heading_of(est.quaternion), "quaternion": est.quaternion.tolist()},
            "reference": {"position": reference.position.tolist(),
                          "velocity": reference.velocity.tolist(), "yaw": reference.yaw},
            "ground": core.mission.ground.tolist(),
            "motion": None if motion is None else motion.report(),
            "idle_land_in_s": None if commander is None
            else commander.idle_land_in(self._clock()),
            "land_request": core.land_request_reason,
            "auto": list(core.auto_channels),
            "health": dict(self._health()),
        }


def _state_reason(core: FlightCore) -> str:
    transitions = core.supervisor.transitions
    return transitions[-1].reason if transitions else "waiting for the preflight checks"


def _refusal(exc: CommandRefusedError) -> Reply:
    reason = exc.reason if len(exc.reason) <= 400 else exc.reason[:397] + "..."
    return {"ok": False, "error": reason, "kind": exc.kind}


def _only(request: Mapping[str, Any], *fields: str) -> None:
    unknown = sorted(set(request) - {"request", *fields})
    if unknown:
        raise CommandRefusedError("request", f"unknown field(s) {', '.join(unknown)[:80]} "
                                  f"(known: {', '.join(fields) or 'none'})")
