"""The application around the flight core: everything that owns threads, sockets, files
or clocks.

Modules: :mod:`.daemon` (:class:`FlightDaemon`, the real-time flight behind ``gs fly``:
serial link, Vicon, recorder, telemetry, request socket, signals), :mod:`.fly` (``gs fly``
itself: the checks, the optional virtual lab, the summary, the after-flight steps the
CLI hands in), :mod:`.inprocess` (:func:`fly_in_process`: the same flight core against a
virtual lab on its simulated clock), :mod:`.recorder` (the flight log), :mod:`.api` (the
run-time requests), :mod:`.planner_process`, :mod:`.motors` (``gs motors``),
:mod:`.replay` (``gs replay``), and the OS helpers :mod:`.realtime`, :mod:`.sdnotify`,
:mod:`.signals`, :mod:`.logdir`, :mod:`.ticklog` (the loop's timing histograms are
:mod:`groundstation.timing`).

Each takes the flight's parameters (:func:`groundstation.flight.assemble`), never the
configuration. The flight itself is :mod:`groundstation.flight`.
"""

from typing import TYPE_CHECKING

from groundstation.lazy import reexports

if TYPE_CHECKING:  # the names, imported from their modules on first use (groundstation.lazy)
    from groundstation.app.daemon import FlightDaemon, FlightSummary
    from groundstation.app.fly import AfterFlight, fly_command
    from groundstation.app.inprocess import FlightResult, InProcessFlight, fly_in_process
    from groundstation.app.recorder import FlightRecorder, read_flight
    from groundstation.app.replay import replay_flight

__all__ = [
    "AfterFlight",
    "FlightDaemon",
    "FlightRecorder",
    "FlightResult",
    "FlightSummary",
    "InProcessFlight",
    "fly_command",
    "fly_in_process",
    "read_flight",
    "replay_flight",
]

if not TYPE_CHECKING:
    __getattr__ = reexports(__name__)
