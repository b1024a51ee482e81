"""What a daemon knows of its peers: their latest estimated poses and intents.

:class:`PeerTable` subscribes to ``<fleet>/*/pose`` and ``<fleet>/*/intent`` and keeps,
for each configured peer, the latest message and the monotonic time it arrived here
(ages are measured on this machine's clock: no clock is shared between lab PCs). Zenoh
calls it from its own threads; the flight loop and the request threads read
:meth:`PeerTable.views`. Messages from vehicles that are not configured peers, and bytes
that are not a message, are counted and dropped.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from groundstation.errors import ProtocolError
from groundstation.fleet import keys
from groundstation.fleet.messages import Intent, PeerPose
from groundstation.fleet.separation import PeerView

if TYPE_CHECKING:
    import zenoh

TERMINAL_STATES = frozenset({6, 7, 8, 9, 10})
"""The supervisor's terminal states by number (DONE, HANDBACK, PILOT, LINK_LOST, ABORTED:
``flight.supervisor.TERMINAL``; a test checks they agree)."""


@dataclass
class _Peer:
    pose: PeerPose | None = None
    pose_t: float = -math.inf
    intent: Intent | None = None


class PeerTable:
    """The latest pose and intent of each of ``peers`` (see the module docstring).

    clock : monotonic [s] (injectable for tests)
    """

    def __init__(self, peers: Sequence[str], clock: Callable[[], float] = time.monotonic
                 ) -> None:
        self._peers = {name: _Peer() for name in peers}
        self._clock = clock
        self._lock = threading.Lock()
        self._subscribers: list[Any] = []
        self.ignored = 0
        """Messages from vehicles that are not peers."""
        self.malformed = 0
        """Payloads that were not a pose or intent."""

    @property
    def names(self) -> tuple[str, ...]:
        """The peers' names."""
        return tuple(self._peers)

    def subscribe(self, session: zenoh.Session, fleet: str) -> PeerTable:
        """Subscribe to the peers' poses and intents on ``session``."""
        if self._peers:
            self._subscribers = [
                session.declare_subscriber(keys.all_vehicles(fleet, "pose"), self._on_pose),
                session.declare_subscriber(keys.all_vehicles(fleet, "intent"),
                                           self._on_intent)]
        return self

    def close(self) -> None:
        """Undeclare the subscriptions (idempotent)."""
        subscribers, self._subscribers = self._subscribers, []
        for subscriber in subscribers:
            try:
                subscriber.undeclare()
            except Exception:  # the session closed first: nothing more arrives
                continue

    def _on_pose(self, sample: zenoh.Sample) -> None:
        self.receive_pose(keys.vehicle_of(str(sample.key_expr)), sample.payload.to_bytes())

    def _on_intent(self, sample: zenoh.Sample) -> None:
        self.receive_intent(keys.vehicle_of(str(sample.key_expr)), sample.payload.to_bytes())

    def receive_pose(self, name: str, data: bytes) -> None:
        """A pose message from ``name`` arrived now."""
        now = self._clock()
        with self._lock:
            peer = self._peers.get(name)
            if peer is None:
                self.ignored += 1
                return
            try:
                pose = PeerPose.unpack(data)
            except ProtocolError:
                self.malformed += 1
                return
            peer.pose, peer.pose_t = pose, now

    def receive_intent(self, name: str, data: bytes) -> None:
        """An intent message from ``name`` arrived."""
        with self._lock:
            peer = self._peers.get(name)
            if peer is None:
                self.ignored += 1
                return
            try:
                peer.intent = Intent.unpack(data)
            except ProtocolError:
                self.malformed += 1

    def views(self, now: float | None = None) -> list[PeerView]:
        """Each peer as :class:`~groundstation.fleet.separation.PeerView` at ``now``
        (monotonic [s], default the clock's)."""
        t = self._clock() if now is None else now
        out = []
        with self._lock:
            for name, peer in self._peers.items():
                pose = peer.pose
                position = None
                if pose is not None and pose.known:
                    position = np.array(pose.position, dtype=float)
                intent = peer.intent
                out.append(PeerView(
                    name, position, t - peer.pose_t,
                    ended=pose is not None and pose.state in TERMINAL_STATES,
                    intent=intent.points if intent is not None else np.zeros((0, 3)),
                    step_m=intent.step_m if intent is not None else 0.0))
        return out
