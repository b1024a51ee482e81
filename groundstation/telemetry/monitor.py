"""``gs monitor``: a live view of the telemetry stream.

On a terminal the view is a block of :data:`HEIGHT` lines, each at most
:data:`WIDTH` characters whatever the payloads hold, redrawn in place a few times a
second (plain ANSI, no curses: the cursor moves up over the block and each line is
cleared and rewritten; a fixed size is what makes that leave no stale or wrapped
lines). Anywhere else (a pipe, a file, a log) there are no escape codes at all: one
compact :func:`status_line` a second. The flight's last ``state`` message (``final``)
is shown once more with the terminal state and outcome, and the monitor returns.

:func:`render` and :func:`status_line` are pure (payloads in, text out). Values that
do not fit their field are shown as ``#``, missing or non-numeric ones as ``--``, and
text from the payloads (state names, reject reasons) as printable ASCII, cut with
``~`` where too long. :func:`run_monitor` subscribes, keeps the latest ``state`` and
``health`` payloads and shows them until the final message, ``duration`` or Ctrl-C.
"""

from __future__ import annotations

import math
import os
import signal
import sys
import threading
import time
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from typing import Any, TextIO

import numpy as np

from groundstation.model.quaternion import euler_from_quat
from groundstation.telemetry.schema import SCHEMA_VERSION, TOPIC_HEALTH, TOPIC_STATE
from groundstation.telemetry.subscriber import TelemetrySubscriber

WIDTH = 79
"""Longest line drawn [characters]: one less than an 80-column terminal, so a line never
wraps (a terminal that wraps at the last column would break the in-place redraw)."""
HEIGHT = 16
"""Lines in the view, whatever the payloads hold."""
STALE_S = 1.0
"""No message for longer than this is shown as a warning [s]."""
REFRESH_S = 0.2
"""Redraw interval on a terminal [s]."""
PLAIN_EVERY_S = 1.0
"""Interval between status lines when the output is not a terminal [s]."""
FINAL_WAIT_S = 0.3
"""After the final ``state``, how long to wait for the ``health`` the daemon sends after
it before the last view is drawn [s]."""

_UP = "\x1b[{n}F"  # cursor to the start of the line n lines up
_CLEAR = "\x1b[2K"  # clear the whole line
_LABEL = 10  # width of the label column ("reference ")
_UNIT_SUFFIXES = {"_s": " s", "_hz": " Hz", "_m": " m", "_v": " V"}
"""Free-form health keys ending in these carry a value in that unit."""


# -- formatting: every helper returns text of bounded width ---------------------------


def _real(value: Any) -> float | None:
    """``value`` as a float; None for anything that is no number (None, NaN, bool, str)."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        return None
    try:
        x = float(value)
    except OverflowError:  # an int beyond a float's range
        x = math.inf if value > 0 else -math.inf
    return None if math.isnan(x) else x


def _num(value: Any, width: int, decimals: int = 1, *, sign: bool = True,
         scale: float = 1.0) -> str:
    """``value * scale`` in exactly ``width`` characters, right-aligned: fixed-point with
    ``decimals``, else an exponent, else ``#`` (too large); ``--`` if it is no number."""
    x = _real(value)
    if x is None:
        return "--".rjust(width)
    x *= scale
    plus = "+" if sign else ""
    for text in (f"{x:{plus}.{decimals}f}", f"{x:{plus}.1e}", f"{x:{plus}.0e}"):
        if len(text) <= width:
            return text.rjust(width)
    return "#" * width


def _count(value: Any) -> str:
    """A counter: ``1234``, an exponent when huge, ``--`` if it is no number."""
    return _num(value, 9, 0, sign=False).strip()


def _text(value: Any, width: int) -> str:
    """``value`` as printable ASCII (other characters, escapes among them, become ``?``)
    of at most ``width`` characters, cut with ``~``."""
    try:
        raw = value if isinstance(value, str) else str(value)
    except ValueError:  # an int too long to print
        raw = "?"
    text = "".join(c if " " <= c <= "~" else "?" for c in raw)
    return text if len(text) <= width else text[: width - 1] + "~"


def _clip(line: str, width: int) -> str:
    """``line`` without trailing blanks, cut with ``~`` to at most ``width`` characters."""
    line = line.rstrip()
    return line if len(line) <= width else line[: width - 1] + "~"


def _get(payload: Any, *keys: str) -> Any:
    """payload[k1][k2]... or None where a level is missing."""
    node: Any = payload
    for key in keys:
        if not isinstance(node, Mapping):
            return None
        node = node.get(key)
    return node


