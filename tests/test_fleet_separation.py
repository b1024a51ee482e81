"""The fleet's separation rules, pure: distances checked against closed forms (the
distance of a point from a segment), the sampling margin, the silent and ended peers,
and the volumes' overlap (which the fleet file checks: ``config/fleetfile.py``)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from groundstation.config.fleetfile import volumes_overlap
from groundstation.fleet.separation import (
    PeerView,
    check_path,
    nearest,
    sample_path,
)

SEP = 0.5


def line(a: list[float], b: list[float], n: int = 101) -> tuple[np.ndarray, float]:
    """A straight path from a to b in n samples, and its step [m]."""
    pts = np.linspace(a, b, n)
    return pts, float(np.linalg.norm(np.subtract(b, a))) / (n - 1)


def peer(name: str, at: list[float] | None, age: float = 0.0, **kw: object) -> PeerView:
    return PeerView(name, None if at is None else np.array(at, dtype=float), age, **kw)  # type: ignore[arg-type]


def test_nearest_is_the_closest_fresh_known_peer() -> None:
    here = np.array([0.0, 0.0, -1.0])
    peers = [peer("far", [3.0, 4.0, -1.0]), peer("near", [0.3, 0.4, -1.0]),
             peer("silent", [0.1, 0.0, -1.0], age=2.0), peer("unknown", None),
             peer("landed", [0.0, 1.0, 0.0], age=9.0, ended=True)]
    assert nearest(here, peers, 0.5) == (pytest.approx(0.5), "near")
    assert nearest(here, peers[:1] + peers[3:], 0.5) == (pytest.approx(math.sqrt(2.0)),
                                                         "landed")
    assert nearest(here, [], 0.5) == (math.inf, "")


def test_a_path_that_passes_a_peer_farther_than_the_separation_is_flown() -> None:
    # the segment y = 0.6 passes (0, 0) at 0.6 m: the closed form of its distance
    path, step = line([-1.0, 0.6, -1.0], [1.0, 0.6, -1.0])
    verdict = check_path(path, step, path[0], [peer("v2", [0.0, 0.0, -1.0])], SEP, 0.5)
    assert verdict.verdict == "ok"


def test_a_path_that_comes_within_the_separation_is_refused_naming_where() -> None:
    path, step = line([-1.0, 0.4, -1.0], [1.0, 0.4, -1.0])
    verdict = check_path(path, step, path[0], [peer("v2", [0.0, 0.0, -1.0])], SEP, 0.5)
    assert verdict.verdict == "separation"
    # 0.4 m less half the 2 cm step between samples
    assert "within 0.39 m of v2 at (0.00, 0.40, -1.00)" in verdict.reason
    assert "fleet.separation_m is 0.50 m" in verdict.reason


def test_the_sampling_margin_makes_a_coarse_path_conservative() -> None:
    """0.52 m from the peer: dense samples pass; samples 0.1 m apart might miss the
    closest point by 5 cm, so the check takes them 5 cm short and refuses."""
    dense, step = line([-1.0, 0.52, -1.0], [1.0, 0.52, -1.0], 2001)
    coarse, coarse_step = line([-1.0, 0.52, -1.0], [1.0, 0.52, -1.0], 21)
    target = [peer("v2", [0.0, 0.0, -1.0])]
    assert check_path(dense, step, dense[0], target, SEP, 0.5).verdict == "ok"
    assert check_path(coarse, coarse_step, coarse[0], target, SEP, 0.5).verdict == \
        "separation"


def test_a_peers_intent_is_kept_clear_of_too() -> None:
    """v2 hovers far away but plans to pass through (0, 0): a path through there is
    refused, one 1 m away from its whole plan is not."""
    plan, plan_step = line([0.0, -1.0, -1.0], [0.0, 1.0, -1.0])
    v2 = peer("v2", [0.0, -1.0, -1.0], intent=plan, step_m=plan_step)
    crossing, step = line([-1.0, 0.0, -1.0], [1.0, 0.0, -1.0])
    assert check_path(crossing, step, crossing[0], [v2], SEP, 0.5).verdict == "separation"
    beside, step = line([1.0, -1.0, -1.0], [1.0, 1.0, -1.0])
    assert check_path(beside, step, beside[0], [v2], SEP, 0.5).verdict == "ok"


def test_within_the_separation_already_a_motion_may_open_the_gap_not_close_it() -> None:
    v2 = [peer("v2", [0.0, 0.0, -1.0])]
    away, step = line([0.4, 0.0, -1.0], [1.0, 0.0, -1.0])
    assert check_path(away, step, away[0], v2, SEP, 0.5).verdict == "ok"
    closer, step = line([0.4, 0.0, -1.0], [0.3, 0.0, -1.0])
    assert check_path(closer, step, closer[0], v2, SEP, 0.5).verdict == "separation"


def test_a_silent_peer_refuses_new_motions_an_ended_one_does_not() -> None:
    path, step = line([-1.0, 1.0, -1.0], [1.0, 1.0, -1.0])
    silent = check_path(path, step, path[0], [peer("v3", [0.0, -1.0, -1.0], age=0.7),
                                              peer("v4", None, age=math.inf)], SEP, 0.5)
    assert silent.verdict == "silent"
    assert "v3 (0.7 s)" in silent.reason and "v4 (never heard)" in silent.reason
    ended = peer("v3", [0.0, -1.0, 0.0], age=60.0, ended=True)
    assert check_path(path, step, path[0], [ended], SEP, 0.5).verdict == "ok"
    onto, step = line([-1.0, -1.0, -0.2], [0.0, -1.0, -0.2])  # onto where it landed
    assert check_path(onto, step, onto[0], [ended], SEP, 0.5).verdict == "separation"


def test_sample_path_takes_the_period_or_stretches_it_to_the_limit() -> None:
    pts, step = sample_path(lambda t: np.array([t, 0.0, -1.0]), 0.0, 2.0, dt=0.05)
    assert len(pts) == 41 and step == pytest.approx(0.05)
    pts, step = sample_path(lambda t: np.array([t, 0.0, -1.0]), 0.0, 600.0, dt=0.05,
                            max_points=2000)
    assert len(pts) == 2000 and step == pytest.approx(600.0 / 1999)


def test_volumes_overlap_only_with_a_positive_volume() -> None:
    a = ((-1.5, 0.0), (-1.5, 1.5), (-2.0, 0.05))
    assert not volumes_overlap(a, ((0.0, 1.5), (-1.5, 1.5), (-2.0, 0.05)))  # a shared face
    assert volumes_overlap(a, ((-0.1, 1.5), (-1.5, 1.5), (-2.0, 0.05)))
    assert not volumes_overlap(a, ((-1.0, -0.5), (2.0, 3.0), (-2.0, 0.05)))
