"""The fleet's systemd units: the template runs one vehicle's daemon per instance with every
setting of the single vehicle's unit (never restarted, notify, watchdog, stop to land);
the relay's unit restarts it (it commands nothing); systemd accepts both."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest
from test_sdnotify import unit_settings
from typer.testing import CliRunner

from groundstation.cli import app


def test_the_template_is_the_single_unit_running_gs_fleet_fly(repo: Path) -> None:
    single = unit_settings(repo / "config" / "groundstation.service")
    template = unit_settings(repo / "config" / "groundstation@.service")
    assert template["Service"]["ExecStart"] == [
        "/opt/groundstation/.venv/bin/gs fleet fly /etc/groundstation/fleet.yaml %i"]
    differs = {key for key in single["Service"]
               if single["Service"][key] != template["Service"].get(key)}
    assert differs == {"ExecStart"}
    assert template["Service"]["Restart"] == ["no"] and template["Service"]["Type"] == ["notify"]
    assert "groundstation-relay.service" in template["Unit"]["After"][0]
    relay = unit_settings(repo / "config" / "groundstation-relay.service")["Service"]
    assert relay["ExecStart"] == [
        "/opt/groundstation/.venv/bin/gs vicon-relay /etc/groundstation/fleet.yaml"]
    assert relay["Restart"] == ["on-failure"]
    for words in (["fleet", "fly"], ["vicon-relay"]):  # the commands they run exist
        assert CliRunner().invoke(app, [*words, "--help"]).exit_code == 0


@pytest.mark.skipif(shutil.which("systemd-analyze") is None, reason="systemd-analyze missing")
@pytest.mark.parametrize(("source", "name"), [("groundstation@.service",
                                               "groundstation@x3d-1.service"),
                                              ("groundstation-relay.service",
                                               "groundstation-relay.service")])
def test_systemd_accepts_the_units(repo: Path, tmp_path: Path, source: str, name: str) -> None:
    text = (repo / "config" / source).read_text()
    unit = tmp_path / name
    unit.write_text(text.replace("/opt/groundstation/.venv/bin/gs", shutil.which("true") or ""))
    if source.startswith("groundstation@"):
        (tmp_path / "groundstation-relay.service").write_text(
            (repo / "config" / "groundstation-relay.service").read_text().replace(
                "/opt/groundstation/.venv/bin/gs", shutil.which("true") or ""))
    result = subprocess.run(["systemd-analyze", "verify", str(unit)], capture_output=True,
                            text=True, timeout=60, check=False, cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert result.stderr.strip() == "", result.stderr
