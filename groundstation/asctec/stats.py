"""Link statistics: DATA stream health (sans-IO) and the link's snapshot record.

:class:`DataStreamMonitor` watches the DATA sample counter (uint16, +1 per
sample, wraps at 65536) for gaps (samples lost on the radio) and repeats (the
thesis saw corrupted frames as repeated samples), and measures the DATA rate
over a sliding window. Times are passed in (monotonic seconds).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass

from groundstation.errors import ConfigError


class DataStreamMonitor:
    """Counter gaps/repeats and sliding-window rate of a DATA stream.

    Parameters
    ----------
    rate_window : length of the rate window [s] (> 0).
    """

    def __init__(self, *, rate_window: float = 1.0) -> None:
        if not rate_window > 0.0:
            raise ConfigError(f"rate_window must be > 0 s, got {rate_window!r}")
        self._window = float(rate_window)
        self._times: deque[float] = deque()
        self._last_counter: int | None = None
        self.counter_gaps = 0
        """Number of jumps of more than +1 in the counter."""
        self.samples_missed = 0
        """Samples skipped over by those jumps (sum of jump - 1)."""
        self.counter_repeats = 0
        """Samples whose counter equals the previous one."""

    def update(self, counter: int, t: float) -> None:
        """Account one DATA sample with ``counter`` received at ``t`` [s]."""
        last = self._last_counter
        if last is not None:
            step = (counter - last) & 0xFFFF
            if step == 0:
                self.counter_repeats += 1
            elif step > 1:
                self.counter_gaps += 1
                self.samples_missed += step - 1
        self._last_counter = counter
        times = self._times
        times.append(t)
        horizon = t - self._window
        while times[0] <= horizon:
            times.popleft()

    def rate(self, now: float) -> float:
        """DATA rate [Hz]: samples received in ``(now - window, now]`` divided by the window."""
        horizon = now - self._window
        return sum(1 for t in self._times if horizon < t <= now) / self._window


@dataclass(frozen=True, slots=True)
class LinkStats:
    """Snapshot of a serial link's counters.

    bytes_in, bytes_out : bytes read from / written to the port
    frames : accepted frames by message name ("data", "config", "command")
    rejections : rejected frame candidates by reason (decoder.RejectReason values)
    bytes_skipped : received bytes that were not part of an accepted frame
    data_rate_hz : DATA frames per second over the last ``rate_window`` [Hz]
    counter_gaps, samples_missed, counter_repeats : DATA counter health
    queue_dropped : DATA samples dropped because the delivery queue was full
    commands_sent : COMMAND frames written (loop, keep-alive and final release)
    keepalive_resends : COMMANDs the keep-alive re-sent for the loop
    keepalive_releases : mask-0 COMMANDs the keep-alive sent for a stale loop
    max_command_gap : longest interval between COMMAND writes while armed [s]
    command_gap_warnings : gaps longer than half the 100 ms watchdog while armed
    unexpected_data : X-3D: DATA frames of another block mask than the one configured,
        dropped (an LL IMU_RAWDATA can look like one; spec hazard)
    polls_sent, polls_unanswered : LL dialect: polls written, and of those not answered
        completely within ``serial.ll.answer_timeout_ms``
    acks, acks_missing : LL dialect: commands acknowledged, and not acknowledged within
        ``serial.ll.ack_timeout_ms`` (corrupt acknowledgements are the ``bad_ack``
        rejections)
    acks_unexpected : LL dialect: acknowledgements that came when no command was owed one
        (its command had already counted as missing: a late acknowledgement)
    ack_times : LL dialect: recent command-to-acknowledgement times [s], oldest first
    """

    bytes_in: int
    bytes_out: int
    frames: Mapping[str, int]
    rejections: Mapping[str, int]
    bytes_skipped: int
    data_rate_hz: float
    counter_gaps: int
    samples_missed: int
    counter_repeats: int
    queue_dropped: int
    commands_sent: int
    keepalive_resends: int
    keepalive_releases: int
    max_command_gap: float
    command_gap_warnings: int
    unexpected_data: int = 0
    polls_sent: int = 0
    polls_unanswered: int = 0
    acks: int = 0
    acks_missing: int = 0
    acks_unexpected: int = 0
    ack_times: tuple[float, ...] = ()
