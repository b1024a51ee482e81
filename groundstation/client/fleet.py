"""Fly a fleet from your own code: :class:`Fleet` (``groundstation.client.Fleet``).

A fleet started with ``gs fleet up fleet.yaml`` (or one ``gs fleet fly`` per vehicle,
e.g. the systemd units ``groundstation@<vehicle>``) takes its requests over Zenoh. A
:class:`Fleet` opens one session to every member the fleet file lists; ``fleet[name]``
is a :class:`FleetVehicle`, which has every method of :class:`groundstation.client.Client`
(``go_to``, ``follow``, ``hold``, ``land``, ``status``, ``wait_until_arrived``, ...) with
the same checks, refusals (:class:`~groundstation.client.Refused` and its subclasses, with
:class:`~groundstation.client.TooClose` for the fleet's separation) and replies, and the
fleet-wide ones ask every vehicle at once::

    from groundstation.client import Fleet

    with Fleet("config/fleet.yaml") as fleet:
        fleet.wait_for_state("TRACK")
        start = time.time() + 5.0
        for k, name in enumerate(fleet.names):       # three eights in phase
            fleet[name].follow({"name": "figure-eight", "center": [0.0, y[k], -1.0],
                                "period_s": 8.0}, start_at=start)
        fleet.land(wait=True)

Frames and units as in :mod:`groundstation.client`: NED metres in the lab's frame,
headings in degrees, times in seconds; ``start_at`` is a ``time.time()``, so vehicles on
different lab PCs start together as far as the PCs' clocks agree (NTP).
"""

from __future__ import annotations

import json
import queue
import threading
import time
from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from groundstation.client.vehicle import (
    _REFUSALS,
    DEFAULT_TIMEOUT_S,
    ENDED_STATES,
    PLAN_WAIT_S,
    Client,
    DaemonUnreachableError,
    Ended,
    Refused,
    Status,
    WaitTimeout,
)
from groundstation.config import ZenohConfig
from groundstation.config.fleetfile import FleetFile, load_fleet
from groundstation.fleet import keys
from groundstation.fleet.session import Membership, open_session

if TYPE_CHECKING:
    import zenoh

Outcome = Mapping[str, Any] | Exception
"""What one vehicle answered a fleet-wide request: its reply, or why there is none."""


class _Telemetry:
    """A subscription to one vehicle's (or every vehicle's: ``*``) telemetry topics on
    Zenoh, read like :class:`~groundstation.telemetry.subscriber.TelemetrySubscriber`."""

    def __init__(self, session: zenoh.Session, fleet: str, vehicle: str,
                 topics: Sequence[str]) -> None:
        self._queue: queue.Queue[tuple[str, str, dict[str, Any]]] = queue.Queue(1024)
        self._subscribers = [session.declare_subscriber(keys.vehicle_key(fleet, vehicle, t),
                                                        self._on_sample) for t in topics]

    def _on_sample(self, sample: zenoh.Sample) -> None:
        key = str(sample.key_expr)
        try:
            payload = json.loads(sample.payload.to_bytes())
        except ValueError:
            return
        if isinstance(payload, dict):
            try:
                self._queue.put_nowait((keys.vehicle_of(key), key.rsplit("/", 1)[1], payload))
            except queue.Full:
                return

    def receive(self, timeout: float | None) -> tuple[str, str, dict[str, Any]] | None:
        """(vehicle, topic, payload) or None after ``timeout`` [s] without a message."""
        try:
            return self._queue.get(timeout=timeout)
        except queue.Empty:
            return None

    def close(self) -> None:
        """Undeclare the subscriptions."""
        for subscriber in self._subscribers:
            subscriber.undeclare()  # type: ignore[no-untyped-call]  # zenoh's stub: unannotated
        self._subscribers = []

    def __enter__(self) -> _Telemetry:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()


