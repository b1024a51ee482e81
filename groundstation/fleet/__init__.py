"""Several vehicles, one Vicon, one or more lab PCs: a fleet on Eclipse Zenoh.

The ground station flies one vehicle per daemon process. A fleet is several of them
sharing one Vicon Tracker stream and one Zenoh network (README "Fleet"). This package
is what a vehicle's daemon and the relay run; it stands between the flight it serves
(:mod:`groundstation.flight`) and the application that opens it
(:mod:`groundstation.app`):

* :mod:`.relay`: ``gs vicon-relay`` receives Tracker's UDP stream once and publishes
  each object's item (decoded, plausibility-checked, with its frame number and receive
  stamp) on ``<fleet>/vicon/<object>``;
* :mod:`.posesource`: a daemon with ``vicon.source: zenoh`` takes its object's items
  from there through the same pose filter, latency model and failsafes as UDP;
* :mod:`.node`: the daemon's side of the fleet: its state, pose, reference and health
  under ``<fleet>/<vehicle>/``, run-time requests as Zenoh queries answered by the same
  API as the request socket, and the peers' poses for the separation rules
  (:mod:`.separation`, pure functions; :mod:`.peers`);
* :mod:`.session`: the Zenoh session (peer mode, explicit endpoints, no multicast
  scouting; TLS with client certificates and the fleet's access rules beyond loopback);
* :mod:`.keys` and :mod:`.messages`: every key, and the binary messages.

Each takes its parameters from the flight's assembly
(:class:`~groundstation.flight.params.FleetParams`, ``ZenohParams``, ``RelayParams``),
never the configuration. Around it: the ``fleet:`` section and the fleet file
(:mod:`groundstation.config.fleet`, :mod:`groundstation.config.fleetfile`), the Python
client (:class:`groundstation.client.Fleet`), the processes of ``gs fleet up`` and the
virtual fleet (:mod:`groundstation.fleetops`), the commands (:mod:`groundstation.cli.fleet`).

Only :mod:`.session` and the modules that open one import ``zenoh`` (the ``fleet``
extra); :mod:`.keys`, :mod:`.messages` and :mod:`.separation` are pure.
"""
