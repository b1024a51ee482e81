"""A daemon's Vicon poses from the fleet's relay (``vicon.source: zenoh``).

:class:`ZenohPoseSource` is a :class:`~groundstation.vicon.receiver.ViconReceiver` whose
datagrams come from ``<fleet>/vicon/<object>`` instead of a UDP socket: each relayed item
is put back into a one-item datagram of the same layout and fed, with its receive time,
to the same :class:`~groundstation.vicon.posefilter.PoseFilter` (decoding, lost tracking,
plausibility, pose streams, rival senders, the volume), so the latency model
(``vicon.latency_s``), the rate and age the failsafes read and every counter are those of
a daemon reading Tracker itself.

The receive time is the relay's: on the relay's own machine (the same boot, hence the
same ``CLOCK_MONOTONIC``) its stamp is taken as it is; from another machine, the arrival
here less the time the relay held the datagram, so the network's hop counts as latency
(add it to ``vicon.latency_s``: README "Fleet"). A stamp from the future is taken as now.
A relay that stops, or a network that parts, is silence: the Vicon failsafes act as for a
Vicon loss. Bytes that are not a relayed pose are counted and dropped.
"""

from __future__ import annotations

import time
from typing import TYPE_CHECKING, Any

import structlog

from groundstation.errors import ProtocolError, ViconError
from groundstation.fleet import keys
from groundstation.fleet.messages import BOOT_ID, RelayedPose
from groundstation.timing import TimingHistogram
from groundstation.vicon.decoder import ObjectPose, encode_datagram
from groundstation.vicon.receiver import ViconParams, ViconReceiver

if TYPE_CHECKING:
    import zenoh

log = structlog.get_logger(__name__)


class ZenohPoseSource(ViconReceiver):
    """One object's poses from the relay on ``session`` (see the module docstring).

    fleet : the key prefix; the other parameters are :class:`ViconReceiver`'s (no port).
    :attr:`hop` holds the relay-to-here times of same-machine items [s];
    :attr:`malformed` counts payloads that were not a relayed pose.
    """

    def __init__(self, session: zenoh.Session, fleet: str, object_name: str,
                 *args: Any, **kwargs: Any) -> None:
        super().__init__("127.0.0.1", 0, object_name, *args, **kwargs)
        self._session = session
        self.key = keys.vicon_key(fleet, object_name)
        self._subscriber: Any = None
        self.hop = TimingHistogram()
        self.malformed = 0
        self.remote = 0
        """Items from a relay on another machine (their stamps are re-based here)."""

    @classmethod
    def for_fleet(cls, session: zenoh.Session, fleet: str, params: ViconParams
                    ) -> ZenohPoseSource:
        """The source of a fleet's vehicle: its object under the fleet's prefix, through
        the pose filter ``params`` describe (its UDP address unused)."""
        f = params.filter
        return cls(session, fleet, f.object_name, f.world_to_ned, f.body_to_object,
                   f.latency_s, **f.options())

    def start(self) -> ZenohPoseSource:
        """Subscribe (no-op if started). ViconError if closed or the subscription fails."""
        if self._closed:
            raise ViconError("the pose source is closed")
        if self._subscriber is not None:
            return self
        try:
            self._subscriber = self._session.declare_subscriber(self.key, self._on_sample)
        except Exception as exc:  # zenoh.ZError
            raise ViconError(f"cannot subscribe to {self.key}: {exc}") from exc
        # ViconReceiver's calls check that a reader runs; the subscription is the reader
        self._thread = _Subscribed()  # type: ignore[assignment]
        self._log.info("vicon_listening", key=self.key, object=self.filter.object_name)
        return self

    def close(self) -> None:
        """Stop receiving (idempotent)."""
        if self._closed:
            return
        self._closed = True
        subscriber, self._subscriber = self._subscriber, None
        if subscriber is not None:
            try:
                subscriber.undeclare()
            except Exception as exc:  # the session closed first: nothing more arrives
                log.debug("pose subscriber not undeclared", error=str(exc))
        with self._cond:
            self._cond.notify_all()

    @property
    def address(self) -> tuple[str, int]:
        """No socket: the key as ``(key, 0)``."""
        return self.key, 0

    def fileno(self) -> int:
        """No socket to select on."""
        raise ViconError("a Zenoh pose source has no file descriptor")

    def _on_sample(self, sample: zenoh.Sample) -> None:
        """Zenoh's callback: one relayed item -> the pose filter (never raises)."""
        try:
            self._receive(sample)
        except Exception as exc:  # a fault of ours: counted and logged, the stream goes on
            with self._cond:
                self.malformed += 1
            log.warning("relayed pose not taken", error=repr(exc))

    def _receive(self, sample: zenoh.Sample) -> None:
        now = self._clock()
        if self._closed:
            return
        try:
            item = RelayedPose.unpack(sample.payload.to_bytes())
        except ProtocolError:
            with self._cond:
                self.malformed += 1
            return
        if item.boot == BOOT_ID:
            t_receive = min(item.t_receive_ns * 1e-9, now)
            self.hop.add(now - t_receive)
        else:
            held = max(item.t_publish_ns - item.t_receive_ns, 0) * 1e-9
            t_receive = now - min(held, 1.0)
            self.remote += 1
        datagram = encode_datagram(item.frame, [ObjectPose(
            self.filter.object_name, item.translation, item.rotation)], pad_to=None)
        with self._cond:
            pose = self.filter.process(datagram, t_receive)
            if pose is not None:
                self._latest = pose
                self._queue.append(pose)
                self._cond.notify_all()


class _Subscribed:
    """Stands for the reader thread a UDP client has (ViconReceiver checks for one)."""

    def join(self, timeout: float | None = None) -> None:
        """Nothing to join: Zenoh's own threads deliver the samples."""
        time.sleep(0)
