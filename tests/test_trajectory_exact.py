"""The feasibility check on the curve that will be flown: nothing between two samples
escapes it, absurd inputs are refused before any work, and a refusal is one line per
limit with a slow-down that works.

Expected numbers are closed forms written here: a rest-to-rest min-jerk hop of ``d`` in
``h`` seconds peaks at ``10/sqrt(3) d/h^2`` and ``60 d/h^3``; the lemniscate
``x = a/2 sin 2wt, y = a sin wt`` at ``sqrt(2) a w``, ``17/8 a w^2``, ``sqrt(17) a w^3``.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from groundstation.cli import app
from groundstation.control import FigureEight, FlightLimits, Hover, Volume, check_feasibility
from groundstation.control.polynomial import PiecewisePolynomial
from groundstation.control.shaping import MinJerkPath, shape_for_flight
from groundstation.control.trajectories import square
from groundstation.control.trajectory import YawTurn
from groundstation.errors import TrajectoryError
from groundstation.types import Reference

G = 9.82
ROOT = 10.0 / math.sqrt(3.0)  # the quintic smoothstep's peak |S''|
LIMITS = FlightLimits()
VOLUME = Volume(x=(-1.5, 1.5), y=(-1.5, 1.5), z=(-2.0, 0.05), margin_m=0.1, name="vol")


class Opaque:
    """A trajectory that can only be sampled (as a run-time plan is)."""

    def __init__(self, inner: object) -> None:
        self.inner = inner
        self.name = "opaque"
        self.duration = inner.duration  # type: ignore[attr-defined]
        self.periodic = False
        self.free_heading = True

    def sample(self, t: float) -> Reference:
        return self.inner.sample(t)  # type: ignore[attr-defined,no-any-return]


@pytest.mark.slow
def test_a_dense_file_flown_as_corners_is_refused_between_its_knots() -> None:
    """The dense noisy eight flown as rest-to-rest corners: at the knots (every 10 ms)
    it is at rest, so a check that samples there passes it; between them every hop asks
    ``10/sqrt(3) d/h^2``, which the check now reads from the coefficients."""
    rng = np.random.default_rng(11)
    period, hz, a = 8.0, 100.0, 0.6
    w = 2 * math.pi / period
    t = np.arange(0.0, period + 0.5 / hz, 1.0 / hz)
    p = np.column_stack([0.5 * a * np.sin(2 * w * t), a * np.sin(w * t), -np.ones_like(t)])
    p += 5e-4 * rng.standard_normal(p.shape)
    corners = MinJerkPath(t, p)
    assert check_feasibility(Opaque(corners), LIMITS, horizon_s=period).feasible  # the old way
    report = check_feasibility(corners, LIMITS, horizon_s=period, raise_on_error=False)
    d = np.linalg.norm(np.diff(p, axis=0), axis=1)
    h = 1.0 / hz
    assert report.max_accel_m_s2 == pytest.approx(ROOT * d.max() / h**2, rel=1e-3)
    assert report.max_jerk_m_s3 == pytest.approx(60.0 * d.max() / h**3, rel=1e-3)
    assert report.max_accel_m_s2 > 50.0
    names = [line for line in report.problems if "tilt," in line or "tilt rate" in line]
    assert len(names) == 2 and len(report.problems) <= 6  # one line per limit, not 800
    assert all(re.search(r"beyond it in \d+ of 800 segments", line) for line in names)


def test_segments_beyond_a_limit_are_counted_and_the_worst_is_named() -> None:
    # five horizontal hops of 0.3 m turning 90 degrees at each knot (corners: stopped
    # at); two take 0.5 s (10/sqrt 3 * 0.3 / 0.25 = 6.9 m/s^2, 35 deg of tilt), three 2 s
    times = [0.0, 2.0, 2.5, 4.5, 5.0, 7.0]
    points = [[0.3 * (k // 2), 0.3 * ((k + 1) // 2), -1.0] for k in range(6)]
    path = MinJerkPath(times, points)
    report = check_feasibility(path, LIMITS, raise_on_error=False)
    worst = math.atan(ROOT * 0.3 / 0.25 / G)
    assert report.max_tilt_rad == pytest.approx(worst, rel=1e-4)
    (line,) = [p for p in report.problems if "deg tilt" in p]
    assert f"needs {math.degrees(worst):.1f} deg tilt" in line
    assert "(beyond it in 2 of 6 segments)" in line  # 5 hops and the rest after the end


def test_the_figure_eight_peaks_are_its_closed_form() -> None:
    width, period = 1.2, 5.0
    a, w = width / 2, 2 * math.pi / period
    report = check_feasibility(FigureEight([0.1, 0.2, -1.0], width_m=width, period_s=period),
                               LIMITS)
    assert report.method.startswith("exact")
    assert report.max_speed_m_s == pytest.approx(math.sqrt(2) * a * w, rel=1e-4)
    assert report.max_accel_m_s2 == pytest.approx(17 / 8 * a * w * w, rel=1e-4)
    assert report.max_jerk_m_s3 == pytest.approx(math.sqrt(17) * a * w**3, rel=1e-4)
    assert report.max_tilt_rad == pytest.approx(math.atan(17 / 8 * a * w * w / G), rel=1e-4)
    assert report.max_lift_n == pytest.approx(LIMITS.mass_kg * math.hypot(G, 17 / 8 * a * w * w),
                                              rel=1e-4)
    np.testing.assert_allclose(report.extent_min_m, [0.1 - a / 2, 0.2 - a, -1.0], atol=1e-4)
    np.testing.assert_allclose(report.extent_max_m, [0.1 + a / 2, 0.2 + a, -1.0], atol=1e-4)


def test_a_path_that_leaves_the_volume_between_two_samples_is_refused() -> None:
    # 10 ms out and back: x = 1.3 + 4.8 u^2 (1 - u)^2, u = t / 10 ms, reaches 1.6 m at 5 ms
    # while at 0 and 10 ms, the samples of a 10 ms check, it is at 1.3 m
    coef = np.zeros((1, 5, 4))
    coef[0, 0, :3] = [1.3, 0.0, -1.0]
    h = 0.01
    coef[0, 2:5, 0] = np.array([1.0, -2.0, 1.0]) * 4.8 / np.array([h**2, h**3, h**4])
    blip = PiecewisePolynomial([0.0, h], coef, name="blip")
    assert not any("outside" in p for p in check_feasibility(
        Opaque(blip), LIMITS, volume=VOLUME, raise_on_error=False).problems)
    report = check_feasibility(blip, LIMITS, volume=VOLUME, raise_on_error=False)
    assert report.extent_max_m[0] == pytest.approx(1.6, abs=1e-5)
    (line,) = [p for p in report.problems if "outside" in p]
    assert "x = 1.60 m is outside vol_x [-1.50, 1.50] less the 0.10 m margin" in line


def test_absurd_inputs_are_refused_at_once(monkeypatch: pytest.MonkeyPatch) -> None:
    calls = {"n": 0}
    original = FigureEight.sample

    def counted(self: FigureEight, t: float) -> Reference:
        calls["n"] += 1
        return original(self, t)

    monkeypatch.setattr(FigureEight, "sample", counted)
    # a lap in a nanosecond, 7.2 km wide (it would reach +-3.6 km)
    fast = FigureEight([0.0, 0.0, -1.0], width_m=7200.0, period_s=1e-9)
    shaped, duration = shape_for_flight(fast, 1e-9, LIMITS.max_accel_m_s2)
    with pytest.raises(TrajectoryError) as info:
        check_feasibility(shaped, LIMITS, volume=VOLUME, horizon_s=duration)
    message = str(info.value)
    assert "y = 3600.00 m is outside vol_y" in message and "(closed form)" in message
    assert calls["n"] < 100  # evaluated at its critical points, not sampled
    lines = message.splitlines()[1:]
    for limit, most in (("speed limit", 1), ("tilt limit", 1), ("body-rate", 1),
                        ("lift range", 1), ("vol_x", 2), ("vol_y", 2), ("vol_z", 2)):
        assert sum(limit in line for line in lines) <= most, limit  # one line per limit
    # a 360 degree turn in a nanosecond: 1.875 * 360 / 1e-9 deg/s at mid-turn
    turn = YawTurn([0.0, 0.0, -1.0], turn=2 * math.pi, period_s=1e-9)
    with pytest.raises(TrajectoryError, match=r"needs a yaw rate of 675000000000\.0 deg/s, "
                       r"the yaw-rate limit = 128\.9 deg/s \(closed form\)"):
        check_feasibility(turn, LIMITS, volume=VOLUME)


def test_numbers_that_are_not_finite_are_refused() -> None:
    with pytest.raises(TrajectoryError, match="finite"):
        FigureEight([0.0, 0.0, -1.0], width_m=1.0, period_s=math.inf)
    with pytest.raises(TrajectoryError, match="finite"):
        FigureEight([0.0, 0.0, -1.0], width_m=math.nan, period_s=8.0)
    coef = np.zeros((1, 8, 4))
    coef[0, 7, 0] = math.inf
    with pytest.raises(TrajectoryError, match="finite"):
        PiecewisePolynomial([0.0, 1.0], coef)
    coef[0, 7, 0] = 1e300  # finite, but its derivatives overflow
    with pytest.raises(TrajectoryError, match="not finite"):
        check_feasibility(PiecewisePolynomial([0.0, 1.0], coef), LIMITS)
    with pytest.raises(TrajectoryError, match="not a finite time"):
        check_feasibility(Hover([0.0, 0.0, -1.0]), LIMITS, horizon_s=math.inf)


def test_the_slow_down_the_refusal_names_makes_it_flyable() -> None:
    fast = FigureEight([0.0, 0.0, -1.0], width_m=1.5, period_s=2.0)
    report = check_feasibility(fast, LIMITS, raise_on_error=False)
    factors = [float(k) for k in re.findall(r"slow it down by k = (\d+\.\d\d)", "\n".join(
        report.problems))]
    assert factors and len(factors) == len(report.problems)
    # speed sqrt(2) a w = 3.33 m/s against 1.5: k = 2.22; tilt: 17/8 a w^2 / k^2 within
    # g tan 20 deg: k = 2.10; the largest makes every limit hold (closed forms)
    a, w = 0.75, math.pi
    assert max(factors) == pytest.approx(math.sqrt(2) * a * w / 1.5, abs=0.011)
    slow = FigureEight([0.0, 0.0, -1.0], width_m=1.5, period_s=2.0 * max(factors))
    assert check_feasibility(slow, LIMITS).feasible
    just_short = FigureEight([0.0, 0.0, -1.0], width_m=1.5, period_s=2.0 * max(factors) * 0.99)
    assert not check_feasibility(just_short, LIMITS, raise_on_error=False).feasible


def test_the_floor_has_no_margin_the_ceiling_and_sides_have() -> None:
    lo, hi = VOLUME.allowed()
    np.testing.assert_allclose(lo, [-1.4, -1.4, -1.9])
    np.testing.assert_allclose(hi, [1.4, 1.4, 0.05])  # the floor itself
    assert check_feasibility(Hover([0.0, 0.0, 0.05]), LIMITS, volume=VOLUME).feasible
    low = check_feasibility(Hover([0.0, 0.0, 0.06]), LIMITS, volume=VOLUME,
                            raise_on_error=False)
    assert any("z = 0.06 m is below the floor: outside vol_z [-2.00, 0.05] (" in p
               for p in low.problems)
    high = check_feasibility(Hover([0.0, 0.0, -1.95]), LIMITS, volume=VOLUME,
                             raise_on_error=False)
    assert any("the start height 1.95 m is above the ceiling" in p for p in high.problems)
    # climbing to 1.92 m after the start: inside the box, but not inside its margin
    climb = MinJerkPath([0.0, 3.0], [[0.0, 0.0, -1.0], [0.0, 0.0, -1.92]])
    report = check_feasibility(climb, LIMITS, volume=VOLUME, raise_on_error=False)
    assert any("z = -1.92 m is outside vol_z [-2.00, 0.05] less the 0.10 m margin" in p
               for p in report.problems)


def test_check_config_refuses_a_figure_eight_faster_than_a_tick(tmp_path: Path) -> None:
    """A lap in a nanosecond is not a period at all (below the shortest motion the vehicle
    can fly as asked); a lap of half a second is one, refused by its closed form (10.7 m/s
    at the centre: sqrt(2) a w with a = 0.6 m, w = 4 pi / s)."""
    path = tmp_path / "gs.yaml"
    path.write_text("trajectory:\n  name: figure-eight\n  period_s: 1e-9\n  size_m: 1.2\n")
    result = CliRunner().invoke(app, ["check-config", str(path)])
    assert result.exit_code == 2 and "Traceback" not in result.output
    assert "trajectory.period_s: 1e-09: outside [0.2, 3600]" in result.output
    path.write_text("trajectory:\n  name: figure-eight\n  period_s: 0.5\n  size_m: 1.2\n")
    result = CliRunner().invoke(app, ["check-config", str(path)])
    assert result.exit_code == 2 and "Traceback" not in result.output
    assert "cannot be flown" in result.output and "(closed form)" in result.output
    assert "speed 10.66 m/s" in result.output


@pytest.mark.slow
@pytest.mark.parametrize("seed", [1, 2, 3, 4])
def test_every_peak_is_the_curves_own_on_random_polynomial_segments(seed: int) -> None:
    """Random septic segments (continuous or not): each peak the check reports is within
    its tolerance of the largest value numpy finds on 400 000 points of the same
    polynomials, and never below it by more (the check's bound is proven; a dense grid
    only approaches the peak from below)."""
    rng = np.random.default_rng(seed)
    durations = rng.uniform(0.3, 1.5, size=4)
    coef = rng.normal(0.0, 0.4, size=(4, 8, 4)) / np.arange(1, 9)[None, :, None] ** 2
    coef[:, 0, 2] -= 1.0  # about 1 m up
    breaks = np.concatenate([[0.0], np.cumsum(durations)])
    path = PiecewisePolynomial(breaks, coef)
    report = check_feasibility(path, LIMITS, horizon_s=float(breaks[-1]),
                               raise_on_error=False)
    t = np.linspace(0.0, breaks[-1], 400_001)
    seg = np.clip(np.searchsorted(breaks, t, side="right") - 1, 0, 3)
    tau = t - breaks[seg]

    def derivative(order: int) -> np.ndarray:
        out = np.empty((t.size, 4))
        for k in range(4):
            sel = seg == k
            for axis in range(4):
                out[sel, axis] = np.polynomial.polynomial.polyval(
                    tau[sel], np.polynomial.polynomial.polyder(coef[k, :, axis], order))
        return out

    p, v, acc, jerk = (derivative(r) for r in range(4))
    m, inflow = LIMITS.mass_kg, LIMITS.induced_inflow
    force = m * acc[:, :3]
    force[:, 2] -= m * G + inflow * v[:, 2]
    force_rate = m * jerk[:, :3]
    force_rate[:, 2] -= inflow * acc[:, 2]
    lift = np.linalg.norm(force, axis=1)
    dense = {
        "max_speed_m_s": np.linalg.norm(v[:, :3], axis=1).max(),
        "max_accel_m_s2": np.linalg.norm(acc[:, :3], axis=1).max(),
        "max_jerk_m_s3": np.linalg.norm(jerk[:, :3], axis=1).max(),
        "max_yaw_rate_rad_s": np.abs(v[:, 3]).max(),
        "max_lift_n": lift.max(),
        "max_tilt_rad": np.arccos(-force[:, 2] / lift).max(),
        "max_tilt_rate_rad_s": (np.linalg.norm(np.cross(force, force_rate), axis=1)
                                / lift**2).max(),
    }
    for key, expected in dense.items():
        got = getattr(report, key)
        assert got == pytest.approx(expected, rel=2e-4, abs=1e-3), key
    assert report.min_lift_n == pytest.approx(lift.min(), rel=2e-4, abs=1e-3)
    np.testing.assert_allclose(report.extent_min_m, p[:, :3].min(axis=0), atol=2e-5)
    np.testing.assert_allclose(report.extent_max_m, p[:, :3].max(axis=0), atol=2e-5)


def test_a_refusal_never_calls_a_point_inside_the_box_outside() -> None:
    """A square lapped in a nanosecond: its corners are inside, but no bound between its
    samples can be shown inside the volume. Each volume line either names a point that is
    outside or says that the path cannot be shown inside, with the sample and the bound."""
    fast = shape_for_flight(square([0.0, 0.0, -1.0], size_m=1.0, period_s=1e-9), 1e-9,
                            LIMITS.max_accel_m_s2)[0]
    report = check_feasibility(fast, LIMITS, volume=VOLUME, raise_on_error=False)
    lines = [p for p in report.problems if "vol_" in p]
    assert lines
    lo, hi = VOLUME.allowed()
    for line in lines:
        said = re.search(r"\b([xyz]) = (-?\d+\.\d\d) m is (?:below the floor: )?outside", line)
        if said is not None:
            axis, value = "xyz".index(said[1]), float(said[2])
            assert not lo[axis] <= value <= hi[axis], line  # what is called outside is
        else:
            assert re.search(r"[xyz] cannot be shown inside vol_[xyz] .*the worst sample, "
                             r"-?\d+\.\d\d m, is inside; the proven bound between samples "
                             r"reaches -?\d+\.\d\d m", line), line


@pytest.mark.parametrize("periodic", [False, True])
def test_one_sample_is_numpys_polynomial_and_its_derivatives(periodic: bool) -> None:
    """A single sample (the flight's reference every tick) against numpy's own polynomial
    evaluation of each segment and its derivatives; laps add the period and the heading."""
    rng = np.random.default_rng(7)
    breaks = np.cumsum(np.r_[0.0, rng.uniform(0.3, 2.0, 4)])
    coef = rng.normal(size=(4, 8, 4))
    if periodic:  # close the path: the last segment ends where the first starts
        h = breaks[-1] - breaks[-2]
        end = np.polynomial.polynomial.polyval(h, coef[-1])
        coef[-1, 0, :3] -= end[:3] - coef[0, 0, :3]
    path = PiecewisePolynomial(breaks, coef, periodic=periodic)
    lap_yaw = (np.polynomial.polynomial.polyval(breaks[-1] - breaks[-2], coef[-1, :, 3])
               - coef[0, 0, 3])
    span = 2.5 * breaks[-1] if periodic else breaks[-1]
    for t in rng.uniform(0.0, span, 300):
        laps = math.floor(t / breaks[-1]) if periodic else 0
        local = t - laps * breaks[-1]
        i = int(np.searchsorted(breaks, local, side="right")) - 1
        tau = local - breaks[i]
        want = [np.array([np.polynomial.polynomial.polyval(
            tau, np.polynomial.polynomial.polyder(coef[i, :, axis], r) if r else coef[i, :, axis])
            for axis in range(4)]) for r in range(4)]
        ref = path.sample(float(t))
        for got, exact in ((ref.position, want[0][:3]), (ref.velocity, want[1][:3]),
                           (ref.acceleration, want[2][:3]), (ref.jerk, want[3][:3])):
            np.testing.assert_allclose(got, exact, rtol=1e-12, atol=1e-9)
        assert ref.yaw == pytest.approx(want[0][3] + laps * lap_yaw, rel=1e-12, abs=1e-9)
        assert ref.yaw_rate == pytest.approx(want[1][3], rel=1e-12, abs=1e-9)
        assert ref.t == pytest.approx(t, abs=1e-9)
