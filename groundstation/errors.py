"""One exception root for the whole package.

Every error the package raises on purpose derives from :class:`GroundStationError`
and also from the builtin exception a caller would naturally catch, so
``except OSError`` still sees a lost serial port and ``except ValueError`` still
sees a bad configuration (python-can's ``can/exceptions.py`` pattern).
Third-party errors (pyserial, socket, zmq) are translated once, at the boundary
that touches them, with ``raise ... from exc``.

Tree::

    GroundStationError
    ├── ConfigError(ValueError)           bad configuration file or override
    ├── ProtocolError(ValueError)         a message that cannot be encoded (sender bug)
    ├── LinkError(OSError)                serial port could not be opened / read / written
    │   └── LinkTimeoutError(TimeoutError) no DATA within the expected time
    ├── ViconError(OSError)               UDP socket could not be bound or read
    ├── TelemetryError(OSError)           telemetry socket could not be bound or connected
    ├── FleetError(OSError)               the fleet's Zenoh session could not be opened or used
    ├── RecorderError(OSError)            flight log could not be written or read
    ├── EstimatorError(ArithmeticError)   estimator diverged or lost numerical soundness
    ├── ControlError                      controller could not be built or evaluated
    │   └── TrajectoryError(ValueError)   a trajectory that cannot be flown or parsed
    ├── IdentificationError(ValueError)   measurement data that cannot be fitted
    └── SafetyError                       the supervisor refused to fly (preflight failed)

Bad bytes on the wire are *not* exceptions: the decoders count and skip them.
"""

from __future__ import annotations


class GroundStationError(Exception):
    """Root of every exception the ground station raises on purpose."""


class ConfigError(GroundStationError, ValueError):
    """A configuration file or override is invalid.

    ``problems`` holds one ``(field_path, value, reason)`` tuple per problem;
    the message lists them one per line.
    """

    def __init__(self, message: str, problems: list[tuple[str, object, str]] | None = None):
        super().__init__(message)
        self.problems: list[tuple[str, object, str]] = problems or []


class ProtocolError(GroundStationError, ValueError):
    """A message could not be encoded, e.g. a command value out of its range."""


class LinkError(GroundStationError, OSError):
    """The serial link failed: the port could not be opened, read or written."""


class LinkTimeoutError(LinkError, TimeoutError):
    """The serial link delivered no data within the expected time."""


class ViconError(GroundStationError, OSError):
    """The Vicon UDP socket could not be bound or read."""


class TelemetryError(GroundStationError, OSError):
    """The telemetry (pyzmq) socket could not be bound or connected, or is closed."""


class FleetError(GroundStationError, OSError):
    """The fleet's Zenoh session could not be opened (a port taken, a certificate that
    cannot be read) or used (groundstation/fleet)."""


class RecorderError(GroundStationError, OSError):
    """A flight log could not be created, written or read."""


class EstimatorError(GroundStationError, ArithmeticError):
    """The estimator diverged or its covariance lost positive definiteness."""


class ControlError(GroundStationError):
    """A controller could not be designed or evaluated."""


class TrajectoryError(ControlError, ValueError):
    """A trajectory cannot be parsed or cannot be flown within the command limits."""


class IdentificationError(GroundStationError, ValueError):
    """Measurement data for system identification is missing or cannot be fitted."""


class SafetyError(GroundStationError):
    """The safety supervisor refused to fly, e.g. a failed preflight check."""
