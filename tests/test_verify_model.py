"""`gs verify-model LOG` (thesis Ch. 5) on flights in the virtual lab.

The virtual vehicle flies the model's physics plus what the model leaves out (the rate
loop's lag, the command delay, motor lag, battery droop), so on a flight of the nominal
vehicle the nonlinear model's velocity-derivative error is small against the signal and
has no bias; with a planted thrust-map error (the lab's lift 0.9 of the model's, which
the controller's integral action compensates with more stick) the model overestimates
the lift by the planted amount, and the reported bias of v3_dot is its size:
(1/0.9 - 1) g = 1.09 m/s^2 in the model's direction (more upward, negative in FRD z).
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
from lab_helpers import empty_log, fly_logged, sim_config

from groundstation.identification.verify import VerificationError, verify_model

REPO = Path(__file__).resolve().parents[1]


def flight(tmp_path: Path, overrides: dict[str, object], duration_s: float = 12.0) -> str:
    cfg = sim_config(**{"trajectory.name": "figure-eight", **overrides})
    return str(fly_logged(cfg, tmp_path, duration_s)[0])


@pytest.mark.slow
def test_nominal_vehicle_fits_and_a_thrust_error_shows_as_its_size(tmp_path: Path) -> None:
    nominal = verify_model(flight(tmp_path / "a", {})).figures()
    assert nominal["samples"] > 1000
    # the velocity derivatives are predicted within their own size, without bias (the
    # rest is the estimate's noise and what the model leaves out: rate and motor lags)
    for axis, share in (("v1_dot", 0.7), ("v2_dot", 0.7), ("v3_dot", 0.4)):
        assert nominal[f"nonlinear_rms_{axis}"] < share * nominal[f"signal_rms_{axis}"], axis
    assert abs(nominal["nonlinear_mean_v3_dot"]) < 0.1
    weak = verify_model(flight(tmp_path / "b", {"sim.thrust_scale": 0.9})).figures()
    assert weak["nonlinear_mean_v3_dot"] == pytest.approx(-(1 / 0.9 - 1) * 9.82, abs=0.15)
    assert weak["linear_mean_v3_dot"] == pytest.approx(-(1 / 0.9 - 1) * 9.82, abs=0.15)


def test_a_hover_on_the_floor_is_refused(tmp_path: Path) -> None:
    with pytest.raises(VerificationError, match="airborne samples"):
        verify_model(empty_log(tmp_path))


@pytest.mark.slow
def test_the_command_prints_json_and_writes_the_figure(tmp_path: Path) -> None:
    log = flight(tmp_path, {}, duration_s=6.0)
    out = subprocess.run([sys.executable, "-m", "groundstation", "verify-model", log, "--json",
                          "--out", str(tmp_path)], capture_output=True, text=True, timeout=120,
                         cwd=REPO)
    assert out.returncode == 0, out.stderr
    got = json.loads(out.stdout)
    assert got["samples"] > 300 and "nonlinear_rms_v3_dot" in got
    assert (tmp_path / "verify-model.png").stat().st_size > 20_000
