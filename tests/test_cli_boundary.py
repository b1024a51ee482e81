"""Every `gs` command goes through one error boundary: the console script
runs :func:`groundstation.cli.main`, which turns a user's mistake into one line and a
documented exit code, never a traceback. Run as a user runs it: the installed script
in a subprocess."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from groundstation.flight.assembly import assemble

ROOT = Path(__file__).resolve().parents[1]
GS = [sys.executable, "-c", "import sys; from groundstation.cli import main; "
      "sys.argv[0] = 'gs'; main()"]


def _gs(*args: str, env: dict[str, str] | None = None) -> subprocess.CompletedProcess[str]:
    return subprocess.run([*GS, *args], capture_output=True, text=True, timeout=120, cwd=ROOT,
                          env={**os.environ, **(env or {})})


def test_the_console_script_is_the_boundary() -> None:
    import tomllib

    scripts = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["scripts"]
    assert scripts["gs"] == "groundstation.cli:main"


@pytest.mark.slow
@pytest.mark.parametrize(("args", "code", "text"), [
    (("check-config", "missing.yaml"), 2, "missing.yaml: cannot read"),
    (("check-config", "config"), 2, "config: cannot read"),
    (("report", "no-such-log"), 2, "no-such-log: no such flight log"),
    (("export", "no-such-log"), 2, "no-such-log: no such flight log"),
    (("replay", "no-such-log"), 2, "no-such-log: no such flight log"),
])
def test_a_users_mistake_is_one_line_and_a_code(args: tuple[str, ...], code: int,
                                                text: str) -> None:
    out = _gs(*args)
    assert out.returncode == code, out.stderr
    assert text in out.stderr
    assert "Traceback" not in out.stderr
    lines = out.stderr.splitlines()
    assert lines[0].startswith("error:") and text in lines[0]
    # check-config ends with its verdict; everything else says it in one line
    assert lines[1:] == ([f"{args[1]}: invalid, 1 problem"] if args[0] == "check-config"
                         else [])


@pytest.fixture(scope="module")
def flight_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A short real flight log (in-process flight of the virtual lab, recorder on)."""
    from groundstation.app.inprocess import fly_in_process
    from groundstation.app.recorder import FlightRecorder
    from groundstation.config import apply_overrides, dump_config, load_config
    from groundstation.flight.supervisor import State

    out = tmp_path_factory.mktemp("log")
    cfg = apply_overrides(load_config(ROOT / "config" / "sim.yaml"), {"trajectory.name": "hover"})
    with FlightRecorder.create(out, dump_config(cfg),
                               {"supervisor_states": [s.name for s in State]}) as recorder:
        fly_in_process(assemble(cfg), duration_s=2.0, max_time_s=40.0, recorder=recorder)
    return Path(recorder.directory)


@pytest.mark.slow
def test_a_truth_file_that_is_not_one_is_an_error_line(flight_log: Path,
                                                       tmp_path: Path) -> None:
    bad = tmp_path / "other.npy"
    np.save(bad, np.arange(10.0))
    out = _gs("report", str(flight_log), "--truth", str(bad), "--out", str(tmp_path / "r"))
    assert out.returncode == 2, out.stderr  # a file that is not what the command expects
    assert "other.npy" in out.stderr and "Traceback" not in out.stderr


@pytest.mark.slow
def test_a_closed_pipe_exits_quietly(flight_log: Path) -> None:
    child = subprocess.Popen([*GS, "export", str(flight_log)], stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, cwd=ROOT)
    assert child.stdout is not None and child.stderr is not None
    child.stdout.read(10)
    child.stdout.close()  # the reader goes away, as `| head -c 10` does
    err = child.stderr.read().decode()
    assert child.wait(timeout=60) == 141
    assert err == ""


def _without(package: str, tmp_path: Path) -> dict[str, str]:
    """An environment in which importing ``package`` fails as if it were not installed."""
    fake = tmp_path / "site" / package
    fake.mkdir(parents=True)
    (fake / "__init__.py").write_text(
        f"raise ModuleNotFoundError(\"No module named '{package}'\", name='{package}')\n")
    return {"PYTHONPATH": str(tmp_path / "site")}


@pytest.mark.slow
def test_a_missing_optional_package_names_the_extra(flight_log: Path, tmp_path: Path) -> None:
    out = _gs("export", str(flight_log), "--format", "mcap", "--out", str(tmp_path / "f.mcap"),
              env=_without("foxglove", tmp_path))  # the MCAP is foxglove-sdk's writer's
    assert out.returncode == 1, out.stderr
    assert "pip install 'groundstation[analysis]'" in out.stderr
    assert "Traceback" not in out.stderr


@pytest.mark.slow
def test_a_report_without_matplotlib_still_writes_its_metrics(flight_log: Path,
                                                              tmp_path: Path) -> None:
    out = _gs("report", str(flight_log), "--out", str(tmp_path / "r"),
              env=_without("matplotlib", tmp_path))
    assert out.returncode == 0, out.stderr
    assert "pip install 'groundstation[plot]'" in out.stderr  # the one-line note
    assert (tmp_path / "r" / "metrics.json").is_file()
    assert not (tmp_path / "r" / "flight.png").exists()
    assert "Traceback" not in out.stderr
