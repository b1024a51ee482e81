"""The application around the flight core: the real-time daemon and ``gs fly``, the
in-process runner, the flight recorder, ``gs motors`` and ``gs replay``.

Everything here owns threads, sockets, files or clocks; the flight itself is
:mod:`groundstation.flight`.
"""