def _three(values: Any) -> list[Any]:
    """The first three entries of a list (None for missing ones or a non-list)."""
    items = list(values[:3]) if isinstance(values, list | tuple) else []
    return items + [None] * (3 - len(items))


def _vec(values: Any, unit: str, *, labels: tuple[str, str, str] = ("x", "y", "z"),
         decimals: int = 3, scale: float = 1.0, width: int = 7) -> str:
    """``x  +0.100  y  -0.200  z  -0.950 m``: three components of ``width`` characters."""
    return "  ".join(f"{label} {_num(v, width, decimals, scale=scale)}"
                     for label, v in zip(labels, _three(values), strict=True)) + " " + unit


def attitude_deg(quaternion: Any) -> list[float | None]:
    """3-2-1 Euler angles ``[roll, pitch, yaw]`` [deg] of a scalar-first quaternion
    ``[w, x, y, z]`` (normalised here); Nones if it is not four finite numbers, not 0."""
    parts = [_real(c) for c in quaternion] if isinstance(quaternion, list | tuple) else []
    if len(parts) != 4 or not all(c is not None and math.isfinite(c) for c in parts):
        return [None, None, None]
    q = np.array(parts, dtype=float)
    biggest = float(np.max(np.abs(q)))
    if biggest == 0.0:
        return [None, None, None]
    q /= biggest  # so that the norm neither overflows nor underflows
    phi, theta, psi = euler_from_quat(q / np.linalg.norm(q))
    return [math.degrees(phi), math.degrees(theta), math.degrees(psi)]


def _clock(seconds: Any) -> str:
    """``mm:ss.s`` (minutes grow to 3 digits), ``--:--.-`` if unknown or negative."""
    t = _real(seconds)
    if t is None or t < 0:
        return "--:--.-"
    if t >= 60_000 - 0.05:
        return "###:##.#"
    minutes, tenths = divmod(round(t * 10), 600)
    return f"{minutes:02d}:{tenths / 10:04.1f}"


def _mask(value: Any) -> str:
    """Ctrl-mask bits, bit 0 (pitch) rightmost: ``1111``; ``--`` unless a uint8."""
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= 0xFF:
        return "--"
    return f"{value:04b}"


def _command(cmd: Any) -> str:
    """``pitch   +30  roll   -12  yaw    +0  thrust 2010 RC  mask 1111 sent``."""
    if not isinstance(cmd, Mapping):
        return "--"
    return (f"pitch {_num(cmd.get('pitch'), 5, 0)}  roll {_num(cmd.get('roll'), 5, 0)}  "
            f"yaw {_num(cmd.get('yaw'), 5, 0)}  "
            f"thrust {_num(cmd.get('thrust'), 4, 0, sign=False)} RC  "
            f"mask {_mask(cmd.get('mask')):>4} " + ("sent" if cmd.get("sent") is True else "held"))


def _vehicle(section: Any) -> str:
    """``battery 11.78 V  applies 1111  motors on  RC ok  switch on`` (STATUS and RC)."""
    if not isinstance(section, Mapping):
        return "--"
    applies = (_mask(section.get("applied_mask")) if section.get("serial_active")
               else "none (pilot)")
    return "  ".join([
        f"battery {_num(section.get('battery_v'), 5, 2, sign=False)} V",
        f"applies {applies}",
        "motors " + ("on" if section.get("motors_on") else "off"),
        "RC " + ("ok" if section.get("rc_valid") else "LOST"),
        "switch " + ("on" if section.get("pilot_enabled", True) else "OFF")])


def _rate(section: Any) -> str:
    """``  99.5 Hz``, the ``rate_hz`` of a link or Vicon section."""
    return _num(_get(section, "rate_hz"), 6, 1, sign=False) + " Hz"


def _rejected(section: Any) -> tuple[str, str]:
    """(total, detail) of a section's ``rejected`` {reason: count}: ``("3", "crc 2, length
    1")``, non-zero reasons only; ``("--", "")`` if there is no such mapping."""
    rejected = _get(section, "rejected")
    if _real(rejected) is not None:
        return _count(rejected), ""
    if not isinstance(rejected, Mapping):
        return "--", ""
    counts = [(_text(k, 20), x) for k, v in rejected.items() if (x := _real(v))]
    detail = ", ".join(f"{k} {_count(x)}" for k, x in sorted(counts))
    return _count(sum(x for _, x in counts)), detail


