"""Fly from your own code: a client of a running ``gs fly --trajectory none`` daemon.

A daemon started with ``--trajectory none`` takes off to ``trajectory.center`` and holds
there; a client then moves it with :meth:`Client.go_to`, :meth:`Client.follow`,
:meth:`Client.hold` and :meth:`Client.land`. The ground station stays in charge: it
plans every motion within the configured limits and volume and refuses one it cannot
fly (:class:`Refused` and its subclasses say why); a failsafe always takes over from a
motion (:class:`Preempted`); a client that goes away leaves the vehicle finishing its
checked motion and then holding, and the daemon lands after ``api.idle_land_s`` without
a command.

Frames and units are the project's: positions NED [m] in the lab's frame (from
Tracker's origin on the floor, not from the take-off point; :meth:`Client.takeoff`'s
height alone is above the take-off point; 1 m above the floor is
``z = -1``), times [s], and headings in degrees from north, clockwise seen from above,
as everywhere a user gives one (``trajectory.yaw_deg``, ``gs goto --yaw``, a waypoint
CSV's ``yaw_deg`` column): ``go_to(..., yaw_deg=90)`` faces east, and the replies report
``yaw_deg``, ``reference_yaw_deg`` and ``target_yaw_deg``. (Until this release the client
took and reported radians: the ``yaw=`` keyword and the ``yaw``, ``reference_yaw`` and
``target_yaw`` attributes still work, in radians, with a DeprecationWarning. The wire
format, :mod:`groundstation.app.api`, stays in radians.)

Example (``examples/fly_square.py`` flies a square)::

    from groundstation.client import Client

    gs = Client()  # nothing to close: every request opens and closes its own socket
    gs.wait_for_state("TRACK", timeout=30)
    gs.go_to([0.5, 0.0, -1.0], yaw_deg=90, wait=True)
    gs.land(wait=True)

Every request is one JSON message on the daemon's request socket
(``telemetry.control_endpoint``; see :mod:`groundstation.app.api` for the wire format);
a daemon that authenticates clients needs ``server_key`` and ``client_key`` (CURVE).

A fleet's daemons (``gs fleet up``, README "Fleet") take the same requests over Zenoh:
:class:`Fleet` opens one session to every vehicle its fleet file lists, ``fleet[name]``
is a :class:`FleetVehicle` with every method of :class:`Client`, and a refusal for the
fleet's separation is :class:`TooClose`.

Modules: :mod:`.vehicle` (:class:`Client` and its replies and refusals), :mod:`.fleet`
(:class:`Fleet`, :class:`FleetVehicle`; imported on first use, below).
"""

from typing import TYPE_CHECKING, Any

from groundstation.client.vehicle import (
    DEFAULT_CONTROL,
    DEFAULT_TELEMETRY,
    DEFAULT_TIMEOUT_S,
    ENDED_STATES,
    FAILSAFE_STATES,
    PLAN_WAIT_S,
    POLL_S,
    BadRequest,
    Busy,
    Client,
    ClientError,
    DaemonUnreachableError,
    Ended,
    Infeasible,
    InternalError,
    Motion,
    NotNow,
    OutsideVolume,
    Preempted,
    Refused,
    Status,
    TooClose,
    WaitTimeout,
)

if TYPE_CHECKING:  # the fleet's client, imported on first use (``__getattr__`` below)
    from groundstation.client.fleet import Fleet as Fleet
    from groundstation.client.fleet import FleetVehicle as FleetVehicle

__all__ = [
    "DEFAULT_CONTROL",
    "DEFAULT_TELEMETRY",
    "DEFAULT_TIMEOUT_S",
    "ENDED_STATES",
    "FAILSAFE_STATES",
    "PLAN_WAIT_S",
    "POLL_S",
    "BadRequest",
    "Busy",
    "Client",
    "ClientError",
    "DaemonUnreachableError",
    "Ended",
    "Fleet",
    "FleetVehicle",
    "Infeasible",
    "InternalError",
    "Motion",
    "NotNow",
    "OutsideVolume",
    "Preempted",
    "Refused",
    "Status",
    "TooClose",
    "WaitTimeout",
]


def __getattr__(name: str) -> Any:
    """``Fleet`` and ``FleetVehicle``: a fleet's vehicles over Zenoh (:mod:`.fleet`),
    Client's methods for each vehicle and fleet-wide requests. Imported on first use: they
    need the fleet's configuration and sessions (and the fleet extra once a Fleet opens
    its session), which a client of one vehicle does without."""
    if name in ("Fleet", "FleetVehicle"):
        from groundstation.client import fleet

        return getattr(fleet, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