class FleetVehicle(Client):
    """One vehicle of a :class:`Fleet`: :class:`groundstation.client.Client`'s methods over
    Zenoh queries (``<fleet>/<vehicle>/cmd/<request>``) and its telemetry keys."""

    def __init__(self, fleet: Fleet, name: str) -> None:
        super().__init__(f"zenoh:{keys.request_key(fleet.name, name, '*')}",
                         telemetry=keys.vehicle_key(fleet.name, name, "state"),
                         timeout_s=fleet.timeout_s, plan_wait_s=fleet.plan_wait_s)
        self.fleet = fleet
        self.name = name

    def request(self, request: Mapping[str, Any], timeout_s: float | None = None
                ) -> dict[str, Any]:
        """Send one request and return the reply; raises the :class:`Refused` subclass of
        its ``kind``, or DaemonUnreachableError if the vehicle does not answer."""
        wait = self.timeout_s if timeout_s is None else timeout_s
        name = str(request.get("request", ""))
        fields = {k: v for k, v in request.items() if k != "request"}
        replies = self.fleet.query(self.name, name, fields, wait)
        reply = replies.get(self.name)
        if not isinstance(reply, Mapping):
            raise DaemonUnreachableError(
                f"{self.name} did not answer {name!r} within {wait:g} s"
                + (f" ({reply})" if reply is not None else ""))
        if not reply.get("ok"):
            kind = str(reply.get("kind", "request"))
            raise _REFUSALS.get(kind, Refused)(str(reply.get("error", reply)), kind)
        return dict(reply)

    def land(self, *, wait: bool = False, timeout: float = 60.0) -> Ended | None:
        """Land now; with ``wait``, return how the flight ended (its final ``state``)."""
        if not wait:
            self.request({"request": "land"})
            return None
        with self.fleet.telemetry(self.name, ["state"]) as sub:
            self.request({"request": "land"})
            return self._ended(sub, timeout)

    def wait_until_ended(self, timeout: float = 60.0) -> Ended:
        """Block until the flight ends; WaitTimeout after ``timeout`` [s]."""
        with self.fleet.telemetry(self.name, ["state"]) as sub:
            self.status()
            return self._ended(sub, timeout)

    @staticmethod
    def _ended(sub: _Telemetry, timeout: float) -> Ended:
        deadline = time.monotonic() + timeout
        while (left := deadline - time.monotonic()) > 0:
            message = sub.receive(timeout=left)
            if message is not None and message[2].get("final"):
                return Ended.from_payload(message[2])
        raise WaitTimeout(f"the flight has not ended within {timeout:g} s")

    def subscribe(self, topics: Sequence[str] = ("state", "health"),
                  timeout: float | None = None) -> Iterator[tuple[str, dict[str, Any]]]:
        """The vehicle's telemetry as (topic, payload) pairs until ``timeout`` [s] of
        silence (None: forever) or the flight's final message."""
        with self.fleet.telemetry(self.name, topics) as sub:
            while (message := sub.receive(timeout)) is not None:
                yield message[1], message[2]
                if message[1] == "state" and message[2].get("final"):
                    return