def _source(section: Any) -> str:
    """``  99.5 Hz  last  0.01 s  rejected 3 (crc 2, length 1)`` for link and Vicon."""
    if not isinstance(section, Mapping):
        return "--"
    text = _rate(section)
    for key in ("time_since_data_s", "time_since_pose_s"):
        if key in section:
            text += f"  last {_num(section[key], 5, 2, sign=False)} s"
    total, detail = _rejected(section)
    return text + f"  rejected {total}" + (f" ({detail})" if detail else "")


def _streams(section: Any) -> str:
    """The Vicon section's pose streams: ``one sender  rival episodes 0  rival poses 0
    outside 0``, led by ``RIVAL STREAM x1`` while a second sender of the object is fed
    (``rivals``); ``outside`` counts sightings beyond the volume. ``--`` without them."""
    if not isinstance(section, Mapping) or "rivals" not in section:
        return "--"
    rivals = _real(section.get("rivals"))
    head = ("--" if rivals is None else "one sender" if rivals == 0
            else f"RIVAL STREAM x{_count(rivals)}")
    return (f"{head}  rival episodes {_count(section.get('rival_events'))}  "
            f"rival poses {_count(section.get('rival_poses'))}  "
            f"outside {_count(section.get('outside'))}")


def _free(section: Any, *, hide_zero: bool = False, skip: tuple[str, ...] = ()) -> str:
    """``key value`` pairs of a free-form section's scalar entries, with the unit its key
    names (``compute_time_s 0.0011`` -> ``compute_time 0.0011 s``); ``hide_zero`` leaves
    out counters at 0. Empty if there are none."""
    if not isinstance(section, Mapping):
        return ""
    items = []
    for key, value in section.items():
        name, unit = _text(key, 24), ""
        zero = isinstance(value, int) and not isinstance(value, bool) and value == 0
        if name in skip or (hide_zero and zero):
            continue
        for suffix, unit_text in _UNIT_SUFFIXES.items():
            if name.endswith(suffix):
                name, unit = name.removesuffix(suffix), unit_text
                break
        if isinstance(value, bool):
            shown = "yes" if value else "no"
        elif isinstance(value, int):
            shown = _count(value)
        elif (x := _real(value)) is not None:
            shown = f"{x:.4g}"
        elif isinstance(value, str):
            shown = _text(value, 20)
        else:
            continue
        items.append(f"{name} {shown}{unit}")
    return "  ".join(items)


_ESTIMATOR_SHOWN = ("t", "initialised", "diverged", "updates", "last_nis", "time_since_fix",
                    "covariance_trace")


def _estimator(section: Any) -> str:
    """``updates 1234  NIS  2.3  fix  0.01 s`` (the last Vicon fix's age), ``DIVERGED`` or
    ``NOT INITIALISED`` when so, then the estimator's other non-zero counters."""
    if not isinstance(section, Mapping):
        return "--"
    parts = []
    if section.get("initialised") is False:
        parts.append("NOT INITIALISED")
    if section.get("diverged") is True:
        parts.append("DIVERGED")
    if "updates" in section:
        parts.append(f"updates {_count(section['updates'])}")
    if "last_nis" in section:
        parts.append(f"NIS {_num(section['last_nis'], 5, 1, sign=False)}")
    if "time_since_fix" in section:
        parts.append(f"fix {_num(section['time_since_fix'], 5, 2, sign=False)} s")
    parts.append(_free(section, hide_zero=True, skip=_ESTIMATOR_SHOWN))
    return "  ".join(part for part in parts if part) or "--"


def _ended(state: Any) -> bool:
    """Whether ``state`` is the flight's final message."""
    return _get(state, "final") is True


def _state_name(state: Any) -> str:
    """``TRACK``; for the final message ``DONE (COMPLETED)``, the terminal state and the
    flight's outcome; ``--`` before any state."""
    name = _get(state, "supervisor", "name")
    number = _real(_get(state, "supervisor", "state"))
    if isinstance(name, str) and name:
        text = _text(name, 14)
    elif number is not None:
        text = f"state {_count(number)}"
    else:
        text = "--"
    if _ended(state):
        outcome = _get(state, "outcome")
        text += f" ({_text(outcome, 12) if outcome else 'final'})"
    return text


def _status(state: Any, age_s: float | None) -> str:
    """``last 0.05 s ago``, ``NO DATA for 3.0 s`` (older than :data:`STALE_S`),
    ``waiting for telemetry`` or ``FLIGHT ENDED``."""
    if _ended(state):
        return "FLIGHT ENDED"
    if age_s is None:
        return "waiting for telemetry"
    if age_s > STALE_S:
        return f"NO DATA for {_num(age_s, 7, 1, sign=False).strip()} s"
    return f"last {_num(age_s, 4, 2, sign=False)} s ago"


