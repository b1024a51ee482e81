"""System identification from flight logs: the rate loop and the IMU scales.

* :func:`identify_rates` fits each body axis's stick-to-rate gain, transport delay and
  rate-loop time constant (thesis eq. 3.22, Ch. 3.3.1, Fig. 3.8) to the recorded
  COMMANDs and gyro (:mod:`.rates`).
* :func:`identify_scales` fits the gyro and accelerometer scale factors (Table 6.2)
  against the body rates and specific force that Vicon's poses in the same log imply
  (:mod:`.scales`).

The flight that feeds them is the identification flight, ``gs fly --trajectory sysid``
(:mod:`groundstation.control.excitation`: doublets on each rate stick within the
configured limits, climbs and descents); a refusal for want of excitation recommends
it (:data:`~groundstation.identification.rates.SYSID_HINT`), and its log passes them all.

Both read a flight directory written by :class:`groundstation.app.recorder.FlightRecorder`
and its configuration, return frozen records with ``config_fields()`` (values keyed by
the configuration's field paths), ``summary()`` and ``figure(path)``, and raise
:class:`~groundstation.errors.IdentificationError` (a
:class:`~groundstation.errors.GroundStationError`) with a message naming the axis when
a log cannot determine what was asked.
"""

from groundstation.errors import IdentificationError
from groundstation.identification.rates import (
    AXES,
    AxisRateFit,
    FlightLog,
    RateFit,
    RateSeries,
    identify_rates,
    load_flight_log,
)
from groundstation.identification.scales import (
    SCALE_AXES,
    AxisScaleFit,
    ScaleFit,
    identify_scales,
)

__all__ = [
    "AXES",
    "SCALE_AXES",
    "AxisRateFit",
    "AxisScaleFit",
    "FlightLog",
    "IdentificationError",
    "RateFit",
    "RateSeries",
    "ScaleFit",
    "identify_rates",
    "identify_scales",
    "load_flight_log",
]
