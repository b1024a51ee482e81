"""Three vehicles fly a figure-eight each, in phase, from your own code.

Start a fleet that takes motion commands first, e.g. three virtual vehicles through the
Vicon relay (``gs fleet demo`` does all of this and this script's flight itself)::

    gs sim-device -c config/sim.yaml --fleet my-fleet.yaml --json   # prints each pty
    gs fleet up my-fleet.yaml                                        # relay + 3 daemons

(in the lab: ``gs fleet up config/fleet.yaml``), then run
``python examples/fleet_eight.py my-fleet.yaml``. The script waits until every vehicle
hovers, sends each one a figure-eight around its own hover point with one common
``start_at`` (so the three start together: in phase), waits until each has flown its lap,
and lands them all at once. Exit 0 only if every flight ended normally (COMPLETED).

Each eight is 1 m wide (east-west) and 0.5 m north-south: vehicles whose hover points are
1 m apart along north keep 0.5 m between their paths, clear of a fleet separation up to
0.5 m. A path that would come closer is refused (``TooClose``) before anything moves.
Frames: NED metres (1 m above the floor is z = -1), times in seconds.
"""

from __future__ import annotations

import argparse
import sys
import time

from groundstation.client import ClientError, Ended, Fleet, Refused, Status

EIGHT = {"name": "figure-eight", "size_m": 1.0, "period_s": 8.0}
START_IN_S = 4.0  # time for every vehicle to plan and fly to its eight's start [s]


def main() -> int:
    parser = argparse.ArgumentParser(description="Three figure-eights in phase.")
    parser.add_argument("fleet", help="the fleet file (fleet.yaml)")
    parser.add_argument("--identity", default=None, help="with TLS: this client's certificate")
    args = parser.parse_args()
    with Fleet(args.fleet, identity=args.identity) as fleet:
        try:
            hovering = fleet.wait_for_state("TRACK", timeout=120.0)
            start = time.time() + START_IN_S
            motions = {}
            for vehicle in fleet:
                status: Status = hovering[vehicle.name]
                centre = list(status.reference)  # its own hover point
                motions[vehicle.name] = vehicle.follow({**EIGHT, "center": centre},
                                                       start_at=start)
                print(f"{vehicle.name}: figure-eight around {centre}")
            for vehicle in fleet:
                vehicle.wait_until_arrived(motions[vehicle.name], timeout=30.0)
                print(f"{vehicle.name}: lap flown")
        except Refused as exc:
            print(f"refused ({exc.kind}): {exc.reason}", file=sys.stderr)
        except ClientError as exc:
            print(f"stopped: {exc}", file=sys.stderr)
        ended = fleet.land(wait=True)
    good = True
    for name, end in ended.items():
        print(f"{name}: {end}")
        good &= isinstance(end, Ended) and end.outcome == "COMPLETED"
    return 0 if good else 1


if __name__ == "__main__":
    sys.exit(main())
