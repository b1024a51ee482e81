"""Piecewise-polynomial trajectory files as Crazyswarm and uav_trajectories write them.

The format (github.com/whoenig/uav_trajectories, read by Crazyswarm and the Crazyflie
high-level commander): a CSV (or a table of another delimiter,
:mod:`groundstation.control.table`) whose header is ``Duration,x^0,...,x^7,y^0,...,y^7,
z^0,...,z^7,yaw^0,...,yaw^7``, one row per segment: its duration [s], then the
coefficients of each axis, lowest power first, in the time since the segment's start
(restarting at 0 in each segment). Positions are in metres in the Crazyflie's world
(x forward, y left, z up), the heading in radians counter-clockwise about z up. Any
degree is read (the header names the powers); columns are found by name.

Converted to the ground station's frames: NED ``(x, -y, -z)`` (the Crazyflie's x is
taken as north) and the heading ``-yaw`` (clockwise seen from above, from north).
Positions are relative to the start unless configured absolute (as the Crazyflie's
``start_trajectory(relative=True)``): the file's first point is placed at ``origin``
(``trajectory.center``) and the heading is relative to the heading at take-off (free
heading), or to ``yaw`` [rad] when one is configured. With absolute positions the file's
coordinates are the lab's (after the same axis conversion) and a heading column that is
not all zero is absolute. A file whose heading coefficients are all zero leaves the
heading to the configuration (free, or ``trajectory.yaw_deg``).
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np

from groundstation.control.polynomial import PiecewisePolynomial
from groundstation.control.table import parse_number, read_table
from groundstation.errors import TrajectoryError
from groundstation.types import FloatArray

_POWER = re.compile(r"^\s*(x|y|z|yaw)\s*\^\s*(\d+)\s*$", re.IGNORECASE)
AXES = ("x", "y", "z", "yaw")
TO_NED = np.array([1.0, -1.0, -1.0, -1.0])
"""Crazyflie world (x forward, y left, z up, yaw counter-clockwise) to NED and heading."""


def is_polynomial_file(path: str | Path) -> bool:
    """True when the file's first content line is a ``Duration,x^0,...`` header."""
    try:
        head = Path(path).read_text(encoding="utf-8", errors="replace")[:4096]
    except OSError:
        return False
    rows = read_table(head).rows
    return bool(rows) and rows[0][1][0].strip().lower() == "duration"


def load_polynomial_file(path: str | Path, *, origin: FloatArray | list[float] | None,
                         yaw: float | None = None) -> PiecewisePolynomial:
    """Read a uav_trajectories / Crazyswarm polynomial file (see the module doc).

    origin : NED point [m] where the file's start is placed (relative positions), or None
    for absolute positions; yaw : the start heading [rad] of a relative heading (None:
    free heading). TrajectoryError naming the file and line of any problem.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        reason = exc.strerror if isinstance(exc, OSError) else "not UTF-8 text"
        raise TrajectoryError(f"{path}: cannot read the polynomial file: {reason}") from exc
    table = read_table(text)
    rows = table.rows
    if not rows:
        raise TrajectoryError(f"{path}: empty polynomial file")
    header_line, header = rows[0]
    columns = _columns(path, header_line, header)
    degree = max(k for _, k in columns.values())
    durations, coef = [], []
    for lineno, row in rows[1:]:
        if len(row) != len(header):
            raise TrajectoryError(f"{path}:{lineno}: {len(row)} columns, the header has "
                                  f"{len(header)}")
        try:
            values = [parse_number(cell, table.delimiter) for cell in row]
        except ValueError:
            raise TrajectoryError(f"{path}:{lineno}: not a number in {row!r:.80}") from None
        if not all(math.isfinite(v) for v in values):
            raise TrajectoryError(f"{path}:{lineno}: values must be finite numbers")
        if not values[0] > 0.0:
            raise TrajectoryError(f"{path}:{lineno}: a segment's duration must be > 0 s, "
                                  f"found {values[0]:g}")
        c = np.zeros((degree + 1, 4))
        for col, (axis, power) in columns.items():
            c[power, axis] = values[col]
        durations.append(values[0])
        coef.append(c * TO_NED[None, :])
    if not durations:
        raise TrajectoryError(f"{path}: no segments after the header")
    coefficients = np.array(coef)
    breaks = np.concatenate([[0.0], np.cumsum(durations)])
    start = coefficients[0, 0, :].copy()
    turns = bool(np.any(coefficients[:, :, 3] != 0.0))
    relative = origin is not None
    if relative:
        coefficients[:, 0, :3] += np.asarray(origin, dtype=float) - start[:3]
    if relative or not turns:  # the heading: relative to the start, or the configuration's
        coefficients[:, 0, 3] += (0.0 if yaw is None else yaw) - start[3]
        free = yaw is None
    else:
        free = False
    where = "its start placed at the configured centre" if relative else "absolute positions"
    description = (f"polynomial segments (uav_trajectories / Crazyswarm file {path.name}): "
                   f"{len(durations)} segments of degree {degree}, {breaks[-1]:.2f} s, "
                   f"{where}, x forward -> north, y left -> east negated, z up -> down")
    try:
        return PiecewisePolynomial(breaks, coefficients, free_heading=free, name="waypoints",
                                   description=description)
    except TrajectoryError as exc:
        raise TrajectoryError(f"{path}: {exc}") from None


def _columns(path: Path, lineno: int, header: list[str]) -> dict[int, tuple[int, int]]:
    """Column index -> (axis 0..3, power) from the header; TrajectoryError if malformed."""
    out: dict[int, tuple[int, int]] = {}
    seen: set[tuple[int, int]] = set()
    for col, name in enumerate(header[1:], start=1):
        match = _POWER.match(name)
        if match is None:
            raise TrajectoryError(f"{path}:{lineno}: column {col + 1} {name!r} is not "
                                  "x^k, y^k, z^k or yaw^k")
        key = (AXES.index(match.group(1).lower()), int(match.group(2)))
        if key in seen:
            raise TrajectoryError(f"{path}:{lineno}: column {name!r} appears twice")
        seen.add(key)
        out[col] = key
    if not out or max(k for _, k in out.values()) > 15:
        raise TrajectoryError(f"{path}:{lineno}: expected coefficient columns x^0 ... "
                              "yaw^7 (degree at most 15)")
    return out
