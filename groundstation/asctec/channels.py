"""Per-channel manual/automatic handover with bumpless transfer (sans-IO).

Each stick channel ("pitch", "roll", "yaw", "thrust") is either with the pilot
(its ctrl-mask bit clear) or under ground-station control (bit set). The set of
automatic channels can change at any time with :meth:`ChannelHandover.set_auto`.

Bumpless transfer: the first COMMAND composed after a channel is handed to the
controller sends exactly the pilot's current stick value. At that instant
``t0`` the handover records ``offset = pilot - controller`` and sends
``controller + offset * w(t)``, where ``w`` falls linearly from 1 at ``t0`` to 0
at ``t0 + blend_time``; afterwards the controller's value goes out unchanged.
A channel handed back to the pilot is cleared from the mask in the very next
COMMAND. Every value sent is clamped to the legal command range.

Time is passed in (monotonic seconds); nothing here reads a clock.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Final

from groundstation.asctec.messages import (
    CHANNEL_BITS,
    STICK_MAX,
    STICK_MIN,
    THRUST_MAX,
    THRUST_MIN,
    CommandMsg,
    channel_mask,
)
from groundstation.errors import ConfigError
from groundstation.types import CHANNELS, Channel, Sticks

_LIMITS: Final[dict[Channel, tuple[int, int]]] = {
    "pitch": (STICK_MIN, STICK_MAX),
    "roll": (STICK_MIN, STICK_MAX),
    "yaw": (STICK_MIN, STICK_MAX),
    "thrust": (THRUST_MIN, THRUST_MAX),
}


def clamp_channel(channel: Channel, value: float) -> int:
    """``value`` rounded to an integer and clamped to the channel's command range."""
    lo, hi = _LIMITS[channel]
    return min(hi, max(lo, round(value)))


class ChannelHandover:
    """Composes COMMANDs from controller and pilot sticks, channel by channel.

    Parameters
    ----------
    blend_time : time over which a handover offset decays to zero [s] (>= 0;
        0 switches to the controller's value at once).
    """

    def __init__(self, *, blend_time: float = 1.0) -> None:
        if not blend_time >= 0.0:
            raise ConfigError(f"blend_time must be >= 0 s, got {blend_time!r}")
        self._blend_time = float(blend_time)
        self._auto: frozenset[Channel] = frozenset()
        self._pending: set[Channel] = set()  # handed over, offset not yet recorded
        self._offsets: dict[Channel, tuple[float, float]] = {}  # channel -> (t0, offset)

    @property
    def auto_channels(self) -> frozenset[Channel]:
        """Channels under ground-station control."""
        return self._auto

    @property
    def mask(self) -> int:
        """The ctrl mask the next COMMAND will carry."""
        return sum(CHANNEL_BITS[c] for c in self._auto)

    def set_auto(self, channels: Iterable[Channel]) -> None:
        """Put exactly ``channels`` under ground-station control from the next COMMAND.

        Newly added channels blend in from the pilot's stick; channels already
        automatic keep their blend; removed channels go back to the pilot.
        Raises ProtocolError for an unknown channel name.
        """
        wanted = frozenset(channels)
        channel_mask(wanted)  # validates the names
        for gone in self._auto - wanted:
            self._pending.discard(gone)
            self._offsets.pop(gone, None)
        self._pending |= wanted - self._auto
        self._auto = wanted

    def compose(self, t: float, controller: Sticks, pilot: Sticks) -> CommandMsg:
        """The COMMAND to send at time ``t``.

        t : monotonic time [s]
        controller : the controller's sticks (RC units, thesis meaning; may be out of
            range, they are clamped)
        pilot : the pilot's current sticks (from the DATA RC block); automatic
            channels start from these, manual channels send them (ignored by the
            vehicle since their mask bit is clear)
        """
        values: dict[Channel, int] = {}
        for channel in CHANNELS:
            pilot_value: int = getattr(pilot, channel)
            if channel not in self._auto:
                values[channel] = clamp_channel(channel, pilot_value)
                continue
            ctrl_value: int = getattr(controller, channel)
            if channel in self._pending:
                self._pending.discard(channel)
                self._offsets[channel] = (t, float(pilot_value - ctrl_value))
            values[channel] = clamp_channel(channel, ctrl_value + self._blend(channel, t))
        return CommandMsg(
            pitch=values["pitch"],
            roll=values["roll"],
            yaw=values["yaw"],
            thrust=values["thrust"],
            ctrl=self.mask,
        )

    def blending(self, t: float) -> bool:
        """True while a channel handed to the controller still sends (part of) the pilot's
        offset at ``t``, or has not yet sent its first COMMAND."""
        if self._pending:
            return True
        return any(self._blend_time > 0.0 and t - t0 < self._blend_time
                   for t0, _offset in self._offsets.values())

    def _blend(self, channel: Channel, t: float) -> float:
        """The part of the handover offset still applied at ``t`` (linear decay)."""
        entry = self._offsets.get(channel)
        if entry is None:
            return 0.0
        t0, offset = entry
        if self._blend_time <= 0.0 or t - t0 >= self._blend_time:
            del self._offsets[channel]  # blend finished: controller value from now on
            return 0.0
        weight = 1.0 - max(0.0, t - t0) / self._blend_time
        return offset * weight
