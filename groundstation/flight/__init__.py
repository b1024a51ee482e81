"""The flight, without I/O: one tick in, one COMMAND out.

No threads, sockets, files or clocks here: time and data are passed in. The real-time
daemon and the in-process runner (:mod:`groundstation.app`) fly the same code.
"""
