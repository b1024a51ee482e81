"""One vehicle's daemon over its request socket: :class:`Client`, its replies
(:class:`Status`, :class:`Motion`, :class:`Ended`) and its refusals.

Imported as :mod:`groundstation.client`, whose docstring is the guide: frames, units,
an example and the wire.
"""

from __future__ import annotations

import math
import time
import warnings
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from groundstation.errors import GroundStationError
from groundstation.telemetry.curve import CurveClient, load_client_keys
from groundstation.telemetry.requests import send_request
from groundstation.telemetry.subscriber import TelemetrySubscriber

DEFAULT_CONTROL = "tcp://127.0.0.1:5557"
"""The daemon's default ``telemetry.control_endpoint``."""
DEFAULT_TELEMETRY = "tcp://127.0.0.1:5556"
"""The daemon's default ``telemetry.endpoint``."""
DEFAULT_TIMEOUT_S = 3.0
"""How long a request waits for the daemon's reply by default [s] (``gs ... --timeout``
has the same default)."""
POLL_S = 0.05
"""How often the blocking helpers ask for the status [s]."""
PLAN_WAIT_S = 20.0
"""How much longer than ``timeout_s`` a motion request waits for its reply [s]: the
daemon answers once the motion is planned, within its ``api.plan_timeout_s`` (5 s by
default) after its planner process is ready (a start still under way may take up to
10 s more on a busy machine), and refuses it otherwise."""
FAILSAFE_STATES = frozenset({"HOLD", "HANDBACK", "LINK_LOST", "ABORTED"})
"""States a failsafe puts the flight in (a landing may be one too: see ``reason``)."""
ENDED_STATES = frozenset({"DONE", "HANDBACK", "LINK_LOST", "ABORTED"})
"""States a flight ends in."""


# --------------------------------------------------------------------------- errors
class ClientError(GroundStationError):
    """Anything the client raises."""


class DaemonUnreachableError(ClientError):
    """No reply: no daemon flying at the endpoint, or it does not accept our keys."""


class Refused(ClientError):  # noqa: N818 (a refusal, not a fault of the client)
    """The daemon refused the request; ``kind`` and ``reason`` say why."""

    kind = "refused"

    def __init__(self, reason: str, kind: str | None = None) -> None:
        super().__init__(reason)
        self.reason = reason
        if kind is not None:
            self.kind = kind


class BadRequest(Refused):
    """Malformed or absurd: a position that is not 3 finite numbers, a heading beyond one
    turn (+-360 degrees), a duration outside [0.2, 600] s, a ``start_at`` beyond the daemon's
    ``api.start_horizon_s``, an unknown field or request."""

    kind = "request"


class NotNow(Refused):
    """Not in this state: before take-off is complete, while a failsafe acts, once landing
    began, or a flight that flies a configured trajectory."""

    kind = "state"


class OutsideVolume(Refused):
    """A point of the motion outside the flight volume: beyond its sides or ceiling less
    the margin, or below the floor (which has no margin)."""

    kind = "volume"


class Infeasible(Refused):
    """Beyond the vehicle's or the configured limits: speed, tilt, turn rate, lift; a motion
    longer than 600 s; a plan not made within the daemon's ``api.plan_timeout_s``."""

    kind = "infeasible"


class TooClose(Refused):
    """In a fleet: the motion would bring the vehicle closer to another vehicle than the
    fleet's ``separation_m`` (where the other is, or is planned to be)."""

    kind = "separation"


class Busy(Refused):
    """The flight kept changing its plan while this motion was planned, or the daemon's
    planner was starting: try again."""

    kind = "busy"


class InternalError(Refused):
    """The daemon failed to answer the request (a fault of the ground station, in its log);
    the flight goes on."""

    kind = "internal"


class Preempted(ClientError):  # noqa: N818
    """A motion waited for did not arrive: a failsafe took over or another motion replaced
    it. ``status`` is the flight's status then."""

    def __init__(self, reason: str, status: Status) -> None:
        super().__init__(reason)
        self.status = status


class WaitTimeout(ClientError, TimeoutError):  # noqa: N818
    """A blocking helper's timeout ran out."""


_REFUSALS: dict[str, type[Refused]] = {
    cls.kind: cls for cls in (BadRequest, NotNow, OutsideVolume, Infeasible, Busy,
                              InternalError, TooClose)}


