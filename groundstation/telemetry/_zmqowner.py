"""What the telemetry publisher and client share: one socket, and a context they may own."""

from __future__ import annotations

from collections.abc import Mapping
from types import TracebackType
from typing import Any, Self

import zmq

from groundstation.errors import TelemetryError


class ZmqOwner:
    """Owns at most one zmq socket and, unless one was shared, its context.

    Subclasses set :attr:`_socket`; :meth:`close` closes it without lingering and
    terminates the context if this object created it. Idempotent; a context manager.
    """

    _socket: zmq.Socket[Any] | None

    def _open_context(self, shared: zmq.Context[Any] | None, needed: bool = True) -> None:
        """Use ``shared``, or create (and own) a context if one is ``needed``."""
        self._own_context = shared is None and needed
        self._context: zmq.Context[Any] | None = zmq.Context() if self._own_context else shared

    def _bind_socket(self, kind: int, endpoint: str, what: str,
                     options: Mapping[int, int | bytes] | None = None) -> str:
        """Create a socket of ``kind`` with ``options`` (LINGER 0 always), bind it to
        ``endpoint`` and keep it as :attr:`_socket`; returns the bound endpoint with the
        actual port. On failure closes everything and raises TelemetryError naming
        ``what`` and the endpoint."""
        try:
            self._socket, last = self._new_bound_socket(kind, endpoint, options)
        except zmq.ZMQError as exc:
            self._close_context()
            raise TelemetryError(f"{what}: cannot bind {endpoint!r}: {exc}") from exc
        return last

    def _new_bound_socket(self, kind: int, endpoint: str,
                          options: Mapping[int, int | bytes] | None = None
                          ) -> tuple[zmq.Socket[Any], str]:
        """A socket of ``kind`` with ``options`` (LINGER 0 always) bound to ``endpoint``,
        and the bound endpoint with the actual port; closes it and re-raises the
        ZMQError if it cannot be set up. The context stays open."""
        assert self._context is not None
        sock = self._context.socket(kind)
        try:
            sock.setsockopt(zmq.LINGER, 0)
            for option, value in (options or {}).items():
                sock.setsockopt(option, value)
            sock.bind(endpoint)
            last = sock.getsockopt(zmq.LAST_ENDPOINT)
        except zmq.ZMQError:
            sock.close(linger=0)
            raise
        return sock, last.decode() if isinstance(last, bytes) else str(last)

    def _close_context(self) -> None:
        if self._own_context and self._context is not None:
            self._context.term()
            self._context = None

    def _close_socket(self) -> None:
        if self._socket is not None:
            self._socket.close(linger=0)
            self._socket = None
        self._close_context()

    def close(self) -> None:
        """Close the socket and terminate an owned context (idempotent)."""
        self._close_socket()

    def __enter__(self) -> Self:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()
