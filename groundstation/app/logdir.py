"""Where a flight's log goes when the configured directory cannot take it.

``config/lab.yaml`` logs to ``/var/lib/groundstation/flightlogs``, the systemd
service's state directory. A person running ``gs fly`` from their own shell usually
cannot write there; refusing to fly for that (exit 3) sends them off to edit the
configuration for no safety gain. :func:`create_flight_log` therefore tries the
configured directory first and then, in order, the user's directories
(:func:`fallback_log_dirs`): ``$XDG_STATE_HOME/groundstation/flightlogs`` (the XDG
Base Directory place for state that should outlive a restart; its default is
``~/.local/state``) and ``./flightlogs``. It says in one warning line where the log
went and why; ``meta.json`` records the same under ``flight_log_dir``. Only when no
directory at all can take the log does it raise (``gs fly`` then exits 3, nothing
sent to the vehicle).
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import structlog

from groundstation.app.recorder import FlightRecorder
from groundstation.errors import RecorderError

__all__ = ["create_flight_log", "fallback_log_dirs"]

log = structlog.get_logger(__name__)

SUBDIR = Path("groundstation") / "flightlogs"
"""The flight logs' place under a user's state directory."""


def fallback_log_dirs(environ: Mapping[str, str] | None = None,
                      cwd: Path | None = None) -> list[Path]:
    """The user directories a flight log falls back to, in order.

    ``$XDG_STATE_HOME/groundstation/flightlogs`` (a relative ``XDG_STATE_HOME`` is
    ignored, as the XDG Base Directory specification asks), else
    ``$HOME/.local/state/groundstation/flightlogs`` (no ``HOME``: left out), then
    ``flightlogs`` in the working directory ``cwd`` (default: the process's).
    environ : the environment to read (default ``os.environ``)
    """
    env = os.environ if environ is None else environ
    out: list[Path] = []
    xdg = env.get("XDG_STATE_HOME", "")
    home = env.get("HOME", "")
    if xdg and Path(xdg).is_absolute():
        out.append(Path(xdg) / SUBDIR)
    elif home and Path(home).is_absolute():
        out.append(Path(home) / ".local" / "state" / SUBDIR)
    out.append((cwd if cwd is not None else Path.cwd()) / "flightlogs")
    return out


def _reason(exc: BaseException) -> str:
    """The OS's words for why a directory could not take the log ("Permission denied")."""
    cause = exc.__cause__
    if isinstance(cause, OSError) and cause.strerror:
        return cause.strerror
    return str(exc)


def create_flight_log(configured: str | Path, config_yaml: str,
                      meta: Mapping[str, Any] | None = None, *,
                      fallbacks: list[Path] | None = None) -> FlightRecorder:
    """A :class:`FlightRecorder` in ``configured`` or, if that cannot be written, in the
    first of ``fallbacks`` (default :func:`fallback_log_dirs`) that can.

    config_yaml, meta : as :meth:`FlightRecorder.create`. A fallback logs one warning line
    naming both directories and the reason, and adds ``flight_log_dir`` (``configured``,
    ``used``, ``reason``) to meta.json. Raises RecorderError naming every directory tried
    when none can take the log.
    """
    first = Path(configured)
    try:
        return FlightRecorder.create(first, config_yaml, meta)
    except RecorderError as exc:
        reason = _reason(exc)
        failures = [f"{first}: {reason}"]
    tried = {first.absolute()}
    for candidate in fallbacks if fallbacks is not None else fallback_log_dirs():
        if candidate.absolute() in tried:
            continue
        tried.add(candidate.absolute())
        note = {"configured": str(first), "used": str(candidate), "reason": reason}
        try:
            recorder = FlightRecorder.create(candidate, config_yaml,
                                             {**(meta or {}), "flight_log_dir": note})
        except RecorderError as exc:
            failures.append(f"{candidate}: {_reason(exc)}")
            continue
        log.warning(f"flight log directory {first} cannot be written ({reason}): logging to "
                    f"{candidate} instead")
        return recorder
    raise RecorderError("cannot start a flight log in any directory: " + "; ".join(failures))