# --------------------------------------------------------------------------- replies
@dataclass(frozen=True, slots=True)
class Motion:
    """A motion the daemon accepted.

    id : its number in this flight; kind : go_to, follow or hold; state : moving, arrived,
    superseded (by a later motion) or preempted (by a failsafe), with ``reason``;
    target : where it comes to rest, NED [m]; target_yaw_deg : the heading there [deg from
    north] (None: kept); duration_s : planned time until at rest [s]; latency_s : request
    received to the reference starting to move [s] (None until it moved); arrived_at : when it
    arrived, on the daemon's monotonic clock (``time.monotonic()`` on the same machine)
    [s] (None until then).
    """

    id: int
    kind: str
    state: str
    reason: str
    target: tuple[float, float, float]
    target_yaw_deg: float | None
    duration_s: float
    latency_s: float | None
    arrived_at: float | None = None

    @classmethod
    def from_reply(cls, data: Mapping[str, Any]) -> Motion:
        """From a reply's ``motion`` object (its ``target_yaw`` in radians on the wire)."""
        x, y, z = (float(v) for v in data["target"])
        return cls(int(data["id"]), str(data["kind"]), str(data["state"]),
                   str(data.get("reason", "")), (x, y, z), _degrees(data.get("target_yaw")),
                   float(data["duration_s"]), data.get("latency_s"), data.get("arrived_at"))

    @property
    def target_yaw(self) -> float | None:
        """Deprecated: :attr:`target_yaw_deg` in radians."""
        _warn_radians("Motion.target_yaw", "target_yaw_deg")
        return None if self.target_yaw_deg is None else math.radians(self.target_yaw_deg)


@dataclass(frozen=True, slots=True)
class Status:
    """The flight now.

    state : the supervisor's state (PREFLIGHT, TAKEOFF, TRACK, HOLD, LAND, DISARM, DONE,
    HANDBACK, LINK_LOST, ABORTED) and ``reason`` its last transition's reason;
    position, velocity : the estimate, NED [m], [m/s] (None before the estimator runs);
    yaw_deg : its heading [deg from north]; reference, reference_yaw_deg : what is
    tracked, NED [m], [deg from north]; ground : where it took off, NED [m]; motion : the
    latest motion (None before any);
    battery_v [V]; idle_land_in_s : seconds until the idle landing (None while moving);
    commanded : the flight takes motions (``--trajectory none``); raw : the whole reply
    (as on the wire: headings in radians).
    """

    state: str
    reason: str
    position: tuple[float, float, float] | None
    velocity: tuple[float, float, float] | None
    yaw_deg: float | None
    reference: tuple[float, float, float]
    reference_yaw_deg: float
    ground: tuple[float, float, float]
    motion: Motion | None
    battery_v: float | None
    idle_land_in_s: float | None
    commanded: bool
    raw: Mapping[str, Any]

    @classmethod
    def from_reply(cls, data: Mapping[str, Any]) -> Status:
        """From a ``status`` reply."""
        est = data.get("estimate")
        motion = data.get("motion")
        battery = data.get("health", {}).get("battery_v")
        return cls(
            str(data["state"]), str(data.get("reason", "")),
            _xyz(est["position"]) if est else None, _xyz(est["velocity"]) if est else None,
            math.degrees(float(est["yaw"])) if est else None,
            _xyz(data["reference"]["position"]),
            math.degrees(float(data["reference"]["yaw"])), _xyz(data["ground"]),
            Motion.from_reply(motion) if motion else None,
            float(battery) if isinstance(battery, int | float) else None,
            data.get("idle_land_in_s"), bool(data.get("commanded")), dict(data))

    @property
    def yaw(self) -> float | None:
        """Deprecated: :attr:`yaw_deg` in radians."""
        _warn_radians("Status.yaw", "yaw_deg")
        return None if self.yaw_deg is None else math.radians(self.yaw_deg)

    @property
    def reference_yaw(self) -> float:
        """Deprecated: :attr:`reference_yaw_deg` in radians."""
        _warn_radians("Status.reference_yaw", "reference_yaw_deg")
        return math.radians(self.reference_yaw_deg)

    @property
    def error_m(self) -> float | None:
        """Distance from the estimate to the reference [m]."""
        if self.position is None:
            return None
        return math.dist(self.position, self.reference)


