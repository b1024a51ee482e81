"""``gs report``'s figure set (groundstation.evaluation.flight_figures), from a short logged
in-process flight of the virtual lab (hover, 2 s of trajectory) with its truth.

Independent answers: the transitions against a plain loop over the ``state`` column,
the Euler angles against scipy's Rotation, the Vicon residual against a synthetic log
whose estimate moves exactly on a known line, the pose rate against a hand count.
The figures are drawn once (module fixture); the transition lines and labels drawn are
read back from each figure's matplotlib artists as it is saved.
"""

from __future__ import annotations

import json
import math
import struct
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from lab_helpers import fly_logged, sim_config
from scipy.spatial.transform import Rotation
from typer.testing import CliRunner

from groundstation.app.recorder import RECORD_DTYPE, read_flight
from groundstation.cli import app
from groundstation.evaluation import flight_figures
from groundstation.evaluation.flight_figures import (
    BENCHMARK_TARGETS,
    FIGURES,
    TIME_AXIS_GID,
    TRANSITION_GID,
    LogLimits,
    euler_angles,
    pose_rate,
    transitions,
    vicon_residuals,
)
from groundstation.evaluation.report import FlightReport, report_flight
from groundstation.flight.supervisor import State
from groundstation.model.quaternion import multiply, quat_from_euler, quat_from_rotvec

