"""A trajectory to look at before flying it (``gs trajectory FILE --plot OUT.png``).

Three panels: the top view (NED seen from above: north up, east right) with the volume
a reference may reach and, for fitted samples, the samples themselves; the speed over
time with its limit; the tilt over time with its limit. matplotlib is the ``plot``
extra (:func:`groundstation.evaluation.plotting.pyplot` says so when it is missing).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from groundstation.control.curve import Samples
from groundstation.control.feasibility import FlightLimits, Volume
from groundstation.control.peaks import Vehicle, norm, tilt_angle
from groundstation.control.shaping import TimeWarp
from groundstation.control.splines import FittedPath
from groundstation.control.trajectory import Trajectory
from groundstation.evaluation.plotting import pyplot, save, top_view

POINTS = 2000
"""Samples drawn along the trajectory."""


def _samples(trajectory: Trajectory, times: np.ndarray) -> Samples:
    many = getattr(trajectory, "sample_many", None)
    if many is not None:
        out: Samples = many(times)
        return out
    return Samples.of([trajectory.sample(float(t)) for t in times])


def trajectory_figure(trajectory: Trajectory, duration_s: float, limits: FlightLimits,
                      volume: Volume | None, path: Path, title: str = "") -> Path:
    """Draw ``trajectory`` over ``[0, duration_s]`` [s] against ``limits`` and ``volume``
    into the PNG ``path``; GroundStationError if matplotlib is missing."""
    plt = pyplot()
    t = np.linspace(0.0, duration_s, POINTS)
    s = _samples(trajectory, t)
    veh = Vehicle(limits.mass_kg, limits.gravity, limits.induced_inflow)
    fig = plt.figure(figsize=(11, 5.5), layout="constrained")
    grid = fig.add_gridspec(2, 2, width_ratios=[1.1, 1.0])
    top = fig.add_subplot(grid[:, 0])
    speed_ax = fig.add_subplot(grid[0, 1])
    tilt_ax = fig.add_subplot(grid[1, 1], sharex=speed_ax)
    top.plot(s.position[:, 1], s.position[:, 0], lw=1.3, label="flown reference")
    base = trajectory.base if isinstance(trajectory, TimeWarp) else trajectory
    if isinstance(base, FittedPath) and len(base.sample_points):
        top.plot(base.sample_points[:, 1], base.sample_points[:, 0], ".", ms=2.5, alpha=0.6,
                 label=f"the file's {len(base.sample_points)} samples")
    top.plot(s.position[0, 1], s.position[0, 0], "o", color="g", label="start")
    top.plot(s.position[-1, 1], s.position[-1, 0], "s", color="r", mfc="none", label="end")
    if volume is not None:
        lo, hi = volume.allowed()
        top.plot([lo[1], hi[1], hi[1], lo[1], lo[1]], [lo[0], lo[0], hi[0], hi[0], lo[0]],
                 "k--", lw=0.8, label="volume less its margin")
    top_view(top, title or f"{trajectory.name}: top view")
    top.legend(loc="upper left", fontsize=8)
    speed = norm(s.velocity)
    speed_ax.plot(t, speed, lw=1.2, label="speed")
    speed_ax.set_ylim(0.0, 1.15 * max(limits.max_speed_m_s, float(np.max(speed))))
    speed_ax.axhline(limits.max_speed_m_s, color="r", ls="--", lw=0.9,
                     label=f"limit {limits.max_speed_m_s:.2f} m/s")
    speed_ax.set(ylabel="speed [m/s]", title="speed and tilt over the flight")
    speed_ax.legend(loc="upper right", fontsize=8)
    speed_ax.grid(True, alpha=0.3)
    tilt = np.degrees(tilt_angle(veh, s))
    tilt_ax.plot(t, tilt, lw=1.2, color="tab:orange", label="tilt")
    tilt_ax.set_ylim(0.0, 1.15 * max(math.degrees(limits.max_tilt_rad), float(np.max(tilt))))
    tilt_ax.axhline(math.degrees(limits.max_tilt_rad), color="r", ls="--", lw=0.9,
                    label=f"limit {math.degrees(limits.max_tilt_rad):.1f} deg")
    tilt_ax.set(xlabel="time on the trajectory [s]", ylabel="tilt [deg]")
    tilt_ax.legend(loc="upper right", fontsize=8)
    tilt_ax.grid(True, alpha=0.3)
    return save(fig, path)
