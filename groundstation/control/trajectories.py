"""The named trajectories of thesis Ch. 11 and a waypoint file reader.

:func:`make_trajectory` builds one by name (the names of the configuration's
``trajectory.name``); :func:`build_trajectory` does the same from a
:class:`TrajectorySpec`, the record the configuration's section becomes. Frames:
NED, so a height of 1 m is ``z = -1``; seen from above, x (north) points up and y
(east) right, so clockwise is north -> east -> south -> west. Headings: ``yaw=None``
keeps the heading the vehicle has at take-off (free heading), a number [rad] is
absolute; a waypoint file's yaw column is absolute. These are the raw shapes;
:func:`groundstation.control.shaping.shape_for_flight` makes them flyable.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from groundstation.control.excitation import identification_flight
from groundstation.control.feasibility import FlightLimits, Volume
from groundstation.control.polyfile import is_polynomial_file, load_polynomial_file
from groundstation.control.table import parse_number, read_table
from groundstation.control.trajectory import (
    FigureEight,
    Hover,
    PiecewiseLinear,
    Trajectory,
    YawTurn,
)
from groundstation.errors import TrajectoryError
from groundstation.model.quadrotor import QuadrotorParams
from groundstation.types import FloatArray

_VEHICLE = QuadrotorParams()
"""The vehicle model's defaults (the rate loop's time constant of the identification
flight's pulses)."""

TRAJECTORY_NAMES = (
    "hover", "step-x", "step-y", "step-z", "square", "yz-rectangle", "low-hover",
    "figure-eight", "yaw-turn", "waypoints", "sysid",
)


def square(
    center: FloatArray | list[float] = (0.0, 0.0, -1.0),  # type: ignore[assignment]
    *,
    size_m: float = 0.75,
    period_s: float = 20.0,
    smoothing_s: float = 0.0,
    yaw: float | None = None,
) -> PiecewiseLinear:
    """The Ch. 11.3 square: ``size_m`` x ``size_m`` horizontal, clockwise seen from above.

    Starts at the north-west corner and flies east, south, west, north at the
    constant speed ``4 size_m / period_s`` (0.15 m/s for the thesis's 0.75 m and
    20 s), one lap per ``period_s``. Centre NED [m], default 1 m above the floor.
    """
    c = np.asarray(center, dtype=float)
    h = 0.5 * size_m
    corners = [(+h, -h), (+h, +h), (-h, +h), (-h, -h), (+h, -h)]  # NW, NE, SE, SW, NW
    points = np.array([[c[0] + dx, c[1] + dy, c[2]] for dx, dy in corners])
    times = np.linspace(0.0, period_s, 5)
    return PiecewiseLinear(times, points, periodic=True, smoothing_s=smoothing_s, yaw=yaw,
                           name="square")


def yz_rectangle(
    center: FloatArray | list[float] = (0.0, 0.0, -1.0),  # type: ignore[assignment]
    *,
    width_m: float = 0.75,
    height_m: float = 0.5,
    period_s: float = 20.0,
    smoothing_s: float = 0.0,
    yaw: float | None = None,
) -> PiecewiseLinear:
    """The rectangle of Fig. 11.7 in the vertical y-z plane (x fixed).

    ``width_m`` along y (east), ``height_m`` vertically; the figure prints no
    dimensions, so the defaults keep it inside the Table B.1 volume. Starts at
    the upper west corner, flies east along the top, down, west along the
    bottom and up again; the time per edge is proportional to its length
    (constant speed ``2 (width + height) / period_s``).
    """
    c = np.asarray(center, dtype=float)
    w, h = 0.5 * width_m, 0.5 * height_m
    corners = [(-w, -h), (+w, -h), (+w, +h), (-w, +h), (-w, -h)]  # (dy, dz); -dz is up
    points = np.array([[c[0], c[1] + dy, c[2] + dz] for dy, dz in corners])
    lengths = np.linalg.norm(np.diff(points, axis=0), axis=1)
    times = np.concatenate([[0.0], np.cumsum(lengths)]) * (period_s / float(np.sum(lengths)))
    return PiecewiseLinear(
        times, points, periodic=True, smoothing_s=smoothing_s, yaw=yaw, name="yz-rectangle"
    )


def load_waypoints(path: str | Path, *, smoothing_s: float = 0.0,
                   yaw: float | None = None) -> PiecewiseLinear:
    """Read a CSV of ``t, x, y, z[, yaw]`` rows (s, NED m, heading) into an open path.

    Separated by commas, semicolons (decimal commas read), tabs or whitespace, as
    spreadsheets and numpy write tables (:mod:`groundstation.control.table`). A first
    content line that is not numeric is a header, and so is a comment line just before
    the first row with as many names (numpy's ``savetxt(header=...)``); blank lines and
    lines starting with ``#`` are skipped. Times are taken relative to the first
    row and must increase strictly; the path holds the last point at the end.
    A yaw column gives absolute headings (unwrapped: a step across +-pi is the
    short way) in radians, or in degrees when the header names the column ``yaw_deg``
    (any name with "deg"; ``yaw``, ``yaw_rad`` or no header: radians); without one the
    heading is ``yaw`` [rad] (None: free heading). Raises TrajectoryError naming the
    line of any problem. Whether the rows are corners or samples of a curve is decided
    when the path is shaped (:func:`~groundstation.control.shaping.shape_for_flight`).
    """
    return waypoints_from_rows(read_waypoint_rows(path), smoothing_s=smoothing_s, yaw=yaw,
                               source=str(path))


