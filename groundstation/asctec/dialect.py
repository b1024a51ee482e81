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
from typing import Protocol, get_args

from groundstation.asctec.blocks import DATA_SIZE_BY_MASK
from groundstation.asctec.decoder import FRAME_OVERHEAD
from groundstation.asctec.link import ReceivedData, SerialLink
from groundstation.asctec.ll import COMMAND_SIZE, ImuRawData
from groundstation.asctec.ll_link import LlLink
from groundstation.asctec.messages import CommandMsg, Message
from groundstation.asctec.params import LinkParams
from groundstation.asctec.stats import LinkStats
from groundstation.errors import LinkError
from groundstation.types import Dialect

DIALECTS: tuple[Dialect, ...] = get_args(Dialect)
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


def open_link(params: LinkParams) -> VehicleLink:
    """Open the link of the configured dialect (``serial.protocol``); LinkError if the port
    cannot be opened."""
    if params.protocol == "asctec-ll":
        return LlLink.from_params(params)
    return SerialLink.from_params(params)


def wire_time_s(params: LinkParams) -> float:
    """Time [s] one DATA frame (of the configured blocks) and one COMMAND frame spend on
    the serial wire at the configured baud: 10 bits per byte (8N1), frame = N + 11
    bytes (spec sections 1 and 3); in the AscTec LL dialect an IMU_RAWDATA frame (39
    bytes) and a 17-byte command."""
    if params.protocol == "asctec-ll":  # IMU_RAWDATA frame, unframed `>*>di` command
        data_bytes = max(ImuRawData.PAYLOAD_SIZES) + FRAME_OVERHEAD
        command_bytes = COMMAND_SIZE
    else:
        data_bytes = DATA_SIZE_BY_MASK[params.sensor_mask] + FRAME_OVERHEAD
        command_bytes = max(CommandMsg.PAYLOAD_SIZES) + FRAME_OVERHEAD
    return 10.0 * (data_bytes + command_bytes) / params.baud
