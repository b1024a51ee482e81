"""``gs fleet up``: the relay first, one daemon per vehicle, their lines echoed with their
names, the most urgent exit code, the relay stopped last."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from groundstation.config import load_config
from groundstation.fleetops.manager import fleet_exit_code
from groundstation.fleetops.virtual import write_fleet

REPO = Path(__file__).resolve().parents[1]


def test_the_most_urgent_exit_code_wins() -> None:
    assert fleet_exit_code({"a": 0, "b": 0}) == 0
    assert fleet_exit_code({"a": 4, "b": 0}) == 4
    assert fleet_exit_code({"a": 4, "b": 3, "c": 2}) == 3
    assert fleet_exit_code({"a": 5, "b": 1, "c": 4}) == 1
    assert fleet_exit_code({"a": 2, "b": 5}) == 5
    assert fleet_exit_code({"a": -9, "b": 0}) == 1  # killed: its watchdog handed it back
    assert fleet_exit_code({"a": 4, "b": 70}) == 1


@pytest.mark.slow
def test_gs_fleet_up_starts_the_relay_and_every_daemon_and_reports_them(tmp_path: Path
                                                                        ) -> None:
    """Two vehicles whose radios are not there: each daemon exits 3 (could not start,
    nothing sent), `gs fleet up` names both and exits 3; the relay was up meanwhile and
    stopped after them."""
    fleet = write_fleet(tmp_path, load_config(REPO / "config" / "sim.yaml"),
                        [(-0.5, 0.0), (0.5, 0.0)])
    result = subprocess.run([str(Path(sys.executable).parent / "gs"), "fleet", "up",
                             str(fleet)], capture_output=True, text=True, timeout=120)
    lines = result.stdout.splitlines()
    assert result.returncode == 3, result.stdout + result.stderr
    assert any(line.startswith("[relay] vicon relay: udp://127.0.0.1:") for line in lines)
    assert any(line.startswith("[relay] vicon relay stopped") for line in lines)
    for name in ("v1", "v2"):
        assert any(line.startswith(f"[{name}] error:") and "virtual:" in line
                   for line in lines), lines
        assert f"{name}: exit 3" in lines
    relay_stop = max(i for i, x in enumerate(lines) if x.startswith("[relay] vicon relay stopped"))
    assert relay_stop > max(i for i, x in enumerate(lines) if x.startswith("[v"))
