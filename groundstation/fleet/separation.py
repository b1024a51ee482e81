"""Separation between the vehicles of a fleet: pure functions, no I/O, no clock.

The rules (``fleet.separation_m``, README "Fleet"):

* **At planning** (:func:`check_path`): a motion is refused if any point of its path comes
  within the separation of anywhere a peer is or is planned to be (its estimated position
  and its :class:`~groundstation.fleet.messages.Intent`), unless it stays at least as far
  as the vehicle already is (a motion that opens a gap that is too small is allowed). The
  check is spatial, not timed: it needs no clock shared between lab PCs, and a path that
  a peer will have left by then is refused all the same (conservative).
* **Before flight** (the fleet file, :mod:`groundstation.config.fleetfile`): the homes at
  least the separation apart, and two vehicles' volumes overlapping only with it on.
* **In flight** (the supervisor, ``flight/supervisor.py``): closer than the separation to a
  peer's estimate, both hold; closer than half of it, both land (:func:`nearest` gives the
  distance the daemon hands its supervisor).
* A peer whose pose is older than ``fleet.peer_timeout_s`` is **silent**: new motions are
  refused (the one in progress was checked and flies on). A peer whose flight ended is
  no longer silent when it stops talking: it stays where it was last seen, as an obstacle.

Points are NED [m]; a path's ``step_m`` is the largest distance between consecutive
samples, so every point of the continuous path lies within ``step_m / 2`` of a sample and
the distances are taken ``(step_mine + step_peer) / 2`` short of the samples'.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from groundstation.types import FloatArray

MAX_PATH_POINTS = 2000
"""Most samples of a motion's path checked (a longer motion is sampled more coarsely and
its margin grows with its step)."""

PATH_DT_S = 0.05
"""Sampling period of a path [s] (7.5 cm at the 1.5 m/s speed limit)."""

GAP_TOLERANCE_M = 1e-3
"""A path may come this much closer than the vehicle already is and still count as not
closing the gap [m] (the samples' rounding)."""


@dataclass(frozen=True, slots=True)
class PeerView:
    """What this vehicle knows of one peer now.

    name : the peer's vehicle name
    position : its latest estimated position, NED [m] (None: never heard, or no estimate)
    age_s : seconds since its latest pose arrived (inf: never)
    ended : its flight has ended (its last pose said a terminal state): it is no longer
        silent when it stops talking, and stays an obstacle where it was
    intent : (M, 3) points where it is planned to be, NED [m] (may be empty)
    step_m : the intent's largest step between consecutive points [m]
    """

    name: str
    position: FloatArray | None
    age_s: float
    ended: bool = False
    intent: FloatArray = field(default_factory=lambda: np.zeros((0, 3)))
    step_m: float = 0.0

    def silent(self, timeout_s: float) -> bool:
        """Its pose is older than ``timeout_s`` [s] and its flight has not ended."""
        return not self.ended and not self.age_s <= timeout_s

    def occupied(self) -> FloatArray:
        """(K, 3) points it occupies or will: its position and its intent."""
        pts = [self.intent.reshape(-1, 3)]
        if self.position is not None:
            pts.append(np.asarray(self.position, dtype=float).reshape(1, 3))
        return np.concatenate(pts) if pts else np.zeros((0, 3))


def nearest(position: FloatArray, peers: Sequence[PeerView],
            timeout_s: float) -> tuple[float, str]:
    """(distance [m], name) of the nearest peer whose position is known and not older
    than ``timeout_s`` [s] (or whose flight ended: it stays where it was); (inf, "")
    if none. ``position`` NED [m]."""
    best, name = math.inf, ""
    for peer in peers:
        if peer.position is None or peer.silent(timeout_s):
            continue
        d = float(np.linalg.norm(np.asarray(peer.position, dtype=float) - position))
        if d < best:
            best, name = d, peer.name
    return best, name


def sample_path(sample: Callable[[float], FloatArray], t0: float, t1: float,
                dt: float = PATH_DT_S, max_points: int = MAX_PATH_POINTS
                ) -> tuple[FloatArray, float]:
    """``sample(t)`` (a position, NED [m]) from ``t0`` to ``t1`` [s], every ``dt`` or more
    coarsely so that at most ``max_points`` are taken (both ends included), and the
    largest step between consecutive points [m]."""
    span = max(t1 - t0, 0.0)
    n = max(2, min(max_points, math.ceil(span / dt) + 1))
    times = np.linspace(t0, t0 + span, n)
    points = np.array([np.asarray(sample(float(t)), dtype=float) for t in times])
    step = float(np.max(np.linalg.norm(np.diff(points, axis=0), axis=1))) if n > 1 else 0.0
    return points, step


Verdict = Literal["ok", "silent", "separation"]


@dataclass(frozen=True, slots=True)
class PathCheck:
    """The verdict on a motion's path: ``ok``, ``silent`` (a peer is silent: not now) or
    ``separation`` (it would come too close), with the reason for a refusal."""

    verdict: Verdict
    reason: str = ""


def check_path(path: FloatArray, step_m: float, own: FloatArray, peers: Sequence[PeerView],
               separation_m: float, timeout_s: float) -> PathCheck:
    """Whether a motion along ``path`` ((N, 3) NED [m], steps of at most ``step_m``) from
    this vehicle's position ``own`` keeps ``separation_m`` [m] from every peer (see the
    module docstring). A peer silent for longer than ``timeout_s`` [s] refuses it first."""
    from scipy.spatial import cKDTree  # here: `gs` imports this module for every command

    silent = [p for p in peers if p.silent(timeout_s)]
    if silent:
        names = ", ".join(f"{p.name} ({_age(p.age_s)})" for p in silent)
        return PathCheck("silent", f"peer(s) silent: {names}; new motions wait for their "
                         "poses (the motion in progress flies on)")
    path = np.asarray(path, dtype=float).reshape(-1, 3)
    for peer in peers:
        occupied = peer.occupied()
        if len(occupied) == 0:
            continue
        tree = cKDTree(occupied)
        margin = 0.5 * (step_m + peer.step_m)
        dist, _ = tree.query(path)
        closest = int(np.argmin(dist))
        d_path = float(dist[closest]) - margin
        d_now = float(tree.query(np.asarray(own, dtype=float))[0]) - margin
        if d_path < separation_m and d_path < d_now - GAP_TOLERANCE_M:
            x, y, z = path[closest]
            return PathCheck("separation", (
                f"the path comes within {max(d_path, 0.0):.2f} m of {peer.name} at "
                f"({x:.2f}, {y:.2f}, {z:.2f}) (where it is or is planned to be); "
                f"fleet.separation_m is {separation_m:.2f} m"))
    return PathCheck("ok")


def _age(age_s: float) -> str:
    return "never heard" if math.isinf(age_s) else f"{age_s:.1f} s"