class Fleet:
    """A connection to every vehicle of a fleet (see the module docstring).

    fleet_file : the fleet's ``fleet.yaml`` (its name, vehicles and endpoints)
    identity : with TLS, the name of this client's certificate in the fleet's
        ``tls_directory`` (default: the first operator)
    timeout_s, plan_wait_s : as :class:`~groundstation.client.Client`'s
    """

    def __init__(self, fleet_file: str | Path, *, identity: str | None = None,
                 timeout_s: float = DEFAULT_TIMEOUT_S, plan_wait_s: float = PLAN_WAIT_S
                 ) -> None:
        spec, _base = load_fleet(fleet_file)
        self.spec: FleetFile = spec
        self.name = spec.fleet
        self.names: list[str] = spec.names
        self.timeout_s = timeout_s
        self.plan_wait_s = plan_wait_s
        who = identity or (spec.zenoh.operators[0] if spec.zenoh.operators else "operator")
        settings: ZenohConfig = spec.zenoh_for(who, [])
        # here, not at the top: the assembly loads the whole flight, which `gs fleet status`
        # and the other clients' start-up do not need
        from groundstation.flight.assembly import zenoh_params

        self._session = open_session(zenoh_params(settings), Membership(
            spec.fleet, tuple(spec.names), operators=tuple(spec.zenoh.operators)))
        self._vehicles = {name: FleetVehicle(self, name) for name in spec.names}
        self._lock = threading.Lock()

    def __getitem__(self, name: str) -> FleetVehicle:
        try:
            return self._vehicles[name]
        except KeyError:
            raise KeyError(f"no vehicle {name!r} in fleet {self.name!r} "
                           f"({', '.join(self.names)})") from None

    def __iter__(self) -> Iterator[FleetVehicle]:
        return iter(self._vehicles.values())

    def close(self) -> None:
        """Close the session (idempotent)."""
        if not self._session.is_closed():
            self._session.close()  # type: ignore[no-untyped-call]  # zenoh's stub: unannotated

    def __enter__(self) -> Fleet:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    # ------------------------------------------------------------------ the wire
    def query(self, vehicle: str, request: str, fields: Mapping[str, Any],
              timeout_s: float) -> dict[str, Outcome]:
        """Send ``request`` with ``fields`` to ``vehicle`` (``*``: every vehicle, at once)
        and collect the replies within ``timeout_s`` [s]: vehicle -> reply (a JSON
        object), or the exception saying why it has none."""
        import zenoh

        payload = json.dumps(dict(fields)).encode() if fields else None
        out: dict[str, Outcome] = {}
        try:
            replies = self._session.get(
                keys.request_key(self.name, vehicle, request), payload=payload,
                target=zenoh.QueryTarget.ALL, consolidation=zenoh.ConsolidationMode.NONE,
                timeout=timeout_s)
            for reply in replies:
                if reply.ok is not None:
                    name = keys.vehicle_of(str(reply.ok.key_expr))
                    try:
                        body = json.loads(reply.ok.payload.to_bytes())
                    except ValueError as exc:
                        out[name] = DaemonUnreachableError(f"{name}: not JSON: {exc}")
                        continue
                    out[name] = body if isinstance(body, dict) else \
                        DaemonUnreachableError(f"{name}: not a reply object")
        except zenoh.ZError as exc:
            raise DaemonUnreachableError(f"the fleet's session failed: {exc}") from exc
        wanted = self.names if vehicle == "*" else [vehicle]
        return {name: out.get(name, DaemonUnreachableError(  # in the fleet file's order
            f"{name} did not answer {request!r} within {timeout_s:g} s")) for name in wanted}

    def telemetry(self, vehicle: str, topics: Sequence[str]) -> _Telemetry:
        """Subscribe to ``vehicle``'s (``*``: every vehicle's) telemetry ``topics``."""
        return _Telemetry(self._session, self.name, vehicle, topics)

    # ------------------------------------------------------------------ every vehicle
    def status(self) -> dict[str, Status | Exception]:
        """Every vehicle's status at once (a vehicle that does not answer: the reason)."""
        out: dict[str, Status | Exception] = {}
        for name, reply in self.query("*", "status", {}, self.timeout_s).items():
            out[name] = reply if isinstance(reply, Exception) else _status(reply)
        return out

    def land(self, *, wait: bool = False, timeout: float = 60.0
             ) -> dict[str, Ended | Outcome]:
        """Ask every vehicle to land, all at once. Without ``wait``, each one's reply (or
        why there is none); with ``wait``, how each flight ended (its final ``state``:
        :class:`~groundstation.client.Ended`), or why it did not within ``timeout`` [s]
        (a vehicle that refused, or did not answer, is waited for no longer)."""
        with self.telemetry("*", ["state"]) as sub:
            replies = self.query("*", "land", {}, self.timeout_s)
            if not wait:
                return dict(replies)
            refused: dict[str, Ended | Outcome] = {
                n: r for n, r in replies.items() if isinstance(r, Exception) or not r.get("ok")}
            return self.until_ended(sub, timeout, refused)

    def until_ended(self, sub: _Telemetry, timeout: float,
                    known: Mapping[str, Ended | Outcome] | None = None
                    ) -> dict[str, Ended | Outcome]:
        """How each vehicle's flight ended, from its final ``state`` on ``sub`` (a
        subscription to ``telemetry("*", ["state"])`` made before whatever ends them, so
        that no end is missed), waiting up to ``timeout`` [s]; those in ``known`` are not
        waited for; a vehicle whose flight has not ended then: WaitTimeout."""
        out: dict[str, Ended | Outcome] = dict(known or {})
        deadline = time.monotonic() + timeout
        while len(out) < len(self.names) and (left := deadline - time.monotonic()) > 0:
            message = sub.receive(timeout=left)
            if message is not None and message[2].get("final") and message[0] not in out:
                out[message[0]] = Ended.from_payload(message[2])
        return {name: out.get(name, WaitTimeout(f"{name} has not ended within {timeout:g} s"))
                for name in self.names}

    def hold(self) -> dict[str, Outcome]:
        """Ask every vehicle to hold, all at once: each one's reply (or why there is none)."""
        return self.query("*", "hold", {}, self.timeout_s + self.plan_wait_s)

    def wait_for_state(self, *states: str, timeout: float = 60.0) -> dict[str, Status]:
        """Block until every vehicle is in one of ``states`` (default TRACK); WaitTimeout
        naming the ones that are not after ``timeout`` [s], or at once naming those whose
        flight ended in another state."""
        wanted = states or ("TRACK",)
        deadline = time.monotonic() + timeout
        while True:
            now = self.status()
            good = {n: s for n, s in now.items() if isinstance(s, Status) and s.state in wanted}
            ended = [f"{n} ({s.state}: {s.reason})" for n, s in now.items()
                     if isinstance(s, Status) and s.state in ENDED_STATES]
            if len(good) == len(self.names):
                return good
            if ended:
                raise WaitTimeout(f"ended, not {'/'.join(wanted)}: {', '.join(ended)}")
            if time.monotonic() > deadline:
                late = [n for n in self.names if n not in good]
                raise WaitTimeout(f"not in {'/'.join(wanted)} within {timeout:g} s: "
                                  f"{', '.join(late)}")
            time.sleep(0.1)


def _status(reply: Mapping[str, Any]) -> Status | Exception:
    if not reply.get("ok"):
        kind = str(reply.get("kind", "request"))
        return _REFUSALS.get(kind, Refused)(str(reply.get("error", reply)), kind)
    try:
        return Status.from_reply(reply)
    except (KeyError, TypeError, ValueError) as exc:
        return DaemonUnreachableError(f"a status reply that is not one: {exc}")

