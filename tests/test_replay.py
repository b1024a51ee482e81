"""gs replay: a recorded flight replays to (near) identity; a changed config shows up."""

from __future__ import annotations

from pathlib import Path

import pytest
from typer.testing import CliRunner

from groundstation.app.inprocess import fly_in_process
from groundstation.app.recorder import FlightRecorder
from groundstation.app.replay import replay_flight
from groundstation.cli import app
from groundstation.config import apply_overrides, dump_config, load_config
from groundstation.flight.assembly import assemble
from groundstation.flight.supervisor import State

REPO = Path(__file__).resolve().parents[1]


def recorded_flight(tmp_path: Path) -> str:
    cfg = apply_overrides(load_config(REPO / "config" / "sim.yaml"),
                          {"trajectory.name": "square", "sim.vicon.rate_hz": 10.0})
    with FlightRecorder.create(tmp_path, dump_config(cfg),
                               {"supervisor_states": [s.name for s in State]}) as rec:
        result = fly_in_process(assemble(cfg), duration_s=8.0, max_time_s=60.0, recorder=rec)
        directory = str(rec.directory)
    assert result.final_state is State.DONE
    return directory


@pytest.mark.slow
def test_replay_with_the_flight_config_reproduces_it(tmp_path: Path) -> None:
    log = recorded_flight(tmp_path)
    report = replay_flight(log)
    assert report.estimator_ticks > 1000 and report.controller_ticks > 800
    # Same inputs in the same order: the estimator reproduces the flight. At 10 Hz Vicon
    # every tick carries at most one pose, so nothing is lost in the log.
    assert report.position_max_m < 1e-9 and report.attitude_max_rad < 1e-9
    # The controller is deterministic given the logged estimate and reference.
    assert report.stick_max == (0, 0, 0, 0)

    # A different controller tuning shows up as stick differences, not as a crash.
    cfg = load_config(REPO / "config" / "sim.yaml")
    softer = apply_overrides(cfg, {"controller.lqr_ff.q_error": [1.0, 1.0, 5.0, 1.0]})
    changed = replay_flight(log, softer)
    assert max(changed.stick_max) > 10
    assert changed.position_max_m < 1e-9  # the estimator did not change


@pytest.mark.slow
def test_cli_replay(tmp_path: Path) -> None:
    log = recorded_flight(tmp_path)
    res = CliRunner().invoke(app, ["replay", log])
    assert res.exit_code == 0, res.output
    assert "estimator" in res.output and "controller" in res.output
