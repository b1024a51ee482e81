"""A fleet of three virtual vehicles flown through the relay, end to end.

Every part is a process of its own, as in a lab: ``gs sim-device --fleet`` (three
virtual X-3Ds on three ptys, one Vicon stream carrying all three objects), ``gs
vicon-relay`` (the only reader of that stream), three ``gs fleet fly`` daemons taking
their poses from Zenoh, this test's :class:`groundstation.client.Fleet`, and the ``gs
fleet`` command line. One flight serves every assertion (a module fixture): the hover
judged by the virtual lab's ground truth, a motion refused for the separation and one
accepted, the fleet's status, ``examples/fleet_eight.py`` (three figure-eights in phase,
then every vehicle landed at once), each vehicle handed back.
"""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from lab_helpers import realtime_sim_config

from groundstation.app.recorder import read_flight
from groundstation.client import Fleet, Status, TooClose
from groundstation.fleetops.demo import homes
from groundstation.fleetops.judge import rms, tracking
from groundstation.fleetops.virtual import VirtualFleet, write_fleet
from groundstation.flight.supervisor import State

REPO = Path(__file__).resolve().parents[1]
GS = str(Path(sys.executable).parent / "gs")
SEPARATION_M = 0.4  # the eights of examples/fleet_eight.py keep 0.5 m


@pytest.fixture(scope="module")
def flown(tmp_path_factory: pytest.TempPathFactory, fleet_alone: None) -> dict[str, Any]:
    """Three vehicles 1 m apart: take off, hover, one motion refused and one flown, the
    status from the shell, the example's eights in phase and its landing."""
    workdir = tmp_path_factory.mktemp("fleet")
    fleet_file = write_fleet(workdir, realtime_sim_config(), homes(3),
                             separation_m=SEPARATION_M)
    lines: list[str] = []
    out: dict[str, Any] = {"lines": lines}
    with VirtualFleet(fleet_file, echo=lines.append) as vf:
        with Fleet(vf.run_file) as fleet:
            out["tracking"] = fleet.wait_for_state("TRACK", timeout=120.0)
            # the shell's status while they hover: a process's start (2 s) inside the 3 s
            # the truth is judged on, not after them
            status = subprocess.Popen([GS, "fleet", "status", str(vf.run_file)],
                                      stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                      text=True)
            time.sleep(3.0)  # the hover the truth is judged on
            out["hover_end"] = time.monotonic()
            try:
                stdout, stderr = status.communicate(timeout=30)
            except subprocess.TimeoutExpired:
                status.kill()
                stdout, stderr = status.communicate()
            out["status"] = subprocess.CompletedProcess(status.args, status.returncode,
                                                        stdout, stderr)
            try:  # v1 asked to go 0.3 m from where v2 hovers
                fleet["v1"].go_to([-0.3, 0.0, -1.0])
            except TooClose as exc:
                out["refused"] = exc
            out["accepted"] = fleet["v1"].go_to([-1.0, 0.4, -1.2], wait=True, timeout=20.0)
        out["example_start"] = time.monotonic()
        out["example"] = subprocess.run(
            [sys.executable, str(REPO / "examples" / "fleet_eight.py"), str(vf.run_file)],
            capture_output=True, text=True, timeout=180)
        out["codes"] = vf.wait()
    out["logs"] = {name: vf.log_dir(name) for name in vf.names}
    out["truth"] = dict(vf.truth_files)
    return out


@pytest.mark.realtime
@pytest.mark.slow
@pytest.mark.timeout(400)
def test_each_vehicle_hovers_within_a_centimetre_of_its_reference(flown: dict[str, Any]
                                                                  ) -> None:
    for name, log in flown["logs"].items():
        track = tracking(log, flown["truth"][name])
        # cut by time: the motions asked for after the hover must not count (the
        # vehicle still closing on a go_to's end point is not hovering)
        hover = track.window(State.TRACK, start_after_s=1.0, at_rest=True,
                             until=flown["hover_end"])
        assert len(hover) > 150, name  # at least 1.5 s of 100 Hz rows
        # "within 1 cm" as every hover target of the project reads: RMS by the truth
        assert rms(hover) < 0.01, (name, rms(hover))


