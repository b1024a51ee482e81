"""A WebSocket relay that lets viewers speaking either name of the Foxglove protocol in.

The Foxglove WebSocket protocol was renamed: foxglove-sdk 0.30's server accepts only the
subprotocol ``foxglove.sdk.v1`` and answers HTTP 400 to a client that offers only the
former name ``foxglove.websocket.v1`` (Lichtblick's releases up to at least 1.10, older
Foxglove Studio), although the messages are the same. :class:`SubprotocolRelay` serves
on the address users connect to, accepts a client offering either name (the current one
when it offers both), opens its own connection to the SDK's server on loopback with
``foxglove.sdk.v1``, and copies every frame both ways unchanged (text frames: the JSON
control messages; binary frames: message data), so each viewer talks to the SDK's server
as if directly. One relay connection per viewer; a side that closes closes the other.

It runs an asyncio loop in a thread of its own (the ``websockets`` package, installed
with foxglove-sdk by the ``foxglove`` extra), beside the thread that feeds the SDK.
"""

from __future__ import annotations

import asyncio
import contextlib
import threading
from collections.abc import Sequence
from typing import Any

from groundstation.errors import TelemetryError

SDK_SUBPROTOCOL = "foxglove.sdk.v1"
"""The name foxglove-sdk's server speaks."""
FORMER_SUBPROTOCOL = "foxglove.websocket.v1"
"""The protocol's former name, which older viewers offer."""
SUBPROTOCOLS = (SDK_SUBPROTOCOL, FORMER_SUBPROTOCOL)
"""What the relay accepts, in order of preference."""


class SubprotocolRelay:
    """Serve ``ws://host:port`` for clients offering any of ``accepted`` and relay each to
    ``upstream`` (a ``ws://`` URL speaking ``upstream_subprotocol``).

    :meth:`start` binds (``port`` 0: any free port) and returns the bound port, or raises
    TelemetryError; :meth:`stop` closes every connection and the server.
    """

    def __init__(self, upstream: str, host: str, port: int, *,
                 accepted: Sequence[str] = SUBPROTOCOLS,
                 upstream_subprotocol: str = SDK_SUBPROTOCOL) -> None:
        self.upstream = upstream
        self.host = host
        self.port = port
        self.accepted = tuple(accepted)
        self.upstream_subprotocol = upstream_subprotocol
        self.connections = 0
        """Viewers relayed so far."""
        self._loop: asyncio.AbstractEventLoop | None = None
        self._thread: threading.Thread | None = None
        self._server: Any = None
        self._stopped: asyncio.Event | None = None

    def start(self, timeout: float = 10.0) -> int:
        """Bind and start relaying in a thread; the bound port. TelemetryError if the
        address cannot be bound (or the ``websockets`` package is missing)."""
        try:
            import websockets.asyncio.server  # noqa: F401  (fail here, not in the thread)
        except ImportError as exc:
            raise TelemetryError("gs foxglove needs the websockets package: pip install "
                                 "'groundstation[foxglove]'") from exc
        ready = threading.Event()
        failure: list[BaseException] = []

        def run() -> None:
            loop = asyncio.new_event_loop()
            self._loop = loop
            try:
                loop.run_until_complete(self._serve(ready, failure))
            finally:
                loop.close()

        self._thread = threading.Thread(target=run, name="foxglove-relay", daemon=True)
        self._thread.start()
        if not ready.wait(timeout):
            raise TelemetryError(f"foxglove: the relay on {self.host}:{self.port} did not "
                                 f"start within {timeout:g} s")
        if failure:
            self._thread.join(timeout)
            raise TelemetryError(f"foxglove: cannot serve on {self.host}:{self.port}: "
                                 f"{failure[0]}") from failure[0]
        return self.port

    async def _serve(self, ready: threading.Event, failure: list[BaseException]) -> None:
        from websockets.asyncio.server import serve

        self._stopped = asyncio.Event()
        try:
            server = await serve(self._relay, self.host, self.port,
                                 subprotocols=list(self.accepted),  # type: ignore[arg-type]
                                 max_size=None, compression=None)
        except OSError as exc:
            failure.append(exc)
            ready.set()
            return
        self._server = server
        self.port = int(next(iter(server.sockets)).getsockname()[1])
        ready.set()
        async with server:
            await self._stopped.wait()
            server.close()  # closes the viewers' connections; their relays end
            await server.wait_closed()

    async def _relay(self, client: Any) -> None:
        from websockets.asyncio.client import connect

        self.connections += 1
        try:
            async with connect(self.upstream, max_size=None, compression=None,
                               subprotocols=[self.upstream_subprotocol],  # type: ignore[list-item]
                               open_timeout=10) as upstream:
                await _pipe_both(client, upstream)
        except (OSError, TimeoutError) as exc:  # the SDK's server went away: tell the viewer
            await client.close(1011, f"upstream unavailable: {exc}"[:120])
        except Exception as exc:  # a handshake the SDK refused, a protocol error
            await client.close(1011, f"upstream: {type(exc).__name__}"[:120])

    def stop(self, timeout: float = 10.0) -> None:
        """Close every connection and the server; wait for the thread."""
        loop, stopped = self._loop, self._stopped
        if loop is not None and stopped is not None and not loop.is_closed():
            with contextlib.suppress(RuntimeError):  # the loop ended meanwhile
                loop.call_soon_threadsafe(stopped.set)
        if self._thread is not None:
            self._thread.join(timeout)


async def _pipe_both(a: Any, b: Any) -> None:
    """Copy frames a -> b and b -> a until either side closes; then close both."""
    from websockets.exceptions import ConnectionClosed

    async def pipe(source: Any, sink: Any) -> None:
        with contextlib.suppress(ConnectionClosed):
            async for frame in source:  # str for text frames, bytes for binary ones
                await sink.send(frame)

    tasks = [asyncio.ensure_future(pipe(a, b)), asyncio.ensure_future(pipe(b, a))]
    try:
        await asyncio.wait(tasks, return_when=asyncio.FIRST_COMPLETED)
    finally:
        for task in tasks:
            task.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)
        await a.close()
        await b.close()
