"""One interface to the vehicle whichever serial dialect it speaks.

The ground station speaks two dialects: the X-3D's (``docs/protocol.md``:
configured once, the vehicle pushes DATA) and the AscTec AutoPilot LL's (polled; see
:mod:`groundstation.asctec.ll`). A dialect is a codec plus a link schedule behind
:class:`VehicleLink` (as python-can's interfaces sit behind ``BusABC``), chosen by
``serial.protocol`` and never guessed from the bytes: :func:`open_link`. The flight loop
sees the same IMU sample and vehicle status from either.
"""

from __future__ import annotations

from types import TracebackType
from typing import TYPE_CHECKING, Protocol

from groundstation.asctec.link import ReceivedData, SerialLink
from groundstation.asctec.ll_link import LlLink
from groundstation.asctec.messages import Message
from groundstation.asctec.stats import LinkStats
from groundstation.errors import LinkError

if TYPE_CHECKING:
    from groundstation.config import SerialConfig

DIALECTS = ("x3d", "asctec-ll")
"""The ``serial.protocol`` values."""


class VehicleLink(Protocol):
    """What the flight loop uses of a serial link, whichever the dialect.

    ``get`` returns each IMU sample as a :class:`ReceivedData` (receive time, and a
    :class:`~groundstation.asctec.messages.DataMsg` with the raw gyro and acc counts, the
    sample counter and, when the vehicle reported them, its status and the pilot's
    sticks); ``send`` writes a command now and makes it the keep-alive's; while
    :attr:`armed` the link guarantees the command rate; ``close`` hands the vehicle back
    (a final ctrl mask 0) if this link flew it.
    """

    url: str

    @property
    def error(self) -> LinkError | None:
        """A background thread's failure (the link is then unusable)."""
        ...

    @property
    def flew(self) -> bool:
        """A command with a non-zero ctrl mask was written."""
        ...

    @property
    def armed(self) -> bool:
        """The keep-alive guarantees the command rate."""
        ...

    def start_stream(self) -> None:
        """Ask the vehicle for its data (again): X-3D CONFIG, or start the LL polls."""
        ...

    def get(self, timeout: float) -> ReceivedData | None:
        """The oldest IMU sample within ``timeout`` [s], else None."""
        ...

    def send(self, msg: Message) -> None:
        """Write ``msg`` (a command) now."""
        ...

    def arm(self) -> None:
        """Start the keep-alive."""
        ...

    def disarm(self) -> None:
        """Stop the keep-alive and send ctrl mask 0."""
        ...

    def command_write_times(self) -> tuple[float, ...]:
        """Recent command write times [s]."""
        ...

    def stats(self) -> LinkStats:
        """The link's counters."""
        ...

    def close(self) -> None:
        """Hand back if flown, stop, close the port (idempotent, never raises)."""
        ...

    def __enter__(self) -> VehicleLink: ...

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None: ...


def open_link(config: SerialConfig) -> VehicleLink:
    """Open the link of the configured dialect (``serial.protocol``); LinkError if the port
    cannot be opened."""
    if config.protocol == "asctec-ll":
        return LlLink.from_config(config)
    return SerialLink.from_config(config)