def render(
    state: Mapping[str, Any] | None, health: Mapping[str, Any] | None, *,
    endpoint: str = "", received: int = 0, age_s: float | None = None, width: int = WIDTH,
) -> list[str]:
    """The view: :data:`HEIGHT` lines of at most ``width`` characters, no ANSI codes.

    Supervisor state and flight time [mm:ss.s], position estimate, reference and yaw
    [m, deg], tracking error [cm], body velocity [m/s], attitude [deg], body rates
    [deg/s], command [RC units] and ctrl mask, vehicle (battery [V], switch), link and
    Vicon rates [Hz], last data age [s] and rejections, Vicon's pose streams (a rival
    sender, sightings outside the volume), estimator, loop and telemetry counters.

    state, health : the latest payloads of each topic (None if none yet); a state with
        ``final`` true is shown as the flight's end
    endpoint : shown in the title; received : messages received so far
    age_s : seconds since the last message (None: none yet) [s]
    """
    estimate = _get(state, "estimate")
    schema = _get(state, "schema") or _get(health, "schema")
    state_line = (f"{_state_name(state):<22}  flight {_clock(_get(state, 'flight_time_s'))}"
                  + (f"  [schema {_text(schema, 8)}, expected {SCHEMA_VERSION}]"
                     if schema not in (None, SCHEMA_VERSION) else ""))
    reason = _get(state, "reason") if _ended(state) else None
    if reason:
        state_line += "  " + _text(reason, width)
    distance = _get(state, "error", "distance")
    rows = [
        ("state", state_line),
        ("position", _vec(_get(estimate, "position"), "m") + "    (estimate, NED)"),
        ("reference", _vec(_get(state, "reference", "position"), "m")
         + f"    yaw {_num(_get(state, 'reference', 'yaw'), 6, 1, scale=180 / math.pi)} deg"),
        ("error", _vec(_get(state, "error", "position"), "cm", decimals=1, scale=100.0)
         + f"   |e| {_num(distance, 6, 1, sign=False, scale=100.0)} cm"),
        ("velocity", _vec(_get(estimate, "velocity_body"), "m/s") + "  (body, FRD)"),
        ("attitude", _vec(attitude_deg(_get(estimate, "quaternion")), "deg",
                          labels=("roll", "pitch", "yaw"), decimals=1, width=6)),
        ("rates", _vec(_get(estimate, "omega"), "deg/s", labels=("p", "q", "r"),
                       decimals=1, scale=180 / math.pi)),
        ("command", _command(_get(state, "command"))),
        ("vehicle", _vehicle(_get(state, "vehicle"))),
        ("link", _source(_get(health, "link"))),
        ("vicon", _source(_get(health, "vicon"))),
        ("streams", _streams(_get(health, "vicon"))),
        ("estimator", _estimator(_get(health, "estimator"))),
        ("loop", _free(_get(health, "loop")) or "--"),
        ("telemetry", _free(_get(health, "telemetry")) or "--"),
    ]
    title = (f"gs monitor  {_status(state, age_s):<21}  {_count(received):>7} msgs  "
             + _text(endpoint, width))
    lines = [title] + [f"{label:<{_LABEL}}{text}" for label, text in rows]
    return [_clip(line, width) for line in lines]


def status_line(
    state: Mapping[str, Any] | None, health: Mapping[str, Any] | None, *,
    received: int = 0, age_s: float | None = None, width: int = WIDTH,
) -> str:
    """One compact line of at most ``width`` characters, for output that is no terminal:

    ``TRACK      t 01:23.4  |e|  45.0 cm  11.78 V  link  99.5 Hz  vicon 100.0 Hz``
    (state, flight time [mm:ss.s], tracking error [cm], battery [V], link and Vicon
    rates [Hz]); when stale ``NO DATA for 3.0 s  last: TRACK ...``; for the flight's
    final state ``ENDED  DONE (COMPLETED)  t 01:35.0  11.62 V  <reason>``. Arguments
    as :func:`render`.
    """
    if state is None and health is None:
        return _clip(f"waiting for telemetry ({_count(received)} messages)", width)
    status = _status(state, age_s)
    name, clock = _state_name(state), _clock(_get(state, "flight_time_s"))
    volts = _num(_get(state, "vehicle", "battery_v"), 5, 2, sign=False) + " V"
    error = f"|e| {_num(_get(state, 'error', 'distance'), 5, 1, sign=False, scale=100.0)} cm"
    if _ended(state):
        line = f"ENDED  {name}  t {clock}  {volts}  " + _text(_get(state, "reason") or "", width)
    elif status.startswith("NO DATA"):
        line = f"{status}  last: {name}  t {clock}  {error}  {volts}"
    else:
        line = (f"{name:<10} t {clock}  {error}  {volts}  "
                f"link {_rate(_get(health, 'link'))}  vicon {_rate(_get(health, 'vicon'))}")
    return _clip(line, width)


