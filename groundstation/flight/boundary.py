"""Numbers at the boundary of the run-time API: every field of a request checked before any
arithmetic is done with it.

A request arrives as JSON (:mod:`groundstation.telemetry.requests`), where a number may be
an integer of thousands of digits, ``NaN``, ``Infinity`` or ``1e308``. Each field is
refused here with ``kind: request`` and a reason unless it is a JSON number a float
holds exactly enough (an integer within +-2^53, a finite float) and within its physical
range: headings within one turn, durations and periods within
[:data:`~groundstation.config.ranges.MIN_MOTION_S`,
:data:`~groundstation.flight.commander.MAX_MOTION_S`], ``start_at`` within
``api.start_horizon_s`` of now, sizes no larger than the flight volume. Positions must
lie inside the volume (``kind: volume``, the rule of
:func:`~groundstation.flight.commander.check_target`). Units: NED [m], headings [rad],
times [s].
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from pydantic import ValidationError

from groundstation.config import TrajectoryConfig, describe_problems
from groundstation.config.ranges import MIN_MOTION_S
from groundstation.control.feasibility import Volume
from groundstation.flight.commander import (
    MAX_MOTION_S,
    CommandRefusedError,
    check_target,
)
from groundstation.types import FloatArray

MAX_EXACT_INT = 2**53
"""Largest integer magnitude taken as a number: beyond it a float no longer holds every
integer, and ``float()`` of a long enough one raises (JSON allows any number of digits)."""

TURN = 2.0 * math.pi
"""One turn [rad]: the largest heading magnitude accepted."""

MAX_WAYPOINTS = 1000
"""Most waypoints a ``follow`` request may carry."""


def _refuse(reason: str) -> CommandRefusedError:
    return CommandRefusedError("request", reason)


def number(value: Any, what: str) -> float:
    """``value`` as a float if it is a finite JSON number (not a bool, not a string, an
    integer within +-2^53); else CommandRefusedError('request') naming ``what``."""
    if isinstance(value, int) and not isinstance(value, bool):
        if abs(value) > MAX_EXACT_INT:
            raise _refuse(f"{what}: must be a finite number, got an integer of "
                          f"{value.bit_length()} bits (beyond +-2^53)")
        return float(value)
    if not isinstance(value, float) or not math.isfinite(value):
        raise _refuse(f"{what}: must be a finite number, got {repr(value)[:40]}")
    return value


def in_range(value: Any, what: str, lo: float, hi: float, unit: str) -> float:
    """:func:`number`, and within ``[lo, hi]`` (``unit`` names it in the reason)."""
    v = number(value, what)
    if not lo <= v <= hi:
        raise _refuse(f"{what} {v:g} {unit}: must be in [{lo:g}, {hi:g}] {unit}")
    return v


def heading(value: Any, what: str = "yaw") -> float | None:
    """An optional heading [rad] within one turn (None stays None)."""
    if value is None:
        return None
    v = number(value, what)
    if not abs(v) <= TURN:
        raise _refuse(f"{what} {v:g} rad: a heading is within one turn, [-{TURN:.4f}, "
                      f"{TURN:.4f}] rad (+-360 deg)")
    return v


def duration(value: Any, what: str = "duration") -> float | None:
    """An optional duration [s] in [MIN_MOTION_S, MAX_MOTION_S] (None stays None)."""
    if value is None:
        return None
    return in_range(value, what, MIN_MOTION_S, MAX_MOTION_S, "s")


def position(value: Any, volume: Volume, what: str = "position") -> FloatArray:
    """3 finite numbers, NED [m] (``request``), inside the volume (``volume``)."""
    if not isinstance(value, list | tuple) or len(value) != 3:
        raise _refuse(f"{what}: must be 3 numbers (NED, m), got {str(value)[:60]}")
    point = np.array([number(v, what) for v in value])
    check_target(point, volume)
    return point


def height(value: Any, volume: Volume) -> float:
    """A height above the take-off point [m]: above the floor, at most the volume's height."""
    v = number(value, "height")
    top = volume.z[1] - volume.z[0]
    if not 0.0 < v <= top:
        raise _refuse(f"height {v:g} m: must be above the floor and at most the volume's "
                      f"{top:g} m")
    return v


def start_at(value: Any, now: float, horizon_s: float) -> float | None:
    """An optional unix time [s] within ``horizon_s`` of ``now`` (unix time [s],
    ``api.start_horizon_s``)."""
    if value is None:
        return None
    v = number(value, "start_at")
    ahead = v - now
    if not abs(ahead) <= horizon_s:
        when = f"{ahead:.0f} s from now" if ahead > 0 else f"{-ahead:.0f} s ago"
        raise _refuse(f"start_at is {when}: it must be within api.start_horizon_s = "
                      f"{horizon_s:g} s of now (a unix time [s], as time.time())")
    return v


