"""``gs fleet demo`` (``make demo FLEET=3``): a virtual fleet flies figure-eights in phase.

The virtual lab with N vehicles (at most three: the lab's 3 m volume holds three eights
0.5 m apart) standing 1 m apart along north, one Tracker stream carrying all of them,
``gs vicon-relay``, one daemon per vehicle, all processes of their own
(:class:`~groundstation.fleetops.virtual.VirtualFleet`). Through
:class:`groundstation.client.Fleet`: wait until every vehicle hovers, then each flies one
figure-eight (1 m east-west, 0.5 m north-south, 8 s a lap) around its own home, all
starting at the same ``start_at``, then all land at once. Each vehicle's tracking is
judged against the truth (:mod:`.judge`) and printed; the fleet's separation (0.4 m) is
on throughout.
"""

from __future__ import annotations

import json
import math
import threading
import time
from collections.abc import Callable
from pathlib import Path

from groundstation.config import load_config
from groundstation.errors import ConfigError
from groundstation.fleetops.judge import rms, tracking
from groundstation.fleetops.virtual import VirtualFleet, write_fleet
from groundstation.flight.supervisor import State

SPACING_M = 1.0
"""Distance between the vehicles' homes, along north [m]."""
PERIOD_S = 8.0
"""One lap of the figure-eight [s]."""
EIGHT: dict[str, object] = {"name": "figure-eight", "size_m": 1.0, "period_s": PERIOD_S}
"""Each vehicle's lap: 1.0 m wide (east-west), 0.5 m north-south, 8 s."""
START_IN_S = 4.0
"""How far ahead the common start is set [s]: every vehicle plans and flies to its start."""
TAKEOFF_WAIT_S = 120.0
"""How long the demo waits for every vehicle to hover [s] (a loaded machine)."""


def homes(n: int) -> list[tuple[float, float]]:
    """N homes ``SPACING_M`` apart along north, centred on the lab's origin."""
    return [((k - (n - 1) / 2.0) * SPACING_M, 0.0) for k in range(n)]


def quiet(echo: Callable[[str], None]) -> Callable[[str], None]:
    """``echo`` without the processes' JSON log events below warning (the progress lines,
    the summaries and every warning or error still go through)."""
    def say(line: str) -> None:
        _, sep, rest = line.partition("] ")
        if sep and rest.startswith("{"):
            try:
                level = json.loads(rest).get("level")
            except ValueError:
                level = None
            if level in ("debug", "info"):
                return
        echo(line)
    return say


def run_demo(config: Path, n: int, workdir: Path, *, echo: Callable[[str], None],
             stop: threading.Event) -> dict[str, int]:
    """Fly the demo (see the module docstring); each daemon's exit code."""
    from groundstation.client import Fleet

    base = load_config(config)
    if base.sim is None:
        raise ConfigError(f"{config}: the demo needs a configuration with a sim: section "
                          "(config/sim.yaml)")
    fleet_file = write_fleet(workdir, base, homes(n), separation_m=0.4)
    echo(f"fleet file: {fleet_file}")
    with VirtualFleet(fleet_file, echo=quiet(echo)) as vf:
        with Fleet(vf.run_file) as fleet:
            fleet.wait_for_state("TRACK", timeout=TAKEOFF_WAIT_S)
            start = time.time() + START_IN_S
            motions = {}
            for vehicle, (x, y) in zip(fleet, homes(n), strict=True):
                center = [x, y, -1.0]
                motions[vehicle.name] = vehicle.follow({**EIGHT, "center": center},
                                                       start_at=start)
                echo(f"{vehicle.name}: figure-eight around {center} from "
                     f"{time.strftime('%H:%M:%S', time.localtime(start))}")
            for vehicle in fleet:
                if stop.is_set():
                    break
                vehicle.wait_until_arrived(motions[vehicle.name],
                                           timeout=START_IN_S + 3 * PERIOD_S)
            for name, ended in fleet.land(wait=True).items():
                echo(f"{name}: {ended}")
        codes = vf.wait()
    for name in vf.names:
        track = tracking(vf.log_dir(name), vf.truth_files[name])
        eight = track.window(State.TRACK)
        hover = track.window(State.TRACK, 2.0, at_rest=True)
        echo(f"{name}: exit {codes.get(name)}; truth vs reference while tracking RMS "
             f"{100 * rms(eight):.2f} cm, max {100 * max(eight, default=math.nan):.2f} cm; "
             f"at rest RMS {100 * rms(hover):.2f} cm; log {vf.log_dir(name)}")
    return codes