# -- the live loop ----------------------------------------------------------------------


class _Latest:
    """The latest payload of each topic, how many messages arrived and when the last did.
    Once the final ``state`` has arrived, later ``state`` messages are ignored."""

    def __init__(self) -> None:
        self.payloads: dict[str, dict[str, Any]] = {}
        self.received = 0
        self.last_rx: float | None = None
        self.final_at: float | None = None
        """Monotonic time the final state arrived [s] (None: not yet)."""
        self.health_after_final = False

    def take(self, topic: str, payload: dict[str, Any], now: float) -> None:
        """Keep one received message."""
        self.received, self.last_rx = self.received + 1, now
        if self.final_at is not None:
            if topic == TOPIC_STATE:
                return
            self.health_after_final |= topic == TOPIC_HEALTH
        self.payloads[topic] = payload
        if topic == TOPIC_STATE and _ended(payload):
            self.final_at = now

    def ended(self, now: float) -> bool:
        """True once the final state and its health arrived (or :data:`FINAL_WAIT_S` passed)."""
        return self.final_at is not None and (
            self.health_after_final or now >= self.final_at + FINAL_WAIT_S)

    def wake_by(self) -> float:
        """When :meth:`ended` turns true without another message [s, monotonic]."""
        return math.inf if self.final_at is None else self.final_at + FINAL_WAIT_S


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
    refresh_s: float | None = None, tty: bool | None = None,
) -> int:
    """Show ``endpoint``'s telemetry until the flight's final message (shown, then the
    monitor returns at once), ``duration`` seconds (None: no limit) or Ctrl-C; return
    the number of messages received. With no messages it keeps showing how long none
    came.

    out : where to write (default stdout)
    tty : redraw the :func:`render` view in place (True) or print a :func:`status_line`
        per interval without escape codes (False); None: whether ``out`` is a terminal
    refresh_s : interval between redraws or lines [s]; None: :data:`REFRESH_S` on a
        terminal, :data:`PLAIN_EVERY_S` otherwise
    Raises TelemetryError if the endpoint is invalid.
    """
    stream = sys.stdout if out is None else out
    live = stream.isatty() if tty is None else tty
    if refresh_s is None:
        refresh_s = REFRESH_S if live else PLAIN_EVERY_S
    latest = _Latest()
    drawn = 0

    def show(now: float) -> None:
        nonlocal drawn
        state, health = latest.payloads.get(TOPIC_STATE), latest.payloads.get(TOPIC_HEALTH)
        age = None if latest.last_rx is None else now - latest.last_rx
        if live:
            width = min(WIDTH, _columns(stream) - 1)
            drawn = _draw(stream, render(state, health, endpoint=endpoint, width=width,
                                         received=latest.received, age_s=age), drawn)
        else:
            stream.write(status_line(state, health, received=latest.received, age_s=age)
                         + "\n")
            stream.flush()

    end = math.inf if duration is None else time.monotonic() + duration
    with TelemetrySubscriber(endpoint) as client, _until_interrupted() as stop:
        next_show = time.monotonic() + refresh_s
        while not stop.is_set():
            now = time.monotonic()
            if latest.ended(now) or now >= end:
                show(now)
                break
            if now >= next_show:
                show(now)
                next_show = max(next_show + refresh_s, now)
            message = client.receive(max(0.0, min(next_show, end, latest.wake_by()) - now))
            if message is not None:
                latest.take(*message, time.monotonic())
        if stop.is_set() and live:
            stream.write("\n")
    stream.flush()
    return latest.received


def _columns(stream: TextIO) -> int:
    """The terminal's width [characters]; 80 if ``stream`` is no terminal or its size is
    not set (0 on a new pseudo-terminal)."""
    try:
        columns = os.get_terminal_size(stream.fileno()).columns
    except (OSError, ValueError, AttributeError):
        return WIDTH + 1
    return columns if columns > 1 else WIDTH + 1


def _draw(stream: TextIO, lines: list[str], previous: int) -> int:
    """Overwrite the ``previous`` lines drawn with ``lines``; return how many were drawn."""
    head = _UP.format(n=previous) if previous else ""
    stream.write(head + "".join(f"{_CLEAR}{line}\n" for line in lines))
    stream.flush()
    return len(lines)