def waypoint_rows(value: Any, volume: Volume, min_step_s: float) -> list[list[float]]:
    """Waypoints ``[[t, x, y, z(, yaw)], ...]`` (s, NED m, rad): at most
    :data:`MAX_WAYPOINTS` rows of 4 or 5 numbers like the first, times increasing by at
    least ``min_step_s`` [s] (the command period: a vehicle commanded at that rate cannot
    be asked for more) over at most MAX_MOTION_S, headings within one turn, each point
    inside the volume (``volume``)."""
    if not isinstance(value, list) or not 2 <= len(value) <= MAX_WAYPOINTS:
        raise _refuse(f"waypoints: a list of 2 to {MAX_WAYPOINTS} rows [t, x, y, z(, yaw)]")
    rows: list[list[float]] = []
    for k, row in enumerate(value):
        if not isinstance(row, list) or len(row) not in (4, 5) or \
                (rows and len(row) != len(rows[0])):
            raise _refuse(f"waypoint {k}: expected 4 or 5 numbers (t, x, y, z[, yaw]) like "
                          f"the first, found {str(row)[:80]}")
        values = [number(v, f"waypoint {k}") for v in row]
        if len(values) == 5:
            heading(values[4], f"waypoint {k} yaw")
        if rows and not values[0] - rows[-1][0] >= min_step_s:
            raise _refuse(f"waypoint {k}: t = {values[0]:g} s must be at least "
                          f"{min_step_s:g} s after the one before ({rows[-1][0]:g} s)")
        check_target(np.array(values[1:4]), volume, f"waypoint {k}: ")
        rows.append(values)
    span = rows[-1][0] - rows[0][0]
    if not span <= MAX_MOTION_S:
        raise _refuse(f"waypoints: the path lasts {span:g} s, longer than a motion may be "
                      f"({MAX_MOTION_S:g} s)")
    return rows


def trajectory_section(value: Any, volume: Volume, max_yaw_rate_rad_s: float
                       ) -> TrajectoryConfig:
    """A ``trajectory:`` section like the configuration's (the configuration's rules:
    strict, finite numbers, no unknown key), not ``none`` or ``waypoints`` (waypoints
    come as ``waypoints``), with sizes the volume can hold: ``period_s`` at least
    MIN_MOTION_S, ``center`` inside the volume, ``size_m`` and ``step_m`` at most the
    volume's diagonal, ``low_height_m`` at most its height, ``yaw_deg`` within one turn,
    ``yaw_turn_deg`` no more than ``max_yaw_rate_rad_s`` turns in MAX_MOTION_S."""
    if not isinstance(value, dict):
        raise _refuse("trajectory: an object like the configuration's trajectory section")
    if "file" in value:
        raise _refuse("trajectory: 'file' names a file on the ground station; send the "
                      "rows as 'waypoints'")
    try:
        section = TrajectoryConfig.model_validate(value)
    except ValidationError as exc:
        raise _refuse("trajectory: " + describe_problems(exc)) from None
    if section.name in ("none", "waypoints"):
        raise _refuse(f"trajectory: name {section.name!r}: give waypoints as 'waypoints'")
    extent = [hi - lo for lo, hi in (volume.x, volume.y, volume.z)]
    diagonal = math.hypot(*extent)
    for name, size, most in (("size_m", section.size_m, diagonal),
                             ("step_m", section.step_m, diagonal),
                             ("low_height_m", section.low_height_m, extent[2])):
        if size > most:
            raise CommandRefusedError("volume", f"trajectory: {name} {size:g} m: larger than "
                                      f"the flight volume ({most:.2f} m)")
    check_target(np.asarray(section.center, dtype=float), volume, "trajectory: center: ")
    if section.yaw_deg is not None and not abs(section.yaw_deg) <= 360.0:
        raise _refuse(f"trajectory: yaw_deg {section.yaw_deg:g}: a heading is within one "
                      "turn, [-360, 360] deg")
    most_turn = math.degrees(max_yaw_rate_rad_s) * MAX_MOTION_S
    if not abs(section.yaw_turn_deg) <= most_turn:
        raise _refuse(f"trajectory: yaw_turn_deg {section.yaw_turn_deg:g}: more than the "
                      f"yaw-rate limit turns in {MAX_MOTION_S:g} s ({most_turn:g} deg)")
    return section
