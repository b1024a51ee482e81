"""Running a fleet: the processes of a lab PC and the virtual fleet (README "Fleet").

* :mod:`.manager`: ``gs fleet up``: the relay and one daemon process per vehicle of this
  PC, stop requests passed on, the relay stopped last, one exit code;
* :mod:`.virtual`: a virtual fleet as processes (the virtual lab with N vehicles, the
  relay, the daemons), what ``gs fleet demo``, the fleet's tests and
  ``benchmarks/bench_fleet.py`` fly;
* :mod:`.demo`: ``gs fleet demo`` (``make demo FLEET=3``), figure-eights in phase;
* :mod:`.judge`: a fleet's flights against the virtual lab's ground truth.

They stand above what they drive: the daemons (:mod:`groundstation.app`, as processes of
their own) and their clients (:class:`groundstation.client.Fleet`); the daemons' side of
the fleet is :mod:`groundstation.fleet`.
"""
