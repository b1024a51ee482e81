"""COMMAND keep-alive policy and COMMAND gap bookkeeping (sans-IO).

The X-3D hands every channel back to the pilot when no valid COMMAND has
arrived for 100 ms (spec section 4). While the link is *armed*, a COMMAND must
therefore go out at least every ``1 / command_rate + slack`` seconds whatever the
control loop does. The slack lets a loop whose COMMANDs are a little late (they
follow the DATA frames, which jitter) send them itself instead of racing a
keep-alive copy onto the wire just before its own. :class:`CommandSchedule`
decides, given the time, whether the keep-alive must write and what:

* the loop's last command, while it is fresh (written less than
  ``stale_after`` seconds ago);
* otherwise COMMAND with ctrl mask 0 (every channel to the pilot). Safety
  decision: a dead or stuck control loop hands the vehicle back instead of
  freezing its last stick values for ever.

It also records every COMMAND write time, the longest gap while armed, and logs
a structlog warning when a gap exceeds half the watchdog. The link's sender
thread (:mod:`groundstation.asctec.link`) is the only I/O around it.
"""

from __future__ import annotations

from collections import deque
from typing import Final

import structlog

from groundstation.asctec.messages import CommandMsg
from groundstation.errors import ConfigError

WATCHDOG_S: Final = 0.1
"""The X-3D's command watchdog [s] (spec section 4)."""

GAP_WARNING_S: Final = WATCHDOG_S / 2
"""COMMAND gaps longer than this are logged as warnings [s]."""

_RELEASE: Final = CommandMsg.release()


class CommandSchedule:
    """When to re-send a COMMAND, and which one. Times are monotonic seconds.

    Parameters
    ----------
    command_rate : minimum COMMAND rate while armed [Hz]; its period must be
        shorter than the 100 ms watchdog (rate > 10 Hz).
    stale_after : age of the loop's last command after which the keep-alive
        sends ctrl mask 0 instead [s] (> 0).
    slack : the keep-alive writes only when no COMMAND went out for
        ``1 / command_rate + slack`` [s] (>= 0; the sum must stay under the watchdog).
    history : number of recent COMMAND write times kept.
    logger : structlog logger for gap warnings.
    watchdog : the vehicle's fallback after the last command [s] (the X-3D's 100 ms;
        the AscTec LL dialect's is configured, ``serial.ll.fallback_ms``).
    """

    def __init__(
        self,
        *,
        command_rate: float,
        stale_after: float = 0.25,
        slack: float = 0.0,
        history: int = 256,
        logger: structlog.typing.FilteringBoundLogger | None = None,
        watchdog: float = WATCHDOG_S,
    ) -> None:
        if not command_rate > 1.0 / watchdog:
            raise ConfigError(f"command_rate must exceed {1.0 / watchdog:g} Hz (watchdog), "
                              f"got {command_rate!r}")
        if not stale_after > 0.0:
            raise ConfigError(f"stale_after must be > 0 s, got {stale_after!r}")
        if not (slack >= 0.0 and 1.0 / command_rate + slack < watchdog):
            raise ConfigError(f"slack must be >= 0 s and leave the keep-alive period under "
                              f"the watchdog, got {slack!r}")
        self.period = 1.0 / command_rate
        self.gap_warning = watchdog / 2
        self.slack = float(slack)
        self.stale_after = float(stale_after)
        self._log = logger if logger is not None else structlog.get_logger("groundstation.asctec")
        self._armed_at: float | None = None
        self._loop_cmd: CommandMsg | None = None
        self._loop_t = float("-inf")
        self._last_write: float | None = None
        self._write_times: deque[float] = deque(maxlen=history)
        self.commands_sent = 0
        self.resends = 0
        self.releases = 0
        self.max_gap = 0.0
        self.gap_warnings = 0

    @property
    def armed(self) -> bool:
        """True while the keep-alive guarantee is in force."""
        return self._armed_at is not None

    def arm(self, t: float) -> None:
        """Start guaranteeing the command rate at ``t`` (the first keep-alive is due at once
        unless a COMMAND was written within the last period)."""
        self._armed_at = t
        self.max_gap = 0.0

    def disarm(self) -> None:
        """Stop the guarantee (the caller then sends the final mask-0 COMMAND)."""
        self._armed_at = None

    def loop_command(self, msg: CommandMsg, t: float) -> None:
        """The control loop wrote ``msg`` at ``t`` (call :meth:`record_write` too)."""
        self._loop_cmd = msg
        self._loop_t = t

    def next_deadline(self) -> float | None:
        """Time the next keep-alive COMMAND is due, or None when disarmed."""
        if self._armed_at is None:
            return None
        if self._last_write is None:
            return self._armed_at
        return max(self._armed_at, self._last_write + self.period + self.slack)

    def due(self, t: float) -> CommandMsg | None:
        """The COMMAND the keep-alive must write at ``t``, or None if none is due yet.

        The caller writes it and calls :meth:`record_write`.
        """
        deadline = self.next_deadline()
        if deadline is None or t < deadline:
            return None
        if self._loop_cmd is not None and t - self._loop_t < self.stale_after:
            self.resends += 1
            return self._loop_cmd
        self.releases += 1
        return _RELEASE

    def record_write(self, t: float) -> float | None:
        """Account a COMMAND written at ``t``; returns the gap since the previous one [s]."""
        last = self._last_write
        self._last_write = t
        self._write_times.append(t)
        self.commands_sent += 1
        if last is None:
            return None
        gap = t - last
        if self._armed_at is not None and last >= self._armed_at:
            self.max_gap = max(self.max_gap, gap)
            if gap > self.gap_warning:
                self.gap_warnings += 1
                self._log.warning(
                    "command gap exceeds half the watchdog",
                    gap_s=round(gap, 4),
                    limit_s=self.gap_warning,
                )
        return gap

    def write_times(self) -> tuple[float, ...]:
        """Recent COMMAND write times [s], oldest first."""
        return tuple(self._write_times)
