"""Several vehicles, one Vicon, one or more lab PCs: a fleet on Eclipse Zenoh.

The ground station flies one vehicle per daemon process. A fleet is several of them
sharing one Vicon Tracker stream and one Zenoh network (README "Fleet"):

* :mod:`.relay`: ``gs vicon-relay`` receives Tracker's UDP stream once and publishes
  each object's item (decoded, plausibility-checked, with its frame number and receive
  stamp) on ``<fleet>/vicon/<object>``;
* :mod:`.posesource`: a daemon with ``vicon.source: zenoh`` takes its object's items
  from there through the same pose filter, latency model and failsafes as UDP;
* :mod:`.node`: the daemon's side of the fleet: its state, pose, reference and health
  under ``<fleet>/<vehicle>/``, run-time requests as Zenoh queries answered by the same
  API as the control socket, and the peers' poses for the separation rules
  (:mod:`.separation`, pure functions; :mod:`.peers`);
* :mod:`.fleetfile`: ``fleet.yaml``, one file for the fleet; :mod:`.manager`:
  ``gs fleet up|status|land``; :mod:`.client`: :class:`groundstation.client.Fleet`;
* :mod:`.session`: the Zenoh session (peer mode, explicit endpoints, no multicast
  scouting; TLS with client certificates and the fleet's access rules beyond loopback).

Only :mod:`.session` and the modules that open one import ``zenoh`` (the ``fleet``
extra); :mod:`.keys`, :mod:`.messages` and :mod:`.separation` are pure.
"""