@dataclass(frozen=True, slots=True)
class Ended:
    """How a flight ended: its terminal ``state`` (DONE after a normal landing),
    ``outcome`` (COMPLETED, FAILSAFE or STOPPED: ``gs fly``'s exit code by name),
    ``reason`` and ``flight_time_s`` [s]."""

    state: str
    outcome: str
    reason: str
    flight_time_s: float | None

    @classmethod
    def from_payload(cls, payload: Mapping[str, Any]) -> Ended:
        """From the flight's final ``state`` telemetry message."""
        return cls(str(payload["supervisor"]["name"]), str(payload.get("outcome")),
                   str(payload.get("reason", "")), payload.get("flight_time_s"))


def _xyz(values: Sequence[Any]) -> tuple[float, float, float]:
    x, y, z = (float(v) for v in values)
    return x, y, z


def _degrees(radians: Any) -> float | None:
    """A heading from the wire [rad] in degrees, or None."""
    return None if radians is None else math.degrees(float(radians))


def _warn_radians(old: str, new: str) -> None:
    """Warn that the radian attribute ``old`` is deprecated for ``new`` (degrees)."""
    warnings.warn(f"{old} is in radians and deprecated: use {new} (degrees)",
                  DeprecationWarning, stacklevel=3)


# --------------------------------------------------------------------------- the client
class Client:
    """A connection to a running daemon.

    endpoint : its ``telemetry.control_endpoint``; telemetry : its ``telemetry.endpoint``
    (for :meth:`subscribe` and :meth:`transitions`); timeout_s : how long a request waits
    for its reply [s]; plan_wait_s : how much longer a motion request waits (the daemon
    plans it first; see :data:`PLAN_WAIT_S`); server_key, client_key : the daemon's public
    key file and this client's ``.key_secret`` file when it authenticates clients (CURVE).
    """

    def __init__(self, endpoint: str = DEFAULT_CONTROL, *, telemetry: str = DEFAULT_TELEMETRY,
                 timeout_s: float = DEFAULT_TIMEOUT_S, plan_wait_s: float = PLAN_WAIT_S,
                 server_key: str | Path | None = None,
                 client_key: str | Path | None = None) -> None:
        self.endpoint = endpoint
        self.telemetry = telemetry
        self.timeout_s = timeout_s
        self.plan_wait_s = plan_wait_s
        self._curve: CurveClient | None = None
        if (server_key is None) != (client_key is None):
            raise ClientError("server_key and client_key go together (CURVE needs both)")
        if server_key is not None and client_key is not None:
            self._curve = load_client_keys(client_key, server_key)

    # ------------------------------------------------------------------ requests
    def request(self, request: Mapping[str, Any], timeout_s: float | None = None
                ) -> dict[str, Any]:
        """Send one request and return the reply (waiting ``timeout_s`` [s], default the
        client's); raises the :class:`Refused` subclass of its ``kind``, or
        DaemonUnreachableError."""
        wait = self.timeout_s if timeout_s is None else timeout_s
        try:
            reply = send_request(self.endpoint, dict(request), wait, curve=self._curve)
        except GroundStationError as exc:
            raise DaemonUnreachableError(str(exc)) from exc
        if not reply.get("ok"):
            reason = str(reply.get("error", reply))
            kind = str(reply.get("kind", "request"))
            raise _REFUSALS.get(kind, Refused)(reason, kind)
        return reply

    def status(self) -> Status:
        """The flight now."""
        return Status.from_reply(self.request({"request": "status"}))

    def go_to(self, position: Sequence[float], *, yaw_deg: float | None = None,
              duration: float | None = None, wait: bool = False,
              timeout: float | None = None, yaw: float | None = None) -> Motion:
        """Move to ``position`` (NED [m]) and stop there, turning to ``yaw_deg`` [deg from
        north, within +-360] (None: keep the heading), in ``duration`` [s] (None: the
        daemon sizes it from ``api.speed_m_s`` and the limits). ``wait``: return once
        arrived (see :meth:`wait_until_arrived`; ``timeout`` defaults to the duration plus
        10 s). ``yaw`` [rad] is the deprecated former keyword (DeprecationWarning).

        Everything after the position is keyword-only, so a call written for the radian
        API (``go_to(p, 1.57)``) fails at once instead of turning to 1.57 degrees."""
        if yaw is not None:
            if yaw_deg is not None:
                raise BadRequest("yaw_deg and the deprecated yaw (radians) both given")
            warnings.warn("go_to(yaw=...) is in radians and deprecated: use yaw_deg=",
                          DeprecationWarning, stacklevel=2)
            yaw_deg = math.degrees(yaw)
        heading = None if yaw_deg is None else math.radians(yaw_deg)  # the wire: radians
        motion = self._motion({"request": "go_to", "position": [float(v) for v in position],
                               "yaw": heading, "duration": duration})
        return self._maybe_wait(motion, wait, timeout)

    def takeoff(self, height: float, *, timeout: float = 60.0, wait: bool = True) -> Motion:
        """Wait for the daemon's own take-off to complete (TRACK), then climb or descend to
        ``height`` [m] above the take-off point, straight up or down."""
        self.wait_for_state("TRACK", timeout=timeout)
        motion = self._motion({"request": "takeoff", "height": float(height)})
        return self._maybe_wait(motion, wait, None)

    def follow(self, trajectory: Mapping[str, Any] | str | Path, *,
               duration: float | None = None, start_at: float | None = None,
               wait: bool = False, timeout: float | None = None) -> Motion:
        """Fly a trajectory: a mapping like the configuration's ``trajectory:`` section
        (``{"name": "figure-eight", "period_s": 10, "center": [0, 0, -1], "yaw_deg": 90}``),
        or a waypoint CSV (``t, x, y, z[, yaw_deg]`` rows: s, NED m, degrees; a heading
        column named ``yaw`` or ``yaw_rad``, or none of them named, is in radians, as
        other tools write it), read here and sent. The vehicle
        goes to its start, flies it for ``duration`` [s] (None: one lap, or the whole
        path) from ``start_at`` (a ``time.time()`` [s]; None: on arrival at the start), and
        holds at its end."""
        request: dict[str, Any] = {"request": "follow", "duration": duration,
                                   "start_at": start_at}
        if isinstance(trajectory, Mapping):
            request["trajectory"] = dict(trajectory)
        else:
            from groundstation.control.trajectories import read_waypoint_rows

            try:
                request["waypoints"] = read_waypoint_rows(trajectory)
            except GroundStationError as exc:
                raise BadRequest(str(exc)) from exc
        motion = self._motion(request)
        return self._maybe_wait(motion, wait, timeout)

    def hold(self) -> Motion:
        """Stop as soon as the limits allow and hold there."""
        return self._motion({"request": "hold"})

    def land(self, *, wait: bool = False, timeout: float = 60.0) -> Ended | None:
        """Land now (a nominal end: the daemon exits 0 once landed and handed back).
        ``wait``: return how the flight ended (from its final telemetry message), else
        None at once."""
        if not wait:
            self.request({"request": "land"})
            return None
        with TelemetrySubscriber(self.telemetry, topics=["state"]) as sub:
            self.request({"request": "land"})  # subscribed first: the end cannot be missed
            return self._final(sub, timeout)

    def wait_until_ended(self, timeout: float = 60.0) -> Ended:
        """Block until the flight ends (its final telemetry message); WaitTimeout after
        ``timeout`` [s]."""
        with TelemetrySubscriber(self.telemetry, topics=["state"]) as sub:
            self.status()  # still flying (else DaemonUnreachableError): the end is ahead
            return self._final(sub, timeout)

    def _final(self, sub: TelemetrySubscriber, timeout: float) -> Ended:
        deadline = time.monotonic() + timeout
        while (left := deadline - time.monotonic()) > 0:
            message = sub.receive(timeout=left)
            if message is not None and message[1].get("final"):
                return Ended.from_payload(message[1])
        raise WaitTimeout(f"the flight has not ended within {timeout:g} s")

    def set_channels(self, *auto: str) -> list[str]:
        """Put exactly these channels (pitch, roll, yaw, thrust) under the ground station's
        control and the rest under the pilot's; none: only report. Returns the set."""
        request: dict[str, Any] = {"request": "channels"}
        if auto:
            request["auto"] = list(auto)
        return [str(c) for c in self.request(request)["auto"]]

    # ------------------------------------------------------------------ waiting
    def wait_until_arrived(self, motion: Motion | int | None = None,
                           timeout: float = 30.0) -> Status:
        """Block until ``motion`` (default: the latest) has arrived: its reference at rest
        at the target and the estimate within ``api.arrival_tolerance_m``. Raises
        Preempted if a failsafe or a later motion ended it, WaitTimeout after ``timeout``
        [s]."""
        wanted = motion.id if isinstance(motion, Motion) else motion

        def arrived(status: Status) -> bool:
            nonlocal wanted
            current = status.motion
            if wanted is None and current is not None:
                wanted = current.id
            if current is not None and current.id == wanted and current.state == "arrived":
                return True
            if current is not None and wanted is not None and \
                    (current.id > wanted or current.state in ("superseded", "preempted")):
                why = current.reason if current.id == wanted else \
                    f"replaced by motion {current.id}"
                raise Preempted(f"motion {wanted} did not arrive: {why}", status)
            if status.state not in ("TRACK", "PREFLIGHT", "TAKEOFF"):
                raise Preempted(f"motion {wanted} did not arrive: {status.state} "
                                f"({status.reason})", status)
            return False
        return self._poll(arrived, timeout, lambda s: f"motion {wanted} has not arrived "
                          f"within {timeout:g} s (state {s.state}, error {s.error_m} m)")

    def wait_for_state(self, *states: str, timeout: float = 30.0) -> Status:
        """Block until the supervisor is in one of ``states``; WaitTimeout after ``timeout``
        [s], and Preempted at once if the flight ended in another state."""
        def reached(status: Status) -> bool:
            if status.state in states:
                return True
            if status.state in ENDED_STATES:
                raise Preempted(f"the flight ended in {status.state} ({status.reason}), "
                                f"not {'/'.join(states)}", status)
            return False
        return self._poll(reached, timeout, lambda s: f"not in {'/'.join(states)} within "
                          f"{timeout:g} s (state {s.state}: {s.reason})")

    def _poll(self, done: Callable[[Status], bool], timeout: float,
              late: Callable[[Status], str]) -> Status:
        """The status, every :data:`POLL_S`, until ``done`` says so (or raises); WaitTimeout
        with ``late``'s message after ``timeout`` [s]."""
        deadline = time.monotonic() + timeout
        while True:
            status = self.status()
            if done(status):
                return status
            if time.monotonic() > deadline:
                raise WaitTimeout(late(status))
            time.sleep(POLL_S)

    # ------------------------------------------------------------------ telemetry
    def subscribe(self, topics: Sequence[str] = ("state", "health"),
                  timeout: float | None = None) -> Iterator[tuple[str, dict[str, Any]]]:
        """The daemon's telemetry as (topic, payload) pairs (schema:
        :mod:`groundstation.telemetry.schema`), until ``timeout`` [s] passes without a
        message (None: forever) or the flight's final message."""
        with TelemetrySubscriber(self.telemetry, topics=list(topics)) as sub:
            while True:
                message = sub.receive(timeout=timeout)
                if message is None:
                    return
                yield message
                if message[0] == "state" and message[1].get("final"):
                    return

    def transitions(self, timeout: float | None = None) -> Iterator[tuple[str, str]]:
        """(old, new) supervisor states as the telemetry shows them change, until the
        flight's final message (or ``timeout`` [s] of silence)."""
        last: str | None = None
        for _topic, payload in self.subscribe(("state",), timeout):
            name = str(payload["supervisor"]["name"])
            if last is not None and name != last:
                yield last, name
            last = name

    def _motion(self, request: Mapping[str, Any]) -> Motion:
        # a daemon that is not there must not cost the planner's grace: ask for the status
        # first (one loopback round trip), so only a daemon that answers gets the longer wait
        self.request({"request": "status"})
        reply = self.request(request, self.timeout_s + self.plan_wait_s)
        return Motion.from_reply(reply["motion"])

    def _maybe_wait(self, motion: Motion, wait: bool, timeout: float | None) -> Motion:
        if not wait:
            return motion
        status = self.wait_until_arrived(motion, motion.duration_s + 10.0
                                         if timeout is None else timeout)
        return status.motion or motion

