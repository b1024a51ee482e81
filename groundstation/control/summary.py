"""A trajectory's check for people: what it was taken to be, its peaks against the limits,
the verdict (``gs trajectory``, ``gs check-config``).

Pure text: the caller prints the lines. Units as the configuration writes them: metres,
m/s, m/s^2, m/s^3, degrees, deg/s, rad/s for the body rate, newtons.
"""

from __future__ import annotations

import math

from groundstation.control.feasibility import FeasibilityReport, FlightLimits, Volume


def check_lines(name: str, description: str, duration_s: float, report: FeasibilityReport,
                limits: FlightLimits, volume: Volume | None) -> list[str]:
    """The lines of one trajectory's check: ``name``, ``description`` (what it was taken
    to be), how long it is flown [s], every peak next to its limit, and the verdict with
    one line per broken limit."""
    r, n = report, limits.names
    rows: list[tuple[str, str, str, str]] = [
        ("speed", f"{r.max_speed_m_s:.2f} m/s", f"{limits.max_speed_m_s:.2f} m/s", n.speed),
        ("acceleration", f"{r.max_accel_m_s2:.2f} m/s^2",
         f"{limits.max_accel_m_s2:.2f} m/s^2", f"level flight at {n.tilt}"),
        ("jerk", f"{r.max_jerk_m_s3:.2f} m/s^3", "-", ""),
        ("tilt", f"{math.degrees(r.max_tilt_rad):.1f} deg",
         f"{math.degrees(limits.max_tilt_rad):.1f} deg", n.tilt),
        ("tilt rate", f"{r.max_tilt_rate_rad_s:.2f} rad/s", f"{limits.max_rate_rad_s:.2f} rad/s",
         n.tilt_rate),
        ("yaw rate", f"{math.degrees(r.max_yaw_rate_rad_s):.1f} deg/s",
         f"{math.degrees(limits.max_yaw_rate_rad_s):.1f} deg/s", n.yaw_rate),
        ("lift (thrust)", f"{r.min_lift_n:.2f} .. {r.max_lift_n:.2f} N",
         f"{limits.lift_min_n:.2f} .. {limits.lift_max_n:.2f} N", n.lift),
    ]
    lo, hi = volume.allowed() if volume is not None else (None, None)
    for axis, label in enumerate(("north x", "east y", "down z")):
        allowed = (f"{lo[axis]:.2f} .. {hi[axis]:.2f} m" if lo is not None and hi is not None
                   else "-")
        where = f"{volume.name}_{'xyz'[axis]}" if volume is not None else ""
        rows.append((label, f"{r.extent_min_m[axis]:.2f} .. {r.extent_max_m[axis]:.2f} m",
                     allowed, where))
    parts = description.split("; ")
    out = [f"trajectory {name!r}: {parts[0]}"] + [f"  {part}" for part in parts[1:]] + [
           f"  flown for {duration_s:.2f} s; checked: {r.method} ({r.pieces} pieces)",
           f"  {'peak':<14} {'value':<18} {'limit':<18} set by"]
    out += [f"  {a:<14} {b:<18} {c:<18} {d}".rstrip() for a, b, c, d in rows]
    if r.position_jumps or r.velocity_jumps:
        out.append(f"  jumps: {len(r.position_jumps)} in position (largest "
                   f"{max((s for _, s in r.position_jumps), default=0.0):.2f} m), "
                   f"{len(r.velocity_jumps)} in velocity (largest "
                   f"{max((s for _, s in r.velocity_jumps), default=0.0):.2f} m/s)")
    if r.feasible:
        out.append("  verdict: flyable within the limits")
    else:
        out.append(f"  verdict: refused, {len(r.problems)} limit(s) broken:")
        out += [f"    {p}" for p in r.problems]
    return out