@pytest.mark.realtime
@pytest.mark.slow
@pytest.mark.timeout(400)
def test_a_motion_towards_a_peer_is_refused_one_that_keeps_clear_flies(
        flown: dict[str, Any]) -> None:
    refused = flown["refused"]
    assert isinstance(refused, TooClose), flown["lines"][-40:]
    assert refused.kind == "separation" and "v2" in refused.reason
    assert "0.40 m" in refused.reason  # fleet.separation_m named
    accepted = flown["accepted"]
    assert accepted.state == "arrived" and accepted.kind == "go_to"
    track = tracking(flown["logs"]["v1"], flown["truth"]["v1"])
    assert np.min(np.linalg.norm(track.truth - [-1.0, 0.4, -1.2], axis=1)) < 0.02


@pytest.mark.realtime
@pytest.mark.slow
@pytest.mark.timeout(400)
def test_the_fleet_answers_its_status_flies_in_phase_and_lands_as_one(
        flown: dict[str, Any]) -> None:
    assert all(isinstance(s, Status) for s in flown["tracking"].values())
    status = flown["status"]
    assert status.returncode == 0, status.stdout + status.stderr
    assert [line.split(":")[0] for line in status.stdout.splitlines()] == ["v1", "v2", "v3"]
    assert all(" TRACK " in f" {line} " for line in status.stdout.splitlines())
    example = flown["example"]
    assert example.returncode == 0, example.stdout + example.stderr
    assert example.stdout.count("lap flown") == 3
    assert example.stdout.count("outcome='COMPLETED'") == 3
    assert flown["codes"] == {"v1": 0, "v2": 0, "v3": 0}


@pytest.mark.realtime
@pytest.mark.slow
@pytest.mark.timeout(400)
def test_each_vehicle_is_handed_back_on_the_floor(flown: dict[str, Any]) -> None:
    for name, log in flown["logs"].items():
        rows, meta, _ = read_flight(log)
        assert meta["outcome"]["final_state"] == "DONE", (name, meta["outcome"])
        assert rows["cmd_mask"][-1] == 0, name
        truth = np.load(flown["truth"][name])
        assert truth["position"][-1][2] > -0.02, name  # on the floor
        assert truth["ctrl_mask"][-1] == 0, name  # the vehicle applies the pilot's sticks


@pytest.mark.realtime
@pytest.mark.slow
@pytest.mark.timeout(400)
def test_the_three_eights_are_flown_in_phase(flown: dict[str, Any]) -> None:
    """Each reference reaches its eight's east-most point (0.5 m east of its centre) at
    the same moment, and the truth follows it. Three daemons and three virtual vehicles
    share two cores with the other test workers, so the bound is the one that tells a
    flown eight from one not flown, not the quiet machine's figure: 0.25-0.27 cm RMS in
    `make demo FLEET=3` alone, 3.5 cm once in `make test`, while a vehicle that did not
    fly its eight would be half a metre off."""
    peaks = []
    for name, log in flown["logs"].items():
        track = tracking(log, flown["truth"][name])
        after = (track.t > flown["example_start"]) & (track.state == int(State.TRACK))
        east = track.reference[after, 1]
        centre = 0.5 * (east.max() + east.min())  # its hover point: the eight's centre
        assert east.max() - centre == pytest.approx(0.5, abs=1e-3), name  # 1 m wide
        peaks.append(track.t[after][int(np.argmax(east - centre > 0.5 - 1e-3))])
        assert rms(track.error[after]) < 0.10, name
    assert max(peaks) - min(peaks) < 0.05, peaks  # in phase: within 50 ms
