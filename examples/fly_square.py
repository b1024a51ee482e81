"""Fly a square from your own code through the ground station's run-time API.

Start a daemon that takes motion commands first, e.g. in the virtual lab::

    gs fly --config config/sim.yaml --demo --trajectory none

then run ``python examples/fly_square.py``. The script waits for the take-off, flies
the four corners of a 0.75 m square centred on (0, 0) at 1 m height, prints how close
each arrival was and how fast the vehicle reacted, and lands. Exit code 0 only if the
flight ended normally (COMPLETED: landed and handed back, no failsafe), else 1.

Frames: NED metres, so 1 m above the floor is z = -1; headings in degrees from north
(``go_to(corner, yaw_deg=90)`` would face east). The ground station plans and checks every
motion (volume, speed, tilt); one it cannot fly is refused with a reason.
"""

from __future__ import annotations

import argparse
import math
import sys

from groundstation.client import (
    DEFAULT_CONTROL,
    DEFAULT_TELEMETRY,
    Client,
    ClientError,
    DaemonUnreachableError,
    NotNow,
    Preempted,
    Refused,
)

SIDE_M = 0.75  # side of the square [m]
HEIGHT_M = 1.0  # above the floor [m]


def main() -> int:
    parser = argparse.ArgumentParser(description="Fly a square through the run-time API.")
    parser.add_argument("--control", "--endpoint", default=DEFAULT_CONTROL,
                        help="the daemon's telemetry.control_endpoint (--endpoint: the former "
                             "name, as in gs)")
    parser.add_argument("--telemetry", default=DEFAULT_TELEMETRY,
                        help="the daemon's telemetry.endpoint (to see the flight end)")
    parser.add_argument("--server-key", help="the daemon's public key (CURVE)")
    parser.add_argument("--client-key", help="this client's .key_secret file (CURVE)")
    args = parser.parse_args()

    gs = Client(args.control, telemetry=args.telemetry, timeout_s=5.0,
                server_key=args.server_key, client_key=args.client_key)
    h = SIDE_M / 2
    corners = [(h, h, -HEIGHT_M), (h, -h, -HEIGHT_M), (-h, -h, -HEIGHT_M), (-h, h, -HEIGHT_M)]
    try:
        # the daemon takes off by itself; this waits for TRACK and settles at 1 m
        gs.takeoff(HEIGHT_M, timeout=60.0)
        print(f"airborne at {gs.status().position}")
        for i, corner in enumerate(corners, start=1):
            try:
                gs.go_to(corner, wait=True)  # blocks until arrived (or raises)
            except Refused as exc:  # OutsideVolume, Infeasible, NotNow, Busy, BadRequest
                print(f"corner {i}/4 refused ({exc.kind}): {exc.reason}")
                if isinstance(exc, NotNow):  # no motions now (a failsafe acts): stop here
                    break
                continue
            now = gs.status()
            error = math.dist(now.position, corner) if now.position else math.nan
            latency = now.motion.latency_s if now.motion else None
            latency_ms = f"{1e3 * latency:.0f} ms" if latency is not None else "--"
            print(f"corner {i}/4 at ({corner[0]:+.3f}, {corner[1]:+.3f}, {corner[2]:+.3f}) m: "
                  f"arrived, error {100 * error:.1f} cm, command-to-motion latency "
                  f"{latency_ms}")
    except DaemonUnreachableError as exc:  # no daemon at the endpoint (or wrong keys)
        print(f"error: {exc}")
        return 1
    except Preempted as exc:  # a failsafe took over: the ground station is landing
        print(f"pre-empted: {exc}")
    except ClientError as exc:  # a wait that timed out: land all the same
        print(f"error: {exc}")
    except KeyboardInterrupt:
        print("interrupted: landing")

    try:
        try:
            ended = gs.land(wait=True, timeout=60.0)  # returns once landed and handed back
        except NotNow:  # already landing (a failsafe): wait for the end instead
            ended = gs.wait_until_ended(timeout=60.0)
    except ClientError as exc:
        print(f"error: {exc}")
        return 1
    assert ended is not None  # land(wait=True) always reports the end
    print(f"flight ended in {ended.state} ({ended.outcome}): {ended.reason}")
    return 0 if ended.outcome == "COMPLETED" else 1


if __name__ == "__main__":
    sys.exit(main())
