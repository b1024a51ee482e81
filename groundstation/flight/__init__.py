"""The flight, without I/O: one tick in, one COMMAND out.

No threads, sockets, files or clocks here: time and data are passed in, so the real-time
daemon and the in-process runner (:mod:`groundstation.app`) fly the same code, and a
test steps it by hand.

Modules: :mod:`.core` (:class:`FlightCore`: estimator, supervisor, mission, controller
and channel handover per tick), :mod:`.supervisor` (the state machine and every
failsafe), :mod:`.mission` (the reference across take-off, tracking, hold and landing),
:mod:`.commander` (motions asked for at run time), :mod:`.planner` and :mod:`.boundary`
(planning those motions, checking every number a client sends), :mod:`.inputs` (DATA and
Vicon to what the core consumes), :mod:`.prepare` (the trajectory built, shaped and
checked before flight), :mod:`.params` (:class:`FlightParams`, the flight's parameters in
one frozen bundle) and :mod:`.assembly` (the one place the configuration becomes them:
:func:`assemble`).

What a user calls: ``FlightCore(assemble(load_config(path)))``, then :meth:`FlightCore.tick`.
"""

from typing import TYPE_CHECKING

from groundstation.lazy import reexports

if TYPE_CHECKING:  # the names, imported from their modules on first use (groundstation.lazy)
    from groundstation.flight.assembly import assemble, check_config
    from groundstation.flight.core import FlightCore, TickResult
    from groundstation.flight.inputs import DataFrontEnd, InputHealth, VehicleStatus
    from groundstation.flight.params import DaemonParams, FlightParams
    from groundstation.flight.supervisor import Outcome, State, Supervisor, SupervisorLimits

__all__ = [
    "DaemonParams",
    "DataFrontEnd",
    "FlightCore",
    "FlightParams",
    "InputHealth",
    "Outcome",
    "State",
    "Supervisor",
    "SupervisorLimits",
    "TickResult",
    "VehicleStatus",
    "assemble",
    "check_config",
]

if not TYPE_CHECKING:
    __getattr__ = reexports(__name__)