def yaw_unit(header: Sequence[str]) -> float:
    """Radians per unit of a waypoint header's heading column (the fifth): ``pi / 180``
    when its name mentions degrees (``yaw_deg``, ``yaw [deg]``), else 1 (radians)."""
    if len(header) < 5:
        return 1.0
    return math.pi / 180.0 if "deg" in header[4].strip().lower() else 1.0


def read_waypoint_rows(path: str | Path) -> list[list[float]]:
    """The ``t, x, y, z[, yaw]`` rows of a waypoint CSV, headings in radians (see
    :func:`load_waypoints`); TrajectoryError naming the line of a problem."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise TrajectoryError(f"{path}: cannot read waypoints: {exc.strerror}") from exc
    except UnicodeDecodeError:
        raise TrajectoryError(f"{path}: cannot read waypoints: not UTF-8 text") from None
    table = read_table(text)
    rows: list[list[float]] = []
    named = table.comment_header  # numpy's savetxt(header=...): a header as a comment
    width = len(table.rows[0][1]) if table.rows else 0
    unit = yaw_unit(named) if named is not None and len(named) == width else 1.0
    for index, (lineno, row) in enumerate(table.rows):
        try:
            values = [parse_number(cell, table.delimiter) for cell in row]
        except ValueError:
            if index == 0:
                unit = yaw_unit(row)
                continue
            raise TrajectoryError(f"{path}:{lineno}: not a number in {row!r:.80}") from None
        if len(values) == 5:
            values[4] *= unit
        if len(values) not in (4, 5) or not all(math.isfinite(v) for v in values):
            raise TrajectoryError(
                f"{path}:{lineno}: expected 4 or 5 finite values (t, x, y, z[, yaw]), "
                f"found {row!r}"
            )
        if rows and len(values) != len(rows[0]):
            raise TrajectoryError(f"{path}:{lineno}: row has {len(values)} columns, "
                                  f"the first had {len(rows[0])}")
        rows.append(values)
    return rows


def waypoints_from_rows(rows: Sequence[Sequence[float]], *, smoothing_s: float = 0.0,
                        yaw: float | None = None, source: str = "waypoints") -> PiecewiseLinear:
    """An open path through ``rows`` of ``t, x, y, z[, yaw]`` (s, NED m, rad), as
    :func:`load_waypoints` reads them from a file; TrajectoryError, starting with
    ``source``, for fewer than 2 rows, rows of other lengths or values that are not finite
    numbers, or times that do not increase."""
    if len(rows) < 2:
        raise TrajectoryError(f"{source}: needs at least 2 waypoints, found {len(rows)}")
    width = len(rows[0])
    for k, row in enumerate(rows):
        if len(row) != width or width not in (4, 5) or not all(
                isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)
                for v in row):
            raise TrajectoryError(f"{source}: waypoint {k}: expected 4 or 5 finite values "
                                  f"(t, x, y, z[, yaw]) like the first, found {list(row)!r:.80}")
    data = np.array(rows, dtype=float)
    headings: float | FloatArray | None = data[:, 4] if data.shape[1] == 5 else yaw
    try:
        return PiecewiseLinear(data[:, 0] - data[0, 0], data[:, 1:4], smoothing_s=smoothing_s,
                               yaw=headings, name="waypoints")
    except TrajectoryError as exc:
        raise TrajectoryError(f"{source}: {exc}") from None


def make_trajectory(
    name: str,
    *,
    center: FloatArray | list[float] | tuple[float, float, float] = (0.0, 0.0, -1.0),
    size_m: float = 0.75,
    period_s: float = 20.0,
    step_m: float = 0.5,
    step_time_s: float = 1.0,
    low_height_m: float = 0.02,
    corner_smoothing_s: float = 0.0,
    file: str | Path | None = None,
    yaw: float | None = None,
    yaw_turn: float = 2.0 * math.pi,
    relative: bool = True,
    limits: FlightLimits | None = None,
    volume: Volume | None = None,
    rate_tau_s: float = _VEHICLE.rate_tau,
) -> Trajectory:
    """Build a named trajectory (the names of the configuration's ``trajectory.name``).

    hover: hold ``center``. step-x / step-y: hold ``center``, then at
    ``step_time_s`` step ``step_m`` north / east. step-z: step ``step_m`` *up*
    (z decreases; a step towards the floor is the riskier test). square: Ch. 11.3.
    yz-rectangle: Fig. 11.7 (width ``size_m``, height ``2/3 size_m``).
    low-hover: ``center`` in x, y at ``low_height_m`` above the floor (Ch. 11.4).
    figure-eight: lemniscate ``size_m`` wide, one lap per ``period_s``.
    yaw-turn: hold ``center`` while the heading turns by ``yaw_turn`` [rad] over
    ``period_s``. waypoints: the CSV ``file``, a waypoint list (see
    :func:`load_waypoints`) or a polynomial file recognised by its header
    (:mod:`~groundstation.control.polyfile`; ``relative``: its start placed at
    ``center``). sysid: the identification flight at ``center``
    (:func:`~groundstation.control.excitation.identification_flight`), its amplitudes from
    ``limits``, ``volume`` and the rate loop's ``rate_tau_s`` [s] (defaults: the model's
    and Table B.1's), at heading ``yaw`` (None: north). ``yaw`` [rad]: the heading (the
    start heading of yaw-turn); None keeps the heading at take-off (free heading).
    """
    c = np.asarray(center, dtype=float)
    steps = {"step-x": (step_m, 0.0, 0.0), "step-y": (0.0, step_m, 0.0),
             "step-z": (0.0, 0.0, -step_m)}
    if name == "hover":
        return Hover(c, yaw=yaw)
    if name in steps:
        return Hover(c, step=list(steps[name]), step_time=step_time_s, yaw=yaw, name=name)
    if name == "square":
        return square(c, size_m=size_m, period_s=period_s, smoothing_s=corner_smoothing_s,
                      yaw=yaw)
    if name == "yz-rectangle":
        return yz_rectangle(c, width_m=size_m, height_m=size_m * 2.0 / 3.0, period_s=period_s,
                            smoothing_s=corner_smoothing_s, yaw=yaw)
    if name == "low-hover":
        return Hover([c[0], c[1], -low_height_m], yaw=yaw, name="low-hover")
    if name == "figure-eight":
        return FigureEight(c, width_m=size_m, period_s=period_s, yaw=yaw)
    if name == "yaw-turn":
        return YawTurn(c, turn=yaw_turn, period_s=period_s, yaw=yaw)
    if name == "sysid":
        return identification_flight(
            c, 0.0 if yaw is None else yaw, limits if limits is not None else FlightLimits(),
            volume if volume is not None else Volume((-1.5, 1.5), (-1.5, 1.5), (-2.0, 0.05),
                                                     margin_m=0.1, name="safety.volume"),
            rate_tau_s)
    if name == "waypoints":
        if file is None:
            raise TrajectoryError("trajectory 'waypoints' needs a file")
        return load_trajectory_file(file, center=c, relative=relative, yaw=yaw,
                                    smoothing_s=corner_smoothing_s)
    raise TrajectoryError(f"unknown trajectory {name!r}; known: {', '.join(TRAJECTORY_NAMES)}")


def load_trajectory_file(path: str | Path, *, center: FloatArray | list[float],
                         relative: bool = True, yaw: float | None = None,
                         smoothing_s: float = 0.0) -> Trajectory:
    """A trajectory file as its header says: a uav_trajectories / Crazyswarm polynomial
    file (``Duration,x^0,...``; its start at ``center`` if ``relative``) or a waypoint
    CSV (``t,x,y,z[,yaw]``)."""
    if is_polynomial_file(path):
        return load_polynomial_file(path, origin=center if relative else None, yaw=yaw)
    return load_waypoints(path, smoothing_s=smoothing_s, yaw=yaw)


@dataclass(frozen=True, slots=True)
class TrajectorySpec:
    """A named trajectory as the configuration's ``trajectory`` section or a client's
    ``follow`` request gives it: :func:`make_trajectory`'s arguments (angles in radians).

    name : one of :data:`TRAJECTORY_NAMES` (or ``"none"``: flown by run-time commands)
    center : NED [m]; size_m, step_m, low_height_m : [m]; period_s : one lap [s]
    corner_smoothing_s : [s]; file : a waypoint or polynomial file (``waypoints``)
    yaw : heading [rad] (None: the one at take-off); yaw_turn : a yaw-turn's turn [rad]
    relative : a polynomial file's positions are relative to its start, placed at center
    """

    name: str
    center: tuple[float, float, float]
    size_m: float
    period_s: float
    step_m: float
    low_height_m: float
    corner_smoothing_s: float
    file: Path | None
    yaw: float | None
    yaw_turn: float
    relative: bool


def build_trajectory(spec: TrajectorySpec, **overrides: Any) -> Trajectory:
    """:func:`make_trajectory` for ``spec`` (``overrides`` replace or add arguments: a
    step time, the identification flight's limits); the raw shape, not yet shaped."""
    params: dict[str, Any] = {
        "center": spec.center, "size_m": spec.size_m, "period_s": spec.period_s,
        "step_m": spec.step_m, "low_height_m": spec.low_height_m,
        "corner_smoothing_s": spec.corner_smoothing_s, "file": spec.file, "yaw": spec.yaw,
        "yaw_turn": spec.yaw_turn, "relative": spec.relative,
    }
    params.update(overrides)
    return make_trajectory(spec.name, **params)
