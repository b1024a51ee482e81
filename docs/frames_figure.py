"""Draw docs/frames.png: the lab's frames and where a flight's coordinates are.

Run from the repository root (needs matplotlib, the ``plot`` extra)::

    .venv/bin/python docs/frames_figure.py            # writes docs/frames.png

Left, from the side: Vicon Tracker's world frame (z up) and NED at the same origin
(Tracker's volume origin, on the floor), the flight volume (``safety.volume_x/y/z``), the
vehicle in the air with its FRD body frame and the Tracker object frame at its centre of
gravity, ``trajectory.center`` and the square flown around it, and the take-off from a
point elsewhere on the floor. Right, the same seen from above (north up, east right).
The numbers are the configuration's defaults, read from the package, so the figure
follows them.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from groundstation.config import validate_config
from groundstation.control.trajectories import make_trajectory

OUT = Path(__file__).resolve().parent / "frames.png"
TAKEOFF = np.array([0.8, -1.0, 0.0])  # an example take-off point on the floor, NED [m]
VEHICLE = np.array([-0.85, 0.85, -1.4])  # the vehicle drawn in flight, heading north
AXIS = 0.4  # length of a drawn frame axis [m]


def _arrow(ax, tail, vec, color, label, *, dashed=False, offset=(4, 4)):  # type: ignore[no-untyped-def]
    """A frame axis in plot coordinates: an arrow from ``tail`` along ``vec`` [m]."""
    ax.annotate("", xy=(tail[0] + vec[0], tail[1] + vec[1]), xytext=tail,
                arrowprops={"arrowstyle": "-|>", "color": color, "lw": 1.6,
                            "ls": "--" if dashed else "-", "shrinkA": 0, "shrinkB": 0})
    ax.annotate(label, (tail[0] + vec[0], tail[1] + vec[1]), textcoords="offset points",
                xytext=offset, color=color, fontsize=8)


def main() -> int:
    """Draw the figure into :data:`OUT`; 0 on success."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        from matplotlib.patches import Rectangle
    except ImportError:
        print("needs matplotlib: pip install 'groundstation[plot]'", file=sys.stderr)
        return 1
    cfg = validate_config({})
    s, t = cfg.safety, cfg.trajectory
    center = np.array(t.center)
    square = make_trajectory("square", center=center, size_m=t.size_m, period_s=t.period_s)
    corners = np.array([square.sample(k * t.period_s / 4).position for k in range(5)])
    start = corners[0]
    (x0, x1), (y0, y1), (z0, z1), m = s.volume_x, s.volume_y, s.volume_z, s.volume_margin_m

    fig, (side, top) = plt.subplots(1, 2, figsize=(13, 6.4),
                                    gridspec_kw={"width_ratios": [1.15, 1.0]})
    # ---- side view, looking west: north to the right, up is up (z up = -NED z)
    side.add_patch(Rectangle((x0, -z1), x1 - x0, z1 - z0, fill=False, color="0.6"))
    side.add_patch(Rectangle((x0 + m, -z1), x1 - x0 - 2 * m, z1 - z0 - m, fill=False,
                             color="0.8", ls="--"))
    side.axhline(0.0, color="0.3", lw=2.5)
    side.text(x1 - 0.02, 0.04, "floor: z = 0 (set Tracker's origin on it)", ha="right",
              fontsize=8, color="0.3")
    _arrow(side, (0.0, 0.0), (AXIS, 0.0), "C3", "x north (NED)", offset=(4, -12))
    _arrow(side, (0.0, 0.0), (0.0, -AXIS), "C3", "z down (NED)", offset=(4, -4))
    _arrow(side, (0.0, 0.0), (0.0, AXIS), "C0", "z up (Tracker)", dashed=True)
    side.annotate("origin: Tracker's volume origin = NED origin", (0.0, 0.0),
                  textcoords="offset points", xytext=(-150, -38), fontsize=8)
    side.plot(corners[:, 0], -corners[:, 2], color="C2", lw=3, solid_capstyle="butt")
    side.plot(center[0], -center[2], "o", color="C2")
    side.annotate(f"trajectory.center ({center[0]:g}, {center[1]:g}, {center[2]:g}):\n"
                  "1 m above the origin, wherever the\nvehicle took off",
                  (center[0], -center[2]), textcoords="offset points", xytext=(-170, -48),
                  color="C2", fontsize=8)
    side.plot([TAKEOFF[0], TAKEOFF[0], start[0]], [0.0, -start[2], -start[2]], ":",
              color="C1", lw=1.8)
    side.plot(TAKEOFF[0], 0.0, "o", color="C1")
    side.annotate("take-off point:\nstraight up, then\nto the start", (TAKEOFF[0], 0.0),
                  textcoords="offset points", xytext=(6, 40), color="C1", fontsize=8)
    body = np.array([VEHICLE[0], -VEHICLE[2]])
    side.plot([body[0] - 0.12, body[0] + 0.12], [body[1], body[1]], color="k", lw=3)
    _arrow(side, tuple(body), (AXIS * 0.8, 0.0), "k", "x forward (FRD)", offset=(2, 4))
    _arrow(side, tuple(body), (0.0, -AXIS * 0.8), "k", "z down (FRD)", offset=(4, 0))
    _arrow(side, tuple(body), (0.0, AXIS * 0.8), "C4", "z up (Tracker object)", dashed=True)
    side.annotate("the vehicle: both frames at\nits centre of gravity", tuple(body),
                  textcoords="offset points", xytext=(-40, -62), fontsize=8)
    side.set(xlim=(x0 - 0.2, x1 + 0.2), ylim=(-AXIS - 0.25, -z0 + 0.2), aspect="equal",
             xlabel="north [m] (NED x)", ylabel="height [m] (= -NED z)",
             title="side view (looking west): Tracker z up, NED z down, body FRD")
    side.grid(alpha=0.3)
    # ---- top view: north up, east right
    top.add_patch(Rectangle((y0, x0), y1 - y0, x1 - x0, fill=False, color="0.6"))
    top.add_patch(Rectangle((y0 + m, x0 + m), y1 - y0 - 2 * m, x1 - x0 - 2 * m, fill=False,
                            color="0.8", ls="--"))
    top.plot(corners[:, 1], corners[:, 0], color="C2", lw=3, label="the square (trajectory)")
    for k, c in enumerate(corners[:4]):
        where = {0: (-62, 4), 1: (4, 4), 2: (4, -12), 3: (-62, -12)}[k]
        top.annotate(f"({c[0]:+.3f}, {c[1]:+.3f})" + ("\nstart" if k == 0 else ""),
                     (c[1], c[0]), textcoords="offset points", xytext=where, fontsize=7)
    top.plot(center[1], center[0], "o", color="C2")
    top.plot([TAKEOFF[1], start[1]], [TAKEOFF[0], start[0]], ":", color="C1", lw=1.8,
             label="take-off: up, then to the start")
    top.plot(TAKEOFF[1], TAKEOFF[0], "o", color="C1")
    _arrow(top, (0.0, 0.0), (0.0, AXIS), "C3", "x north", offset=(4, -12))
    _arrow(top, (0.0, 0.0), (AXIS, 0.0), "C3", "y east (NED)", offset=(-10, -14))
    _arrow(top, (0.0, 0.0), (-AXIS, 0.0), "C0", "y Tracker", dashed=True, offset=(-30, 4))
    body = (VEHICLE[1], VEHICLE[0])
    _arrow(top, body, (0.0, AXIS * 0.7), "k", "x fwd", offset=(2, 2))
    _arrow(top, body, (AXIS * 0.7, 0.0), "k", "y right (FRD)", offset=(-20, 6))
    _arrow(top, body, (-AXIS * 0.7, 0.0), "C4", "y left (object)", dashed=True,
           offset=(-40, -14))
    top.text(y0 + 0.04, x0 + 0.05, f"safety.volume (solid), less volume_margin_m {m:g} m "
             "(dashed)", fontsize=7, color="0.4")
    top.set(xlim=(y0 - 0.2, y1 + 0.2), ylim=(x0 - 0.2, x1 + 0.2), aspect="equal",
            xlabel="east [m] (NED y)", ylabel="north [m] (NED x)",
            title="top view: heading from north, clockwise (east = 90 deg)")
    top.grid(alpha=0.3)
    top.legend(fontsize=8, loc="upper right")
    fig.tight_layout()
    fig.savefig(OUT, dpi=110)
    print(f"wrote {OUT}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