EXPECTED = ("flight", "position", "top_view", "attitude", "rates", "commands", "estimator",
            "health", "battery", "timing")
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def flown(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """(flight-log directory, truth file) of a hover flown in-process with the recorder on.

    In-process the log's clock is the lab's, so the truth file's ``start_monotonic`` is 0.
    """
    tmp = tmp_path_factory.mktemp("flight")
    log, result = fly_logged(sim_config(**{"trajectory.name": "hover"}), tmp / "logs", 2.0)
    truth = result.lab.truth_log.arrays()
    np.savez(tmp / "truth.npz", t=truth["t"], position=truth["position"],
             quaternion=truth["quaternion"], start_monotonic=0.0)
    return log, tmp / "truth.npz"


Drawn = tuple[list[list[tuple[float, str]]], list[str], list[str]]
"""Per time axis of a figure, the transition lines (x [s], state name); the labels on top;
the time axes' x labels."""
TIME_AXES = {"flight": 2, "position": 4, "attitude": 3, "rates": 3, "commands": 4,
             "estimator": 8, "health": 6, "battery": 1, "timing": 3, "top_view": 0}
"""Time axes per figure (the estimator's: the NIS, and with truth estimate minus truth)."""


@pytest.fixture(scope="module")
def reported(flown: tuple[Path, Path],
             tmp_path_factory: pytest.TempPathFactory) -> tuple[FlightReport, dict[str, Drawn]]:
    """The report of that flight, figures included (drawn once for the module), and what
    each figure had drawn when it was saved (by file stem)."""
    log, truth = flown
    drawn: dict[str, Drawn] = {}
    real_save = flight_figures.save

    def spy(fig: Any, path: Path) -> Path:
        drawn[path.stem] = _drawn(fig)
        return real_save(fig, path)

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(flight_figures, "save", spy)
        report = report_flight(log, truth, tmp_path_factory.mktemp("report"))
    return report, drawn


@pytest.fixture()
def report(reported: tuple[FlightReport, dict[str, Drawn]]) -> FlightReport:
    """The flight's report."""
    return reported[0]


def png_size(path: Path) -> tuple[int, int]:
    """(width, height) [px] from a PNG's IHDR chunk."""
    head = path.read_bytes()[:24]
    assert head[:8] == PNG_SIGNATURE and head[12:16] == b"IHDR", path
    width, height = struct.unpack(">II", head[16:24])
    return int(width), int(height)


@pytest.mark.slow
def test_every_figure_is_written_as_a_png_and_listed(report: FlightReport) -> None:
    out = report.report_md.parent
    assert [p.name for p in report.figures] == [f"{name}.png" for name in EXPECTED]
    assert report.figure == out / "flight.png" == report.figures[0]
    md = report.report_md.read_text()
    for png in report.figures:
        assert png.parent == out and png.stat().st_size > 10_000, png
        width, height = png_size(png)
        assert 700 <= width <= 2000 and 300 <= height <= 2500, (png, width, height)
        assert f"[{png.name}]({png.name})" in md and f"]({png.name})" in md
    assert "NIS of every pose the estimator judged" in md  # schema 5 records it
    assert json.loads(report.metrics_json.read_text())["metrics"]["final_state"] == "DONE"


def test_transitions_are_the_changes_of_the_state_column(flown: tuple[Path, Path]) -> None:
    rows, meta, _ = read_flight(flown[0])
    t, state, names = rows["t"] - rows["t"][0], rows["state"], meta["supervisor_states"]
    expected = []
    for k in range(1, len(rows)):
        if state[k] != state[k - 1]:
            expected.append((float(t[k]), names[state[k]]))
    assert transitions(t, state, names) == expected
    assert [name for _, name in expected] == ["TAKEOFF", "TRACK", "LAND", "DISARM", "DONE"]
    # no change, a single row, and a value without a name
    assert transitions(np.arange(3.0), [2, 2, 2]) == []
    assert transitions(np.zeros(1), [0]) == []
    assert transitions(np.arange(3.0), [0, 1, 42], ["A", "B"]) == [(1.0, "B"), (2.0, "state 42")]


def _drawn(fig: Any) -> Drawn:
    """Per time axis of ``fig``, the transition lines drawn (x, state name); and the labels
    along the top."""
    per_axis: list[list[tuple[float, str]]] = []
    labels: list[str] = []
    xlabels: list[str] = []
    for ax in fig.axes:
        if ax.get_gid() == TIME_AXIS_GID:
            xlabels.append(ax.get_xlabel())
            per_axis.append(sorted(
                (float(line.get_xdata()[0]), line.get_gid()[len(TRANSITION_GID) + 1:])
                for line in ax.get_lines()
                if (line.get_gid() or "").startswith(TRANSITION_GID)))
        for child in ax.child_axes:
            labels += [text.get_text() for text in child.get_xticklabels()]
    return per_axis, labels, xlabels


def test_every_time_axis_carries_the_transitions_named_once(
        flown: tuple[Path, Path], reported: tuple[FlightReport, dict[str, Drawn]]) -> None:
    rows, meta, _ = read_flight(flown[0])
    expected = transitions(rows["t"] - rows["t"][0], rows["state"], meta["supervisor_states"])
    assert len(expected) == 5
    _, drawn = reported
    assert sorted(drawn) == sorted(stem for stem, _, _ in FIGURES)
    for stem, (per_axis, labels, xlabels) in drawn.items():
        assert len(per_axis) == TIME_AXES[stem], stem
        if stem == "top_view":
            assert labels == []
            continue
        assert all(lines == expected for lines in per_axis), stem
        assert set(xlabels) - {""} == {"time since log start [s]"}, (stem, xlabels)
        # named once per figure: every new state's name in exactly one label, in order
        names = [name for label in labels for name in label.split(" / ")]
        assert names == [name for _, name in expected], (stem, labels)


def test_euler_angles_agree_with_scipy() -> None:
    rng = np.random.default_rng(7)
    q = rng.normal(size=(500, 4))  # any sign, not normalised
    q[:3] = [[1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0], [-0.7, 0.1, -0.2, 0.3]]
    ypr = Rotation.from_quat(q, scalar_first=True).as_euler("ZYX")
    rpy = euler_angles(q)
    ok = np.abs(ypr[:, 1]) < np.radians(85.0)  # away from gimbal lock
    assert ok.sum() > 400
    np.testing.assert_allclose(rpy[ok], ypr[ok, ::-1], atol=1e-9)
    # the project's own convention: quat_from_euler(roll, pitch, yaw)
    np.testing.assert_allclose(euler_angles(quat_from_euler(0.1, -0.2, 3.0)[None, :]),
                               [[0.1, -0.2, 3.0]], atol=1e-12)
    assert np.isnan(euler_angles(np.full((1, 4), np.nan))).all()


def test_the_vicon_residual_is_the_pose_minus_the_predicted_estimate() -> None:
    # the estimate moves exactly on p(t) = p0 + v t, heading east (yaw 90 deg); each pose
    # was measured 4 ms before its tick and is off by d, and rotated by 0.01 rad about x
    n, dt, age = 50, 0.01, 0.004
    p0, v = np.array([0.1, -0.2, -1.0]), np.array([0.3, 0.5, -0.1])
    d, tilt = np.array([0.004, -0.002, 0.001]), np.array([0.01, 0.0, 0.0])
    q = quat_from_euler(0.0, 0.0, np.pi / 2)
    rows = np.zeros(n, dtype=RECORD_DTYPE)
    rows["t"] = t = 100.0 + dt * np.arange(n)
    rows["est_position"] = p0 + v * (t[:, None] - 100.0)
    rows["est_quaternion"] = q
    rows["est_velocity_body"] = Rotation.from_quat(q, scalar_first=True).inv().apply(v)
    rows["vicon_valid"] = np.arange(n) % 3 != 0  # some ticks without a pose
    rows["vicon_t"] = t - age
    rows["vicon_position"] = p0 + v * (t[:, None] - age - 100.0) + d
    rows["vicon_quaternion"] = multiply(q, quat_from_rotvec(tilt))
    pos, att = vicon_residuals(rows)
    has = rows["vicon_valid"].copy()
    has[0] = False  # no tick before the first
    np.testing.assert_allclose(pos[has], np.tile(d, (has.sum(), 1)), atol=1e-12)
    np.testing.assert_allclose(att[has], np.tile(tilt, (has.sum(), 1)), atol=1e-9)
    assert np.isnan(pos[~has]).all() and np.isnan(att[~has]).all()


def test_pose_rate_counts_the_poses_of_the_last_second() -> None:
    t = 0.01 * np.arange(400)
    valid = np.ones(400, dtype=bool)
    valid[200:300:2] = False  # half the poses missing for 1 s
    rate = pose_rate(t, valid)
    assert np.isnan(rate[t < 1.0]).all()
    assert rate[150] == pytest.approx(100.0)
    assert rate[299] == pytest.approx(50.0)  # ticks 200..299: 50 poses
    assert rate[-1] == pytest.approx(100.0)


def test_limits_come_from_the_flights_config(flown: tuple[Path, Path]) -> None:
    _, _, config = read_flight(flown[0])
    cfg = sim_config(**{"trajectory.name": "hover"})
    lim = LogLimits.from_config(config)
    assert lim.data_period_s == pytest.approx(cfg.serial.data_period_ms / 1000.0)
    assert lim.command_period_s == pytest.approx(1.0 / cfg.serial.command_rate_hz)
    assert lim.k_rate == tuple(cfg.vehicle.k_rate)
    assert lim.battery_land_v == cfg.safety.battery_land_v
    odd = LogLimits.from_config("serial: {command_rate_hz: 100}\nsafety: {battery_land_v: null}\n")
    assert odd.command_period_s == pytest.approx(0.01) and odd.battery_land_v is None
    assert LogLimits.from_config(": not yaml [").data_period_s == lim.data_period_s
    # compute has no target of its own (the 200 us one is retired): latency is what counts
    assert BENCHMARK_TARGETS.compute_p99_ms is None and BENCHMARK_TARGETS.latency_p99_ms


def test_without_matplotlib_the_metrics_are_still_written(
        flown: tuple[Path, Path], tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "matplotlib", None)  # import matplotlib -> ImportError
    out = tmp_path / "r"
    result = CliRunner().invoke(app, ["report", str(flown[0]), "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert "no figures" in result.output and "groundstation[plot]" in result.output
    assert (out / "metrics.json").is_file() and (out / "report.md").is_file()
    assert list(out.glob("*.png")) == []
    assert "## Figures" not in (out / "report.md").read_text()
    assert State.DONE.name in (out / "metrics.json").read_text()


def test_the_log_records_a_consistent_filters_nis(flown: tuple[Path, Path]) -> None:
    """The virtual lab's noise is the filter's noise model, so the NIS of the poses it
    judged while hovering follows the chi-square distribution with 6 dof: its median is
    scipy's chi2(6).median() within the spread of a sample median of this size."""
    from scipy.stats import chi2

    from groundstation.app.recorder import read_flight

    rows, _, _ = read_flight(flown[0])
    nis = rows["vicon_nis"][(rows["state"] == int(State.TRACK)) & np.isfinite(rows["vicon_nis"])]
    assert nis.size > 100
    median = float(chi2.median(6))
    # the sample median's std is sqrt(p (1 - p) / n) / f(median); four of them and a margin
    # for the poses' correlation through the filter (a noise model off by 2x moves it ~2.7)
    spread = math.sqrt(0.25 / nis.size) / float(chi2.pdf(median, 6))
    assert abs(float(np.median(nis)) - median) < 4 * spread + 0.5, (np.median(nis), spread)
    assert rows["vicon_refused"][rows["state"] == int(State.TRACK)].sum() == 0
