"""A user's mistake, as `gs` reports it: the exit code the README promises (2 for a file
that is missing or not what the command expects, a bad configuration or usage), one line
per problem naming the file, the field and its line in the file, never a traceback; and
`gs check-config`'s verdict line. Run as a user runs it: the console script's entry point
in a subprocess, the inputs written as a person or another tool writes them."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
import yaml
from lab_helpers import empty_log

ROOT = Path(__file__).resolve().parents[1]
GS = [sys.executable, "-c", "import sys; from groundstation.cli import main; "
      "sys.argv[0] = 'gs'; main()"]


def _gs(*args: str, cwd: Path = ROOT) -> subprocess.CompletedProcess[str]:
    return subprocess.run([*GS, *args], capture_output=True, text=True, timeout=120, cwd=cwd,
                          env={**os.environ, "PYTHONPATH": str(ROOT)})


def _one_error_line(run: subprocess.CompletedProcess[str], *names: str) -> str:
    """The run's one stderr line, checked: exit 2, ``error: `` first, each name in it, no
    traceback and nothing on stdout."""
    assert run.returncode == 2, (run.returncode, run.stderr)
    assert "Traceback" not in run.stderr and run.stdout == "", run
    lines = run.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), run.stderr
    for name in names:
        assert name in lines[0], (name, lines[0])
    return lines[0]


@pytest.mark.slow
@pytest.mark.parametrize("command", ["export", "report", "replay", "verify-model"])
def test_a_flight_log_that_is_not_there_exits_2_naming_it(command: str) -> None:
    line = _one_error_line(_gs(command, "no/such/log"), "no/such/log: no such flight log")
    assert "Errno" not in line


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["directory", "file"])
def test_something_that_is_not_a_flight_log_exits_2_naming_it(tmp_path: Path,
                                                              kind: str) -> None:
    target = tmp_path / "notalog"
    if kind == "directory":
        target.mkdir()
        (target / "notes.txt").write_text("not a flight\n")
    else:
        target.write_text("t,x\n0,1\n")  # a CSV another tool wrote
    line = _one_error_line(_gs("export", str(target)), str(target), "not a flight log")
    assert "Errno" not in line and "flight.npy'" not in line


@pytest.mark.slow
def test_a_truth_file_that_is_not_there_exits_2_naming_it(tmp_path: Path) -> None:
    log = empty_log(tmp_path / "logs")
    missing = tmp_path / "none.npz"
    line = _one_error_line(_gs("report", str(log), "--truth", str(missing)),
                           f"{missing}: no such truth file")
    assert "FileNotFoundError" not in line


# a configuration as a person writes it: comments, blank lines, sections in their order
HEAVY = """\
# our X-3D with the camera mount
serial:
  port: /dev/ttyUSB0

vehicle:
  # weighed on the kitchen scale
  mass_kg: 6.0
  gravity: 9.81
"""

THREE_WRONG = """\
safety:
  volume_x: [1.5, -1.5]   # min, max (swapped by mistake)
  max_speed_m_s: 1.0
vehicle:
  mass_kg: 6.0
trajectory:
  name: square
  size_m: 0.75
  periodd_s: 20
"""


def _line_of(text: str, key: str) -> int:
    """The 1-based line of the first line of ``text`` that sets ``key`` (found by reading
    the text, as a person would)."""
    return next(i for i, line in enumerate(text.splitlines(), start=1)
                if line.strip().startswith(f"{key}:"))


@pytest.mark.slow
def test_an_impossible_mass_is_reported_as_the_mass_with_its_line(tmp_path: Path) -> None:
    path = tmp_path / "lab.yaml"
    path.write_text(HEAVY)
    line = _one_error_line(_gs("fly", "--config", str(path)),
                           f"{path}:{_line_of(HEAVY, 'mass_kg')}: vehicle.mass_kg: 6.0: ",
                           "could not hover")
    # the weight the message gives is this mass at this gravity: 6.0 kg x 9.81 m/s^2
    assert f"weighs {6.0 * 9.81:.2f} N" in line


@pytest.mark.slow
def test_a_thrust_map_too_weak_for_the_default_mass_is_the_thrust_maps(tmp_path: Path) -> None:
    text = "vehicle:\n  thrust_poly: [0.0, 0.0, -0.001, 0.0]  # a stand with a weak motor\n"
    path = tmp_path / "weak.yaml"
    path.write_text(text)
    _one_error_line(_gs("fly", "--config", str(path)), f"{path}:2: vehicle.thrust_poly: ",
                    "could not hover")


@pytest.mark.slow
def test_check_config_gives_one_line_per_problem_with_its_line_then_the_verdict(
        tmp_path: Path) -> None:
    path = tmp_path / "lab.yaml"
    path.write_text(THREE_WRONG)
    run = _gs("check-config", str(path))
    assert run.returncode == 2 and run.stdout == "" and "Traceback" not in run.stderr, run
    lines = run.stderr.splitlines()
    expected = {"safety.volume_x": _line_of(THREE_WRONG, "volume_x"),
                "vehicle.mass_kg": _line_of(THREE_WRONG, "mass_kg"),
                "trajectory.periodd_s": _line_of(THREE_WRONG, "periodd_s")}
    assert len(lines) == len(expected) + 1, run.stderr
    for field, number in expected.items():
        naming = [line for line in lines if f": {field}: " in line]
        assert len(naming) == 1 and naming[0].startswith(f"error: {path}:{number}: "), \
            (field, run.stderr)
    assert lines[-1] == f"{path}: invalid, {len(expected)} problems"


@pytest.mark.slow
def test_check_config_on_a_good_file_is_one_verdict_line(tmp_path: Path) -> None:
    for args in (["config/sim.yaml"], ["--config", "config/sim.yaml"], ["-c", "config/sim.yaml"]):
        run = _gs("check-config", *args)
        assert run.returncode == 0, run.stderr
        lines = run.stdout.splitlines()
        assert len(lines) == 1 and lines[0].startswith("config/sim.yaml: valid: "), run.stdout
        assert "trajectory square" in lines[0] and "flyable" in lines[0]


@pytest.mark.slow
def test_check_config_show_prints_the_configuration_and_ends_with_the_verdict() -> None:
    run = _gs("check-config", "--show", "-c", "config/sim.yaml")
    assert run.returncode == 0, run.stderr
    shown = yaml.safe_load(run.stdout)  # still a configuration file: the rest are comments
    assert shown["vehicle"]["mass_kg"] == pytest.approx(0.6)
    assert "trajectory" in shown and "safety" in shown
    assert re.fullmatch(r"# config/sim\.yaml: valid: .*", run.stdout.splitlines()[-1])


@pytest.mark.slow
def test_check_config_refuses_two_different_files() -> None:
    _one_error_line(_gs("check-config", "config/sim.yaml", "--config", "config/lab.yaml"),
                    "two configurations given")
