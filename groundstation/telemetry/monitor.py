"""``gs monitor``: a live terminal view of the telemetry stream.

Plain ANSI (no curses): the view is a block of lines redrawn in place by moving
the cursor up and clearing each line. :func:`render` is pure (payloads in, lines
out); :func:`run_monitor` subscribes, keeps the latest ``state`` and ``health``
payloads and redraws a few times a second until ``duration`` or Ctrl-C.
"""

from __future__ import annotations

import signal
import sys
import threading
import time
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from typing import Any, TextIO

from groundstation.telemetry.client import TelemetryClient
from groundstation.telemetry.schema import SCHEMA_VERSION, TOPIC_HEALTH, TOPIC_STATE

_UP = "\x1b[{n}F"  # cursor to the start of the line n lines up
_CLEAR = "\x1b[2K"  # clear the whole line
STALE_S = 1.0
"""No message for longer than this is shown as a warning [s]."""


def _vec(values: Sequence[float | None] | None, unit: str = "m") -> str:
    """``x +0.012  y -0.003  z -1.002 m``, dashes for missing values."""
    if not values:
        return "x    --    y    --    z    --  " + unit
    parts = [f"{axis} {v:+7.3f}" if v is not None else f"{axis}    --  "
             for axis, v in zip("xyz", values, strict=False)]
    return "  ".join(parts) + " " + unit


def _get(payload: Mapping[str, Any] | None, *keys: str) -> Any:
    """payload[k1][k2]... or None where a level is missing."""
    node: Any = payload
    for key in keys:
        if not isinstance(node, Mapping):
            return None
        node = node.get(key)
    return node


def _counters(section: Mapping[str, Any] | None) -> str:
    """``98.0 Hz  rejected 3 (crc 2, length 1)  last 0.01 s`` for a link/vicon section."""
    if not isinstance(section, Mapping):
        return "--"
    rate = section.get("rate_hz")
    text = "  --  Hz" if rate is None else f"{rate:6.1f} Hz"
    rejected = section.get("rejected")
    if isinstance(rejected, Mapping):
        nonzero = {k: v for k, v in rejected.items() if v}
        detail = ", ".join(f"{k} {v}" for k, v in sorted(nonzero.items()))
        text += f"  rejected {sum(nonzero.values())}" + (f" ({detail})" if detail else "")
    for key in ("time_since_data_s", "time_since_pose_s"):
        if section.get(key) is not None:
            text += f"  last {section[key]:.2f} s"
    return text


def _free(section: Mapping[str, Any] | None) -> str:
    """``key value`` pairs of a free-form section's scalar entries."""
    if not isinstance(section, Mapping):
        return "--"
    items = [f"{k} {v:.4g}" if isinstance(v, float) else f"{k} {v}"
             for k, v in section.items() if isinstance(v, int | float | str)]
    return "  ".join(items) or "--"


def _command(cmd: Mapping[str, Any] | None) -> str:
    """``pitch   +12  roll    -3  yaw    +0  thrust 2010  mask 1111  sent``."""
    if not isinstance(cmd, Mapping):
        return "--"
    try:
        return (f"pitch {cmd['pitch']:+5d}  roll {cmd['roll']:+5d}  yaw {cmd['yaw']:+5d}  "
                f"thrust {cmd['thrust']:4d}  mask {cmd['mask']:04b}  "
                + ("sent" if cmd.get("sent") else "held"))
    except (KeyError, TypeError, ValueError):
        return "malformed command " + repr(dict(cmd))


def _vehicle(section: Mapping[str, Any] | None) -> str:
    """``battery 11.78 V  applies 1111  motors on  RC ok  switch on`` (the STATUS block)."""
    if not isinstance(section, Mapping):
        return "--"
    volts = section.get("battery_v")
    mask = section.get("applied_mask")
    parts = ["battery " + ("  --  V" if not isinstance(volts, int | float)
                           else f"{volts:6.2f} V"),
             "applies " + (f"{mask:04b}" if isinstance(mask, int) and section.get(
                 "serial_active") else "none (pilot)"),
             "motors " + ("on" if section.get("motors_on") else "off"),
             "RC " + ("ok" if section.get("rc_valid") else "LOST"),
             "switch " + ("on" if section.get("pilot_enabled", True) else "OFF")]
    return "  ".join(parts)


