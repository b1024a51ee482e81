"""Trajectory files as users bring them: dense sampled curves fitted smoothly, corner
lists kept as corners, headings in degrees or radians across +-180 degrees, and the
piecewise-polynomial files of uav_trajectories / Crazyswarm.

Every input is written here the way other tools write it (numpy's ``savetxt`` of a
closed form, a polynomial table from known coefficients, the Crazyflie examples'
``figure8.csv``), and every expected number comes from the closed form or from numpy's
own polynomial evaluation, not from the package.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import numpy.polynomial.polynomial as npoly
import pytest

from groundstation.config import validate_config
from groundstation.control import FlightLimits, check_feasibility
from groundstation.control.polyfile import load_polynomial_file
from groundstation.control.polynomial import PiecewisePolynomial
from groundstation.control.shaping import MinJerkPath, TimeWarp, fit_if_dense, shape_for_flight
from groundstation.control.splines import FittedPath
from groundstation.control.trajectories import load_trajectory_file, load_waypoints
from groundstation.errors import TrajectoryError
from groundstation.flight.assembly import assemble
from groundstation.flight.prepare import trajectory_for_flight

DATA = Path(__file__).resolve().parent / "data"
G = 9.82
CENTER = np.array([0.1, -0.2, -1.2])
A = 0.6  # half the width: 1.2 m east-west, 0.6 m north-south


def lemniscate(t: np.ndarray, period: float) -> tuple[np.ndarray, ...]:
    """Position, velocity, acceleration (n, 3) of ``x = A/2 sin 2wt, y = A sin wt`` about
    CENTER, differentiated by hand."""
    w = 2 * math.pi / period
    zero = np.zeros_like(t)
    p = CENTER + np.column_stack([0.5 * A * np.sin(2 * w * t), A * np.sin(w * t), zero])
    v = np.column_stack([A * w * np.cos(2 * w * t), A * w * np.cos(w * t), zero])
    acc = np.column_stack([-2 * A * w * w * np.sin(2 * w * t), -A * w * w * np.sin(w * t),
                           zero])
    return p, v, acc


def write_samples(path: Path, t: np.ndarray, p: np.ndarray, yaw: np.ndarray | None = None,
                  yaw_header: str = "yaw") -> Path:
    """A CSV as numpy writes one: ``savetxt`` with a header line, full precision."""
    columns = [t[:, None], p] + ([] if yaw is None else [yaw[:, None]])
    header = "t,x,y,z" + ("" if yaw is None else f",{yaw_header}")
    np.savetxt(path, np.hstack(columns), delimiter=",", header=header, comments="")
    return path


def dense_eight(tmp_path: Path, period: float, hz: float, noise_m: float = 0.0,
                laps: float = 1.0, seed: int = 7) -> Path:
    t = np.arange(0.0, laps * period + 0.5 / hz, 1.0 / hz)
    p, _, _ = lemniscate(t, period)
    p = p + noise_m * np.random.default_rng(seed).standard_normal(p.shape)
    return write_samples(tmp_path / f"eight_{period:g}s_{hz:g}hz.csv", t, p)


def fitted(path: Path) -> FittedPath:
    out = fit_if_dense(load_waypoints(path), FlightLimits())
    assert isinstance(out, FittedPath), "expected the samples to be taken as dense"
    return out


# ------------------------------------------------------------------ dense samples
@pytest.mark.parametrize("period", [8.0, 4.0])
@pytest.mark.parametrize("hz", [10.0, 50.0, 100.0])
def test_dense_samples_are_fitted_on_the_closed_form(tmp_path: Path, period: float,
                                                     hz: float) -> None:
    path = fitted(dense_eight(tmp_path, period, hz))
    fit = path.fit
    assert fit.rule.dense and fit.rule.breaking == fit.rule.moving  # every hop: too short
    # every sample lies on the fitted curve within 1 mm (here: micrometres)
    assert fit.residual_max_m < 1e-3 and fit.residual_max_m < 2e-5
    # between the samples too: the curve, its velocity and acceleration against the
    # closed form's derivatives, on a grid 20 times finer than the file's
    t = np.linspace(0.0, period, int(20 * period * hz))
    s = path.sample_many(t)
    p, v, acc = lemniscate(t, period)
    assert np.max(np.linalg.norm(s.position - p, axis=1)) < 1e-4
    assert np.max(np.linalg.norm(s.velocity - v, axis=1)) < 5e-3
    assert np.max(np.linalg.norm(s.acceleration - acc, axis=1)) < 0.05
    # the check's peaks over the file's lap: the lemniscate's closed-form peaks,
    # speed sqrt(2) A w, acceleration 17/8 A w^2 (at sin^2 wt = 17/32)
    w = 2 * math.pi / period
    report = check_feasibility(path, FlightLimits(), horizon_s=period)
    assert report.max_speed_m_s == pytest.approx(math.sqrt(2) * A * w, rel=1e-3)
    assert report.max_accel_m_s2 == pytest.approx(17 / 8 * A * w * w, rel=5e-3)
    assert report.max_tilt_rad == pytest.approx(math.atan(17 / 8 * A * w * w / G), rel=5e-3)
    reach = np.array([A / 2, A, 0.0])
    assert report.extent_min_m == pytest.approx(CENTER - reach, abs=1e-4)
    assert report.extent_max_m == pytest.approx(CENTER + reach, abs=1e-4)


def test_noisy_samples_are_smoothed_to_their_noise(tmp_path: Path) -> None:
    """Half a millimetre of noise at 100 Hz, as a tool that exports a sampled spline
    writes it: the fit says how noisy the samples are and keeps the feed-forward smooth
    (flown as corners the same file asked 69 m/s^2 between ticks)."""
    period, sigma = 8.0, 5e-4
    path = fitted(dense_eight(tmp_path, period, 100.0, noise_m=sigma))
    fit = path.fit
    assert fit.noise_m == pytest.approx([sigma] * 3, rel=0.25)
    # the samples scatter about the curve by their noise: 3-D RMS sqrt(3) sigma
    assert fit.residual_rms_m == pytest.approx(math.sqrt(3) * sigma, rel=0.25)
    t = np.linspace(0.0, period, 8001)
    s = path.sample_many(t)
    p, v, acc = lemniscate(t, period)
    assert np.max(np.linalg.norm(s.position - p, axis=1)) < 1.5e-3
    assert np.max(np.linalg.norm(s.velocity - v, axis=1)) < 0.02
    assert np.max(np.linalg.norm(s.acceleration - acc, axis=1)) < 0.3
    report = check_feasibility(path, FlightLimits(), horizon_s=period)
    assert report.feasible and report.max_jerk_m_s3 < 20.0
    w = 2 * math.pi / period
    assert report.max_accel_m_s2 == pytest.approx(17 / 8 * A * w * w, abs=0.3)


def test_corner_lists_stay_corners(tmp_path: Path) -> None:
    """The thesis's square as a waypoint file: each hop is long enough to fly from rest
    to rest, so the knots are corners passed at rest, not samples of a curve."""
    h = 0.375
    rows = np.array([[0, h, -h, -1], [5, h, h, -1], [10, -h, h, -1], [15, -h, -h, -1],
                     [20, h, -h, -1]], dtype=float)
    path = tmp_path / "square.csv"
    np.savetxt(path, rows, delimiter=",", header="t,x,y,z", comments="")
    raw = load_waypoints(path)
    assert fit_if_dense(raw, FlightLimits()) is None
    shaped, duration = shape_for_flight(raw, 20.0, 3.57, limits=FlightLimits())
    assert isinstance(shaped, MinJerkPath) and duration == 20.0
    for t, corner in zip(rows[:, 0], rows[:, 1:], strict=True):
        ref = shaped.sample(float(t))
        np.testing.assert_allclose(ref.position, corner, atol=1e-12)
        np.testing.assert_allclose(ref.velocity, 0.0, atol=1e-12)


@pytest.mark.parametrize("shaping", ["min-jerk", "none"])
def test_a_file_that_ends_mid_motion_is_eased_not_refused(tmp_path: Path, shaping: str) -> None:
    period = 8.0
    path = dense_eight(tmp_path, period, 50.0, laps=0.7)  # ends on a lobe, moving
    cfg = validate_config({"trajectory": {"name": "waypoints", "file": str(path),
                                          "shaping": shaping}})
    traj, duration = trajectory_for_flight(assemble(cfg))
    assert isinstance(traj, TimeWarp)
    assert duration == pytest.approx(0.7 * period + traj.ramp_s, abs=0.02)
    for t in (0.0, duration):
        ref = traj.sample(t)
        np.testing.assert_allclose(ref.velocity, 0.0, atol=1e-9)
        np.testing.assert_allclose(ref.acceleration, 0.0, atol=1e-9)
    # it flies through the file's last sample and stops there
    last = np.arange(0.0, 0.7 * period + 0.01, 0.02)[-1]  # the file's last row
    p_end, _, _ = lemniscate(np.array([last]), period)
    np.testing.assert_allclose(traj.sample(duration).position, p_end[0], atol=1e-4)


# ------------------------------------------------------------------ headings
@pytest.mark.parametrize("unit", ["yaw_deg", "yaw_rad", "yaw"])
def test_a_heading_column_across_180_degrees_is_unwrapped(tmp_path: Path, unit: str) -> None:
    """A circle flown nose first: the heading turns through +-180 degrees twice; the
    file writes it wrapped, in degrees (``yaw_deg``) or radians (``yaw_rad``/``yaw``)."""
    radius, period, hz = 0.5, 10.0, 50.0
    w = 2 * math.pi / period
    t = np.arange(0.0, 1.5 * period + 0.5 / hz, 1.0 / hz)
    p = np.column_stack([radius * np.cos(w * t), radius * np.sin(w * t), -np.ones_like(t)])
    heading = w * t + math.pi / 2 + 2.5  # the direction of travel, plus a fixed offset
    wrapped = np.angle(np.exp(1j * heading))  # (-pi, pi], as a logger writes it
    column = np.degrees(wrapped) if unit == "yaw_deg" else wrapped
    path = fitted(write_samples(tmp_path / "circle.csv", t, p, column, unit))
    assert not path.free_heading
    s = path.sample_many(np.linspace(0.0, t[-1], 5001))
    truth = w * s.t + math.pi / 2 + 2.5
    offset = s.yaw[0] - truth[0]
    assert abs(math.remainder(offset, 2 * math.pi)) < 1e-4  # same heading
    np.testing.assert_allclose(s.yaw - offset, truth, atol=2e-4)  # continuous: no 2 pi jumps
    np.testing.assert_allclose(s.yaw_rate, w, atol=2e-3)


def test_a_corner_file_in_degrees(tmp_path: Path) -> None:
    path = tmp_path / "turns.csv"
    path.write_text("t,x,y,z,yaw_deg\n0,0,0,-1,170\n4,1,0,-1,-170\n8,1,1,-1,90\n")
    raw = load_waypoints(path)
    # 170 deg to -170 deg is 20 deg through south, then on to 90 deg: radians inside
    np.testing.assert_allclose(np.degrees(raw.yaws), [170, 190, 90], atol=1e-9)


# ------------------------------------------------------------------ tables of other tools
KNOTS = np.array([[0.0, 0.1, -0.2, -1.0, 170.0],  # t, north, east, down, heading [deg]
                  [2.5, 0.625, 0.3125, -1.25, -175.5],
                  [5.0, -0.4, 0.75, -1.5, -90.0],
                  [7.5, 0.0, 0.0, -1.0, 12.25]])


def _savetxt_spaces(path: Path) -> None:  # numpy's default: spaces, %.18e, no header
    np.savetxt(path, np.c_[KNOTS[:, :4], np.radians(KNOTS[:, 4])])


def _savetxt_tabs_named_in_a_comment(path: Path) -> None:  # the header as numpy writes it
    np.savetxt(path, KNOTS, delimiter="\t", header="t\tx\ty\tz\tyaw_deg")


def _matlab_save_ascii(path: Path) -> None:  # MATLAB's save -ascii: "%16.7e" per value
    rows = np.c_[KNOTS[:, :4], np.radians(KNOTS[:, 4])]
    path.write_text("".join("".join(f"{v:16.7e}" for v in row) + "\n" for row in rows))


def _spreadsheet_with_decimal_commas(path: Path) -> None:
    """A spreadsheet's CSV where the decimal mark is a comma: semicolons, CRLF, a byte-order
    mark, and the empty rows it pads the export with."""
    lines = ["t;x;y;z;yaw_deg"] + [";".join(f"{v:g}".replace(".", ",") for v in row)
                                   for row in KNOTS] + [";;;;", ";;;;"]
    path.write_bytes(("\ufeff" + "\r\n".join(lines) + "\r\n").encode("utf-8"))


@pytest.mark.parametrize("write", [_savetxt_spaces, _savetxt_tabs_named_in_a_comment,
                                   _matlab_save_ascii, _spreadsheet_with_decimal_commas])
def test_a_waypoint_table_is_read_whatever_wrote_it(tmp_path: Path, write: Any) -> None:
    """The same four waypoints written by numpy (spaces; tabs with the header as a
    comment), MATLAB's ``save -ascii`` and a spreadsheet that writes decimal commas: the
    same times, points and headings (within the writer's precision; 8 digits for MATLAB)."""
    path = tmp_path / "knots.txt"
    write(path)
    raw = load_waypoints(path)
    np.testing.assert_allclose(raw.times, KNOTS[:, 0], atol=1e-6)
    np.testing.assert_allclose(raw.points, KNOTS[:, 1:4], atol=1e-6)
    # unwrapped: 170 -> -175.5 deg is 14.5 deg on, not 345.5 back
    np.testing.assert_allclose(np.degrees(raw.yaws), [170.0, 184.5, 270.0, 372.25], atol=1e-5)


def test_a_table_that_is_not_numbers_is_refused_naming_the_line(tmp_path: Path) -> None:
    path = tmp_path / "bad.csv"
    path.write_text("t;x;y;z\n0;0;0;-1\n1;0,1,5;0;-1\n")  # two commas: no decimal comma
    with pytest.raises(TrajectoryError, match=r"bad\.csv:3: not a number"):
        load_waypoints(path)
    path.write_text("0 0 0 -1\n1 0,5 0 -1\n")  # a decimal comma in a comma-free table
    with pytest.raises(TrajectoryError, match=r"bad\.csv:2: not a number"):
        load_waypoints(path)
    path.write_text("t x y z\n0 0 0 -1\n1 0.5 0\n")
    with pytest.raises(TrajectoryError, match=r"bad\.csv:3: expected 4 or 5 finite values"):
        load_waypoints(path)


# ------------------------------------------------------------------ polynomial files
def _poly_table(durations: list[float], coef: np.ndarray) -> str:
    """A uav_trajectories table: Duration, then x^0..x^7, y^.., z^.., yaw^.."""
    names = ["Duration"] + [f"{axis}^{k}" for axis in ("x", "y", "z", "yaw") for k in range(8)]
    rows = [",".join(names)]
    for d, c in zip(durations, coef, strict=True):  # c: (4, 8), lowest power first
        rows.append(",".join(f"{v:.9f}" for v in [d, *c.reshape(-1)]))
    return "\n".join(rows) + "\n"


@pytest.mark.parametrize("relative", [True, False])
def test_a_polynomial_file_is_read_in_ned_from_known_coefficients(tmp_path: Path,
                                                                  relative: bool) -> None:
    rng = np.random.default_rng(3)
    durations = [1.0, 0.5, 2.0]
    coef = np.round(rng.uniform(-0.3, 0.3, size=(3, 4, 8)), 6)  # as printed, 6 decimals
    path = tmp_path / "poly.csv"
    path.write_text(_poly_table(durations, coef))
    origin = np.array([0.4, -0.3, -1.1])
    traj = load_trajectory_file(path, center=origin, relative=relative)
    assert isinstance(traj, PiecewisePolynomial) and traj.duration == pytest.approx(3.5)
    assert traj.free_heading is relative
    starts = np.concatenate([[0.0], np.cumsum(durations)])
    flip = np.array([1.0, -1.0, -1.0, -1.0])  # x forward, y left, z up, yaw ccw -> NED
    first = coef[0, :, 0] * flip  # the file's start, converted
    for t in np.linspace(0.01, 3.49, 37):
        k = int(np.searchsorted(starts, t, side="right") - 1)
        tau = t - starts[k]
        value = np.array([npoly.polyval(tau, coef[k, a]) for a in range(4)]) * flip
        rate = np.array([npoly.polyval(tau, npoly.polyder(coef[k, a])) for a in range(4)]) * flip
        accel = np.array([npoly.polyval(tau, npoly.polyder(coef[k, a], 2))
                          for a in range(3)]) * flip[:3]
        expected = value[:3] - first[:3] + origin if relative else value[:3]
        ref = traj.sample(float(t))
        np.testing.assert_allclose(ref.position, expected, atol=1e-12)
        np.testing.assert_allclose(ref.velocity, rate[:3], atol=1e-12)
        np.testing.assert_allclose(ref.acceleration, accel, atol=1e-12)
        assert ref.yaw == pytest.approx(value[3] - first[3] if relative else value[3])
        assert ref.yaw_rate == pytest.approx(rate[3])


def _figure8_by_numpy(n: int = 200_001) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The shared figure8.csv evaluated densely with numpy alone: positions, velocities,
    accelerations (n, 2) in the file's own x/y."""
    table = np.loadtxt(DATA / "figure8.csv", delimiter=",", skiprows=1)
    starts = np.concatenate([[0.0], np.cumsum(table[:, 0])])
    t = np.linspace(0.0, starts[-1], n)
    seg = np.clip(np.searchsorted(starts, t, side="right") - 1, 0, len(table) - 1)
    tau = t - starts[seg]
    out = []
    for order in range(3):
        cols = []
        for axis in range(2):
            c = table[:, 1 + 8 * axis: 9 + 8 * axis]
            vals = np.empty(n)
            for k in range(len(table)):
                sel = seg == k
                vals[sel] = npoly.polyval(tau[sel], npoly.polyder(c[k], order))
            cols.append(vals)
        out.append(np.column_stack(cols))
    return out[0], out[1], out[2]


def test_the_crazyflie_figure8_is_read_and_checked_exactly() -> None:
    """The Crazyflie examples' figure-eight (tests/data/figure8.csv): at the configured
    centre, north = the file's x, east = minus its y; the check's peaks are the curve's
    (numpy's dense evaluation of the coefficients), and the data README's figures."""
    cfg = validate_config({"trajectory": {"name": "waypoints",
                                          "file": str(DATA / "figure8.csv"),
                                          "center": [0.2, 0.1, -1.3]}})
    traj, duration = trajectory_for_flight(assemble(cfg))
    assert isinstance(traj, PiecewisePolynomial) and duration == pytest.approx(7.283185)
    p, v, acc = _figure8_by_numpy()
    report = check_feasibility(traj, FlightLimits(), horizon_s=duration)
    speed = float(np.max(np.linalg.norm(v, axis=1)))
    accel = float(np.max(np.linalg.norm(acc, axis=1)))
    assert report.max_speed_m_s == pytest.approx(speed, rel=2e-4)
    assert report.max_accel_m_s2 == pytest.approx(accel, rel=2e-4)
    # data/README: 1.22 m/s, 3.07 m/s^2, 17.4 deg of tilt; x -1.00..0.99, y -0.54..0.52
    assert round(report.max_speed_m_s, 2) == 1.22 and round(report.max_accel_m_s2, 2) == 3.07
    assert math.degrees(report.max_tilt_rad) == pytest.approx(17.4, abs=0.1)
    np.testing.assert_allclose(report.extent_min_m[:2],
                               [0.2 + p[:, 0].min(), 0.1 - p[:, 1].max()], atol=1e-6)
    np.testing.assert_allclose(report.extent_max_m[:2],
                               [0.2 + p[:, 0].max(), 0.1 - p[:, 1].min()], atol=1e-6)
    assert report.feasible and report.position_jumps == [] and report.velocity_jumps == []
    np.testing.assert_allclose(traj.sample(0.0).position, [0.2, 0.1, -1.3])


def test_the_crazyflie_figure8_with_spaces_or_tabs_is_the_same_curve(tmp_path: Path) -> None:
    """figure8.csv's table written again by numpy with spaces (and with tabs), its header
    kept: the curve is numpy's evaluation of the coefficients, at the configured centre."""
    header = (DATA / "figure8.csv").read_text().splitlines()[0].split(",")
    table = np.loadtxt(DATA / "figure8.csv", delimiter=",", skiprows=1)
    center = np.array([0.2, 0.1, -1.3])
    p, _, _ = _figure8_by_numpy(n=201)
    t = np.linspace(0.0, float(table[:, 0].sum()), 201)
    for delimiter in (" ", "\t"):
        path = tmp_path / "figure8.txt"
        np.savetxt(path, table, delimiter=delimiter, header=delimiter.join(header),
                   comments="")
        traj = load_trajectory_file(path, center=center, relative=True)
        assert isinstance(traj, PiecewisePolynomial)
        got = np.array([traj.sample(float(x)).position for x in t])
        np.testing.assert_allclose(got[:, 0], center[0] + p[:, 0], atol=1e-9)
        np.testing.assert_allclose(got[:, 1], center[1] - p[:, 1], atol=1e-9)
        np.testing.assert_allclose(got[:, 2], center[2], atol=1e-9)


def test_a_malformed_polynomial_file_is_refused_naming_the_line(tmp_path: Path) -> None:
    path = tmp_path / "bad.csv"
    path.write_text("Duration,x^0,x^1,speed\n1.0,0,0,0\n")
    with pytest.raises(TrajectoryError, match=r"bad\.csv:1: column 4 'speed'"):
        load_polynomial_file(path, origin=[0, 0, -1])
    path.write_text("Duration,x^0,x^1\n1.0,0,0\n-2,0,1\n")
    with pytest.raises(TrajectoryError, match=r"bad\.csv:3: a segment's duration must be > 0"):
        load_polynomial_file(path, origin=[0, 0, -1])
    path.write_text("Duration,x^0,x^1\n1.0,0,nan\n")
    with pytest.raises(TrajectoryError, match=r"bad\.csv:2: values must be finite"):
        load_polynomial_file(path, origin=None)
