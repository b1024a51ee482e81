"""`gs trajectory` and `gs check-config` on trajectory files: what a file was taken to be,
its peaks against the limits, the verdict and its exit code, and the figure to look at
before flying."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from groundstation.cli import app

REPO = Path(__file__).resolve().parents[1]
LAB = REPO / "config" / "lab.yaml"
FIGURE8 = REPO / "tests" / "data" / "figure8.csv"
runner = CliRunner()


def eight_csv(path: Path, period: float, hz: float = 50.0) -> Path:
    """A lemniscate 1.2 m x 0.6 m at 1 m height, one lap, as numpy's savetxt writes it."""
    w = 2 * math.pi / period
    t = np.arange(0.0, period + 0.5 / hz, 1.0 / hz)
    rows = np.column_stack([t, 0.3 * np.sin(2 * w * t), 0.6 * np.sin(w * t), -np.ones_like(t)])
    np.savetxt(path, rows, delimiter=",", header="t,x,y,z", comments="")
    return path


@pytest.mark.slow
def test_a_dense_file_is_described_checked_and_drawn(tmp_path: Path) -> None:
    csv = eight_csv(tmp_path / "eight.csv", 8.0)
    png = tmp_path / "eight.png"
    result = runner.invoke(app, ["trajectory", str(csv), "--config", str(LAB), "--plot",
                                 str(png)])
    assert result.exit_code == 0, result.output
    out = result.output
    assert "dense samples: 401 rows at 50 Hz" in out and "fitted with a quintic" in out
    assert "eased in and out" in out  # it starts and ends at the centre, moving
    assert "speed          0.67 m/s" in out  # sqrt(2) 0.6 (2 pi / 8)
    assert "verdict: flyable within the limits" in out
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 20_000


def test_the_crazyflie_figure8_is_flyable_in_the_lab_configuration() -> None:
    result = runner.invoke(app, ["trajectory", str(FIGURE8), "--config", str(LAB)])
    assert result.exit_code == 0, result.output
    assert "polynomial segments (uav_trajectories / Crazyswarm file figure8.csv)" in result.output
    assert "tilt           17.3 deg           20.0 deg" in result.output


def test_a_file_too_fast_is_refused_with_exit_2_and_a_slow_down(tmp_path: Path) -> None:
    csv = eight_csv(tmp_path / "fast.csv", 2.0)
    result = runner.invoke(app, ["trajectory", str(csv), "--config", str(LAB)])
    assert result.exit_code == 2
    assert "verdict: refused" in result.output and "slow it down by k = " in result.output


def test_files_that_cannot_be_used_are_one_line_errors(tmp_path: Path) -> None:
    missing = runner.invoke(app, ["trajectory", str(tmp_path / "absent.csv")])
    assert missing.exit_code == 2 and "absent.csv" in missing.output
    assert "Traceback" not in missing.output
    bad = tmp_path / "bad.csv"
    bad.write_text("Duration,x^0,x^1\n1.0,0,zero\n")
    result = runner.invoke(app, ["trajectory", str(bad)])
    assert result.exit_code == 2 and "bad.csv:2: not a number" in result.output
    assert runner.invoke(app, ["trajectory", "none"]).exit_code == 2


def test_without_matplotlib_the_check_stands_and_a_note_says_so(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "matplotlib", None)  # import matplotlib fails
    result = runner.invoke(app, ["trajectory", "square", "--plot", str(tmp_path / "sq.png")])
    assert result.exit_code == 0, result.output
    assert "no figure: figures need matplotlib: pip install 'groundstation[plot]'" in \
        result.output
    assert not (tmp_path / "sq.png").exists()


def test_check_config_prints_what_the_file_was_taken_to_be(tmp_path: Path) -> None:
    config = tmp_path / "gs.yaml"
    config.write_text(LAB.read_text().replace(
        "trajectory:\n  name: square", f"trajectory:\n  name: waypoints\n  file: {FIGURE8}"))
    result = runner.invoke(app, ["check-config", "--show", str(config)])
    assert result.exit_code == 0, result.output
    assert "# trajectory 'waypoints': polynomial segments" in result.output
    assert "#   verdict: flyable within the limits" in result.output


def test_gs_fly_refuses_a_file_too_fast_before_connecting(tmp_path: Path) -> None:
    csv = eight_csv(tmp_path / "fast.csv", 2.0)
    result = runner.invoke(app, ["fly", "--config", str(LAB), "--trajectory", str(csv),
                                 "--serial-port", "loop://"])
    assert result.exit_code == 2 and "cannot be flown" in result.output