def render(
    state: Mapping[str, Any] | None, health: Mapping[str, Any] | None, *,
    endpoint: str = "", received: int = 0, age_s: float | None = None,
) -> list[str]:
    """The view as lines (no ANSI codes): supervisor state, command, estimated and
    reference position, tracking error, link / Vicon rates and rejections, counters.

    state, health : the latest payloads of each topic (None if none yet)
    received : messages received so far; age_s : seconds since the last one
    """
    if age_s is None:
        status = "waiting for telemetry..."
    elif age_s > STALE_S:
        status = f"NO DATA for {age_s:.1f} s"
    else:
        status = f"last {age_s:.2f} s ago"
    cmd = _get(state, "command")
    name, number = _get(state, "supervisor", "name"), _get(state, "supervisor", "state")
    schema = _get(state, "schema") or _get(health, "schema")
    lines = [
        f"groundstation monitor  {endpoint}  messages {received}  {status}",
        f"state      {name or '--'} ({'--' if number is None else number})"
        + (f"   [schema {schema}, expected {SCHEMA_VERSION}]"
           if schema not in (None, SCHEMA_VERSION) else ""),
        "command    " + _command(cmd),
        "vehicle    " + _vehicle(_get(state, "vehicle")),
        "position   " + _vec(_get(state, "estimate", "position")) + "  (estimate, NED)",
        "reference  " + _vec(_get(state, "reference", "position")),
        "error      " + _vec(_get(state, "error", "position"))
        + ("" if _get(state, "error", "distance") is None
           else f"  |e| {_get(state, 'error', 'distance'):.3f} m"),
        "velocity   " + _vec(_get(state, "estimate", "velocity_body"), "m/s") + "  (body)",
        "link       " + _counters(_get(health, "link")),
        "vicon      " + _counters(_get(health, "vicon")),
        "estimator  " + _free(_get(health, "estimator")),
        "loop       " + _free(_get(health, "loop")),
        "telemetry  " + _free(_get(health, "telemetry")),
    ]
    return lines


@contextmanager
def _until_interrupted() -> Iterator[threading.Event]:
    """An event Ctrl-C sets (in the main thread; elsewhere it is never set). A flag instead
    of KeyboardInterrupt, so the interrupt never lands inside ZeroMQ's calls: the view
    ends within one receive timeout, always cleanly."""
    stop = threading.Event()
    if threading.current_thread() is not threading.main_thread():
        yield stop
        return
    previous = signal.signal(signal.SIGINT, lambda _signum, _frame: stop.set())
    try:
        yield stop
    finally:
        signal.signal(signal.SIGINT, previous)


def run_monitor(
    endpoint: str, duration: float | None = None, *, out: TextIO | None = None,
    refresh_s: float = 0.2,
) -> int:
    """Show the live view of ``endpoint`` until ``duration`` seconds pass (None: until
    Ctrl-C); return the number of messages received. Ctrl-C ends it cleanly.
    Raises TelemetryError if the endpoint is invalid."""
    stream = sys.stdout if out is None else out
    latest: dict[str, dict[str, Any]] = {}
    received, drawn = 0, 0
    last_rx: float | None = None
    start = time.monotonic()
    end = None if duration is None else start + duration
    with TelemetryClient(endpoint) as client, _until_interrupted() as stop:
        while not stop.is_set() and (end is None or time.monotonic() < end):
            redraw_at = time.monotonic() + refresh_s
            while not stop.is_set() and (left := redraw_at - time.monotonic()) > 0:
                message = client.receive(left)
                if message is not None:
                    latest[message[0]] = message[1]
                    received, last_rx = received + 1, time.monotonic()
            age = None if last_rx is None else time.monotonic() - last_rx
            lines = render(latest.get(TOPIC_STATE), latest.get(TOPIC_HEALTH),
                           endpoint=endpoint, received=received, age_s=age)
            drawn = _draw(stream, lines, drawn)
        if stop.is_set():
            stream.write("\n")
    stream.flush()
    return received


def _draw(stream: TextIO, lines: list[str], previous: int) -> int:
    """Overwrite the ``previous`` lines drawn with ``lines``; return how many were drawn."""
    head = _UP.format(n=previous) if previous else ""
    stream.write(head + "".join(f"{_CLEAR}{line}\n" for line in lines))
    stream.flush()
    return len(lines)
