"""The AscTec LL dialect's link: a poll schedule (sans-IO) and the pyserial link.

The LL vehicle sends only what it is asked for, so the link drives the stream itself:

* :class:`PollSchedule` (sans-IO, times passed in) polls IMU_RAWDATA every data period
  and adds LL_STATUS and RC_DATA to every ``status_every``-th and ``rc_every``-th poll.
  It takes turns as the public drivers do on the half-duplex radio: the next poll waits
  until the previous one's answers and the last command's acknowledgement are in, but
  at most half a period past its slot, so a radio whose round trip is longer than the
  period still gets every poll (pipelined); never in a burst.
  It counts polls not answered in time and commands not acknowledged in time, and keeps
  the command-to-acknowledgement times.
* :class:`LlLink` has the X-3D :class:`~groundstation.asctec.link.SerialLink`'s
  interface (:class:`~groundstation.asctec.dialect.VehicleLink`): the loop gets each IMU
  sample as a :class:`~groundstation.asctec.link.ReceivedData` whose
  :class:`~groundstation.asctec.messages.DataMsg` carries what the X-3D's DATA would:
  gyro and acc counts, a counter (:class:`~groundstation.asctec.ll.RepeatCounter`: this
  dialect has none, a repeat is recognised by identical values), and, when new ones
  arrived, the vehicle's status (LL_STATUS: battery, serial commands applied, motors;
  RC_DATA's lock as the RC-link flag) and the pilot's sticks and switch (RC_DATA's
  channels ``serial.ll.rc_channels``; the switch from LL_STATUS's flightMode 0x20).
  Commands go out at once as ``>*>di`` (:func:`~groundstation.asctec.ll.encode_command`);
  while armed the keep-alive (:class:`~groundstation.asctec.keepalive.CommandSchedule`,
  with the configured fallback time as its watchdog) guarantees the command rate.

Missing or corrupt acknowledgements and unanswered polls are counted and reported
(:meth:`LlLink.stats`), never fatal: a vehicle that stops answering is a link loss the
flight's supervisor sees as a stale data stream.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from dataclasses import dataclass

import structlog

from groundstation.asctec.blocks import AxisCounts, RcBlock, StatusBlock
from groundstation.asctec.crc import DEFAULT_PROFILE, profile_init
from groundstation.asctec.decoder import Ack
from groundstation.asctec.keepalive import CommandSchedule
from groundstation.asctec.link import PortLink, ReceivedData, _link_error
from groundstation.asctec.ll import (
    ImuRawData,
    LlDecoder,
    LlStatus,
    PollMask,
    RcData,
    RepeatCounter,
    encode_command,
    encode_poll,
)
from groundstation.asctec.messages import CommandMsg, DataMsg, Message
from groundstation.asctec.params import LinkParams
from groundstation.asctec.stats import DataStreamMonitor, LinkStats
from groundstation.errors import ConfigError, LinkError

_log = structlog.get_logger("groundstation.asctec")

ACK_MARGIN_S = 0.010
"""How much longer than the longest recent poll round trip an acknowledgement may take
before it counts as lost [s]."""

_ANSWER_OF = {PollMask.IMU_RAWDATA: ImuRawData.DESCRIPTOR,
              PollMask.LL_STATUS: LlStatus.DESCRIPTOR, PollMask.RC_DATA: RcData.DESCRIPTOR}


@dataclass
class _Outstanding:
    """A poll whose answers have not all arrived: its send time and the descriptors owed."""

    t: float
    owed: set[int]


class PollSchedule:
    """When to poll and for what, taking turns with the vehicle, and the bookkeeping of
    answers and acknowledgements. Times are monotonic seconds; nothing here reads a clock.

    period : IMU poll period [s]; status_every, rc_every : LL_STATUS / RC_DATA with every
    n-th poll (the first poll asks for both; RC_DATA half its period after LL_STATUS, so
    the two ride on different polls when the periods are equal); answer_timeout : a
    poll's answers not all in by then count it unanswered [s]; ack_timeout : likewise
    for a command's acknowledgement [s].

    Turn-taking: a due poll waits while the previous poll's answers or the last command's
    acknowledgement are still owed, but at most half a period past its slot on the grid;
    then it goes out anyway (the answers of a radio with a round trip longer than the
    period are then pipelined), so the IMU rate holds whatever the latency. Answers and
    acknowledgements come back in order and carry no reference: an answer settles the
    oldest poll that owes it; an acknowledgement settles the oldest command owed, and a
    command older than the longest recent poll round trip plus :data:`ACK_MARGIN_S`
    (at most ``ack_timeout``) lost its acknowledgement. So a round trip longer than the
    command period (a radio) needs no guess, and a lost acknowledgement shifts the
    matching for at most the one command sent right after it.
    """

    def __init__(self, period: float, *, status_every: int = 10, rc_every: int = 10,
                 answer_timeout: float = 0.08, ack_timeout: float = 0.08,
                 history: int = 4096) -> None:
        if not (period > 0 and status_every >= 1 and rc_every >= 1 and answer_timeout > 0
                and ack_timeout > 0):
            raise ConfigError("poll schedule: period and timeouts > 0, every >= 1 required")
        self.period = period
        self.status_every = status_every
        self.rc_every = rc_every
        self.answer_timeout = answer_timeout
        self.ack_timeout = ack_timeout
        self._next: float | None = None
        self._polls: deque[_Outstanding] = deque()
        self._unacked: deque[float] = deque()
        self.ack_times: deque[float] = deque(maxlen=history)
        self._recent_rtts: deque[float] = deque(maxlen=63)
        self.polls_sent = 0
        self.polls_unanswered = 0
        self.acks = 0
        self.acks_missing = 0
        self.acks_unexpected = 0

    @property
    def running(self) -> bool:
        """True once :meth:`start` was called."""
        return self._next is not None

    def start(self, t: float) -> None:
        """Begin polling at ``t`` (no-op if running)."""
        if self._next is None:
            self._next = t

    def poll_due(self, t: float) -> int | None:
        """The mask to poll at ``t``, or None: not yet time, or the vehicle has the turn.

        The caller writes the poll at once."""
        self._expire(t)
        if self._next is None or t < self._next:
            return None
        if self._vehicle_has_turn() and t < self._next + 0.5 * self.period:
            return None
        k = self.polls_sent
        mask = PollMask.IMU_RAWDATA
        if k % self.status_every == 0:
            mask |= PollMask.LL_STATUS
        if k == 0 or k % self.rc_every == self.rc_every // 2:
            mask |= PollMask.RC_DATA  # between the status polls: no 110-byte bursts
        self.polls_sent += 1
        self._polls.append(_Outstanding(t, {d for bit, d in _ANSWER_OF.items() if mask & bit}))
        while self._next <= t:  # the next slot on the grid; missed slots are skipped
            self._next += self.period
        return int(mask)

    def _vehicle_has_turn(self) -> bool:
        return bool(self._polls) or bool(self._unacked)

    def answered(self, descriptor: int, t: float) -> None:
        """A packet with ``descriptor`` arrived at ``t``: it answers the oldest poll owing
        one (an IMU answer also measures the poll's round trip)."""
        for poll in self._polls:
            if descriptor in poll.owed:
                poll.owed.discard(descriptor)
                if descriptor == ImuRawData.DESCRIPTOR:
                    self._recent_rtts.append(t - poll.t)
                break
        while self._polls and not self._polls[0].owed:
            self._polls.popleft()

    def command_sent(self, t: float) -> None:
        """A command was written at ``t``: its acknowledgement is owed."""
        self._unacked.append(t)

    def acked(self, t: float) -> None:
        """An acknowledgement arrived at ``t`` (see the class docstring for which command
        it settles)."""
        self._expire(t)
        if not self._unacked:
            self.acks_unexpected += 1
            return
        age = t - self._unacked.popleft()
        self.acks += 1
        self.ack_times.append(age)

    def _ack_deadline(self) -> float:
        """How old a command may get before its acknowledgement counts as lost [s]: the
        longest recent poll round trip plus :data:`ACK_MARGIN_S` (an acknowledgement can
        wait behind a poll's answers on the line), at most ``ack_timeout``; ``ack_timeout``
        before any poll was answered."""
        if not self._recent_rtts:
            return self.ack_timeout
        return min(self.ack_timeout, max(self._recent_rtts) + ACK_MARGIN_S)

    def _expire(self, t: float) -> None:
        deadline = self._ack_deadline()
        while self._unacked and t - self._unacked[0] > deadline:
            self._unacked.popleft()
            self.acks_missing += 1
        while self._polls and t - self._polls[0].t > self.answer_timeout:
            self._polls.popleft()
            self.polls_unanswered += 1

    def next_deadline(self) -> float | None:
        """The next time :meth:`poll_due` may return a mask (None before :meth:`start`)."""
        if self._next is None:
            return None
        if self._vehicle_has_turn():
            return self._next + 0.5 * self.period  # sooner when the vehicle answers
        return self._next


@dataclass(frozen=True, slots=True)
class RcMap:
    """Where the pilot's sticks are in RC_DATA's channels_out (0..4095, 2048 centre)."""

    pitch: int = 0
    roll: int = 1
    thrust: int = 2
    yaw: int = 3


def _stick(value: int) -> int:
    return min(max(value - 2048, -2048), 2047)


class LlLink(PortLink):
    """Serial link to an AscTec LL vehicle with :class:`~groundstation.asctec.link.SerialLink`'s
    interface (see the module docstring). Raises LinkError if the port cannot be opened."""

    def __init__(self, url: str, *, baudrate: int = 57600, profile: str = DEFAULT_PROFILE,
                 period: float = 0.01, command_rate: float = 50.0, stale_after: float = 0.25,
                 keepalive_slack: float = 0.0, fallback: float = 0.1, status_every: int = 10,
                 rc_every: int = 10, answer_timeout: float = 0.08, ack_timeout: float = 0.08,
                 rc_map: RcMap = RcMap(), queue_size: int = 256, rate_window: float = 1.0,
                 write_timeout: float = 1.0) -> None:
        profile_init(profile)
        self._decoder = LlDecoder(profile)
        self._monitor = DataStreamMonitor(rate_window=rate_window)
        self._polls = PollSchedule(period, status_every=status_every, rc_every=rc_every,
                                   answer_timeout=answer_timeout, ack_timeout=ack_timeout)
        self._commands = CommandSchedule(command_rate=command_rate, stale_after=stale_after,
                                         slack=keepalive_slack, watchdog=fallback)
        self._rc_map = rc_map
        self._repeats = RepeatCounter()
        self._queue: deque[ReceivedData] = deque(maxlen=queue_size)
        self._status: LlStatus | None = None
        self._status_t = -float("inf")
        self._rc: RcData | None = None
        self._new_status = False
        self._new_rc = False
        self._last_ctrl = 0
        self._armed = False
        self._flew = False
        self._queue_dropped = 0
        self._bytes_out = 0
        # the port opens here; _cond guards schedules, decoder, queue, writes, counters
        super().__init__(url, baudrate, write_timeout, "ll")
        self._writer = threading.Thread(target=self._write_loop, name=f"ll-writer {url}",
                                        daemon=True)
        self._start_reader()
        self._writer.start()

    @classmethod
    def from_params(cls, params: LinkParams) -> LlLink:
        """A link to an LL vehicle as ``params`` describe it (``protocol: asctec-ll``)."""
        ll = params.ll
        period = 1.0 / params.command_rate_hz
        slack = max(0.0, min(params.data_period_ms / 1000.0, ll.fallback_s / 2 - period))
        return cls(params.port, baudrate=params.baud, profile=params.crc_profile,
                   period=params.data_period_ms / 1000.0, command_rate=params.command_rate_hz,
                   stale_after=params.stale_command_s, keepalive_slack=slack,
                   fallback=ll.fallback_s, status_every=ll.status_every, rc_every=ll.rc_every,
                   answer_timeout=ll.answer_timeout_s, ack_timeout=ll.ack_timeout_s,
                   rc_map=RcMap(*ll.rc_channels))

    # --- the VehicleLink interface --------------------------------------------------

    @property
    def flew(self) -> bool:
        """True once a command with a non-zero ctrl mask was written."""
        return self._flew

    @property
    def armed(self) -> bool:
        """True while the keep-alive guarantees the command rate."""
        return self._armed

    def start_stream(self) -> None:
        """Start polling (the LL vehicle sends nothing unpolled); idempotent."""
        self._check_usable()
        with self._cond:
            self._polls.start(time.monotonic())
            self._cond.notify_all()

    def send(self, msg: Message) -> None:
        """Write a command now (``>*>di``); it also becomes the keep-alive's command.
        Anything else is an X-3D message this dialect does not have: ConfigError."""
        if not isinstance(msg, CommandMsg):
            raise ConfigError(f"the AscTec LL dialect has no {type(msg).__name__}: only "
                              "commands are sent (the data stream is polled)")
        self._check_usable()
        with self._cond:
            t = self._write_command(msg)
            self._commands.loop_command(msg, t)

    def arm(self) -> None:
        """Start the keep-alive guarantee (no-op if armed)."""
        self._check_usable()
        with self._cond:
            if not self._armed:
                self._armed = True
                self._commands.arm(time.monotonic())
                self._cond.notify_all()

    def disarm(self) -> None:
        """Stop the keep-alive and send a command with ctrl mask 0."""
        with self._cond:
            self._armed = False
            self._commands.disarm()
        self.send(CommandMsg.release())

    def command_write_times(self) -> tuple[float, ...]:
        """Monotonic times [s] of the most recent command writes, oldest first."""
        with self._cond:
            return self._commands.write_times()

    def wait_status(self, timeout: float, newer_than: float = -float("inf")) -> LlStatus | None:
        """The vehicle's last LL_STATUS received after ``newer_than`` (monotonic [s]),
        waiting up to ``timeout`` [s] for one; None if none came (polling must run)."""
        deadline = time.monotonic() + timeout
        with self._cond:
            while self._status is None or self._status_t <= newer_than:
                self._check_usable()
                remaining = deadline - time.monotonic()
                if remaining <= 0.0:
                    return None
                self._cond.wait(remaining)
            return self._status

    def stats(self) -> LinkStats:
        """A consistent snapshot of the link's counters."""
        with self._cond:
            counts = self._decoder.counts()
            m, p, c = self._monitor, self._polls, self._commands
            return LinkStats(
                bytes_in=counts.bytes_in, bytes_out=self._bytes_out, frames=counts.frames,
                rejections=counts.rejections, bytes_skipped=counts.bytes_skipped,
                data_rate_hz=m.rate(time.monotonic()), counter_gaps=m.counter_gaps,
                samples_missed=m.samples_missed, counter_repeats=m.counter_repeats,
                queue_dropped=self._queue_dropped, commands_sent=c.commands_sent,
                keepalive_resends=c.resends, keepalive_releases=c.releases,
                max_command_gap=c.max_gap, command_gap_warnings=c.gap_warnings,
                polls_sent=p.polls_sent, polls_unanswered=p.polls_unanswered, acks=p.acks,
                acks_missing=p.acks_missing, acks_unexpected=p.acks_unexpected,
                ack_times=tuple(p.ack_times))

    def close(self) -> None:
        """Stop polling and the keep-alive, send a final mask-0 command if this link flew
        the vehicle, stop the threads, close the port. Idempotent; never raises."""
        with self._cond:
            if self._closed:
                return
            self._closed = True
            self._armed = False
            self._commands.disarm()
            if self._flew and self._error is None:
                try:
                    self._write_command(CommandMsg.release())
                except LinkError as exc:
                    _log.warning("final mask-0 command not sent", url=self.url, error=str(exc))
            self._stop.set()
            self._cond.notify_all()
        self._writer.join()
        self._close_port()

    # --- internals ------------------------------------------------------------------

    def _write(self, data: bytes) -> float:
        """Write ``data`` (caller holds the lock); returns the write time [s]."""
        try:
            self._port.write(data)
        except Exception as exc:
            error = _link_error(f"write to {self.url!r} failed", exc)
            self._error = self._error or error
            self._cond.notify_all()
            raise error from exc
        self._bytes_out += len(data)
        return time.monotonic()

    def _write_command(self, msg: CommandMsg) -> float:
        t = self._write(encode_command(msg))
        self._flew = self._flew or msg.ctrl != 0
        self._last_ctrl = msg.ctrl
        self._polls.command_sent(t)
        self._commands.record_write(t)
        return t

    def _write_loop(self) -> None:
        """Writer thread: polls on the schedule, keep-alive commands while armed."""
        try:
            with self._cond:
                while not self._stop.is_set():
                    now = time.monotonic()
                    mask = self._polls.poll_due(now)
                    if mask is not None:
                        self._write(encode_poll(mask))
                    if self._armed:
                        cmd = self._commands.due(now)
                        if cmd is not None:
                            self._write_command(cmd)
                    deadlines = [d for d in (self._polls.next_deadline(),
                                             self._commands.next_deadline() if self._armed
                                             else None) if d is not None]
                    wait = min(deadlines) - time.monotonic() if deadlines else 0.1
                    if wait > 0:
                        self._cond.wait(wait)
        except Exception as exc:  # any failure must surface to the user, never vanish
            if not self._stop.is_set():
                self._fail(_link_error(f"polling {self.url!r} failed", exc))

    def _on_bytes(self, chunk: bytes, t: float) -> None:
        with self._cond:
            for item in self._decoder.feed(chunk):
                if isinstance(item, Ack):
                    self._polls.acked(t)
                elif isinstance(item, ImuRawData):
                    self._polls.answered(item.DESCRIPTOR, t)
                    self._queue_sample(t, item)
                elif isinstance(item, LlStatus):
                    self._polls.answered(item.DESCRIPTOR, t)
                    self._status, self._new_status = item, True
                    self._status_t = t
                elif isinstance(item, RcData):
                    self._polls.answered(item.DESCRIPTOR, t)
                    self._rc, self._new_rc = item, True
            self._cond.notify_all()  # the turn may have come back to the host

    def _queue_sample(self, t: float, raw: ImuRawData) -> None:
        counter = self._repeats.update(raw.values())
        self._monitor.update(counter, t)
        status = rc = None
        if self._new_status or self._new_rc:
            status, rc = self._blocks()
            self._new_status = self._new_rc = False
        msg = DataMsg(counter, status, AxisCounts(*raw.gyro), AxisCounts(*raw.acc), raw.pressure,
                      rc)
        if len(self._queue) == self._queue.maxlen:
            self._queue_dropped += 1
        self._queue.append(ReceivedData(t, msg))

    def _blocks(self) -> tuple[StatusBlock | None, RcBlock | None]:
        """The X-3D STATUS and RC blocks the LL vehicle's last LL_STATUS and RC_DATA say."""
        st, rc = self._status, self._rc
        status = None
        if st is not None:
            flags = (int(st.serial_active) | int(bool(st.motors_on)) << 1
                     | int(rc is None or bool(rc.lock)) << 2)
            status = StatusBlock(min(max(st.battery_mv_1, 0), 0xFFFF), flags,
                                 self._last_ctrl if st.serial_active else 0)
        switch = 4095 if st is not None and st.serial_enabled else 0
        if rc is None:
            return status, (RcBlock(0, 0, 0, 0, switch) if st is not None else None)
        ch, m = rc.channels_out, self._rc_map
        return status, RcBlock(_stick(ch[m.pitch]), _stick(ch[m.roll]), _stick(ch[m.yaw]),
                               min(max(ch[m.thrust], 0), 4096), switch)
