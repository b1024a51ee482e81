"""systemd's notify protocol (``sd_notify(3)``), dependency-free.

Under systemd with ``Type=notify`` the service manager sets ``$NOTIFY_SOCKET`` to
an ``AF_UNIX`` datagram socket; the daemon sends newline-separated ``KEY=VALUE``
assignments to it: ``READY=1`` when it is up, ``WATCHDOG=1`` at least every
``$WATCHDOG_USEC`` microseconds (half of it is the usual ping period),
``STOPPING=1`` when it begins to shut down and ``STATUS=...`` as a one-line
status shown by ``systemctl status``. A socket path starting with ``@`` is in
the Linux abstract namespace (the ``@`` stands for a leading NUL byte).

Not under systemd (no ``$NOTIFY_SOCKET``) every call is a no-op that returns
False, so the flight loop calls it unconditionally. Send errors are counted in
:attr:`SdNotifier.errors` and never raised: a lost notification must not stop a
flight (if the watchdog pings stop arriving, systemd acts, see
``config/groundstation.service``).
"""

from __future__ import annotations

import os
import socket
from collections.abc import Mapping


class SdNotifier:
    """Sends notifications to one systemd notify socket (or nowhere).

    address : the socket address as ``$NOTIFY_SOCKET`` gives it (a filesystem path,
        or ``@name`` for the abstract namespace), or None for a no-op notifier
    watchdog_usec : ``$WATCHDOG_USEC`` for this process, or None if no watchdog
    """

    def __init__(self, address: str | None = None, watchdog_usec: int | None = None) -> None:
        self._address: str | bytes | None = None
        if address and address[0] == "@":
            self._address = b"\0" + address[1:].encode()
        elif address and address[0] == "/":
            self._address = address
        self._watchdog_usec = watchdog_usec if watchdog_usec and watchdog_usec > 0 else None
        self.sent = 0
        """Notifications delivered."""
        self.errors = 0
        """Notifications that could not be sent (socket gone, permission, ...)."""

    @classmethod
    def from_env(
        cls, environ: Mapping[str, str] | None = None, pid: int | None = None
    ) -> SdNotifier:
        """Build from ``$NOTIFY_SOCKET``, ``$WATCHDOG_USEC`` and ``$WATCHDOG_PID``.

        environ : the environment to read (default ``os.environ``)
        pid : this process's id (default ``os.getpid()``). The watchdog applies only
            if ``$WATCHDOG_PID`` is unset or equals it (sd_watchdog_enabled(3)), so a
            child process that inherited the variables does not ping for its parent.
        An unusable ``$NOTIFY_SOCKET`` (not absolute, not ``@``) gives a no-op notifier.
        """
        env = os.environ if environ is None else environ
        usec: int | None = None
        try:
            usec = int(env.get("WATCHDOG_USEC", ""))
            watchdog_pid = env.get("WATCHDOG_PID")
            if watchdog_pid is not None and int(watchdog_pid) != (
                os.getpid() if pid is None else pid
            ):
                usec = None
        except ValueError:
            usec = None
        return cls(env.get("NOTIFY_SOCKET"), usec)

    @property
    def enabled(self) -> bool:
        """True if there is a notify socket to send to."""
        return self._address is not None

    def watchdog_interval(self) -> float | None:
        """The watchdog timeout [s] systemd enforces, or None if there is none.

        Ping with :meth:`watchdog` at least every half of it.
        """
        return None if self._watchdog_usec is None else self._watchdog_usec / 1e6

    def notify(self, message: str) -> bool:
        """Send raw newline-separated assignments; True if delivered, False if not
        under systemd or the send failed (counted in :attr:`errors`)."""
        if self._address is None:
            return False
        try:
            with socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM | socket.SOCK_CLOEXEC) as sock:
                sock.sendto(message.encode(), self._address)
        except OSError:
            self.errors += 1
            return False
        self.sent += 1
        return True

    def ready(self, status: str | None = None) -> bool:
        """``READY=1``: start-up finished (optionally with a status line)."""
        return self.notify("READY=1" if status is None else f"READY=1\nSTATUS={_line(status)}")

    def watchdog(self) -> bool:
        """``WATCHDOG=1``: the loop is alive."""
        return self.notify("WATCHDOG=1")

    def stopping(self, status: str | None = None) -> bool:
        """``STOPPING=1``: shutdown began (landing, handing back)."""
        return self.notify(
            "STOPPING=1" if status is None else f"STOPPING=1\nSTATUS={_line(status)}"
        )

    def status(self, text: str) -> bool:
        """``STATUS=text``: free-form one-line status for ``systemctl status``."""
        return self.notify(f"STATUS={_line(text)}")


def _line(text: str) -> str:
    """One line: a newline would start a new assignment."""
    return text.replace("\n", " ")
