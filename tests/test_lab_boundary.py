"""The ground station does not depend on its virtual lab.

Dependencies run one way: ``sim_device`` imports ``groundstation``, never the reverse.
The ground station finds the lab through the ``groundstation.labs`` entry point
(:mod:`groundstation.lab`) and talks to it through protocols; a lab process announces
itself as a JSON line. Checked here statically (no import statement anywhere in
``groundstation/`` names ``sim_device``) and dynamically (every module imports, and
``gs`` runs, with ``sim_device`` made unimportable).
"""

from __future__ import annotations

import ast
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from groundstation.config import load_config, validate_config
from groundstation.errors import ConfigError
from groundstation.flight.assembly import check_config
from groundstation.lab import ENTRY_POINT_GROUP, Announcement, installed_labs, virtual_lab

ROOT = Path(__file__).resolve().parents[1]


def _imported_modules(path: Path) -> set[str]:
    tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
    names: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module is not None and node.level == 0:
            names.add(node.module)
    return names


@pytest.mark.slow
def test_no_groundstation_module_imports_the_lab() -> None:
    offenders = [f"{path.relative_to(ROOT)}: {name}"
                 for path in sorted((ROOT / "groundstation").rglob("*.py"))
                 for name in _imported_modules(path)
                 if name == "sim_device" or name.startswith("sim_device.")]
    assert offenders == []


def test_the_scan_sees_an_import_of_the_lab(tmp_path: Path) -> None:
    """The check above can fail: it finds both import forms, also inside a function."""
    source = tmp_path / "m.py"
    source.write_text("def f():\n    from sim_device.lab import VirtualLab\nimport sim_device\n")
    assert _imported_modules(source) == {"sim_device.lab", "sim_device"}


_WITHOUT_LAB = r"""
import importlib, pkgutil, sys
sys.modules["sim_device"] = None  # import sim_device -> ImportError, as in the flight image
import groundstation
failed = []
for info in pkgutil.walk_packages(groundstation.__path__, "groundstation."):
    if info.name.endswith(".__main__"):
        continue  # `python -m groundstation` runs the CLI on import
    try:
        importlib.import_module(info.name)
    except ImportError as exc:
        failed.append(f"{info.name}: {exc}")
print("\n".join(failed) if failed else "ok")
"""


@pytest.mark.slow
def test_every_module_imports_without_the_lab() -> None:
    out = subprocess.run([sys.executable, "-c", _WITHOUT_LAB], capture_output=True, text=True,
                         timeout=120, cwd=ROOT)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "ok"


def _gs_without_lab(*args: str) -> subprocess.CompletedProcess[str]:
    code = ("import sys; sys.modules['sim_device'] = None; "
            "from groundstation.cli import main; sys.argv[0] = 'gs'; main()")
    return subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True,
                          timeout=120, cwd=ROOT, env={**os.environ, "COLUMNS": "120"})


@pytest.mark.slow
def test_gs_without_the_lab_flies_but_has_no_lab_commands() -> None:
    helped = _gs_without_lab("--help")
    assert helped.returncode == 0, helped.stderr
    assert "fly" in helped.stdout and "check-config" in helped.stdout
    assert "sim-device" not in helped.stdout and " eval " not in helped.stdout
    checked = _gs_without_lab("check-config", str(ROOT / "config" / "lab.yaml"))
    assert checked.returncode == 0, checked.stderr


@pytest.mark.slow
def test_a_sim_section_without_the_lab_is_a_config_error() -> None:
    out = _gs_without_lab("check-config", str(ROOT / "config" / "sim.yaml"))
    assert out.returncode == 2
    assert "sim:" in out.stderr + out.stdout
    assert "Traceback" not in out.stderr


def test_the_bundled_lab_is_registered() -> None:
    assert "virtual" in installed_labs()
    plugin = virtual_lab()
    names = [name for name, _ in plugin.commands()]
    assert names == ["sim-device", "eval"]
    assert ENTRY_POINT_GROUP == "groundstation.labs"


def test_the_lab_validates_its_section_with_field_paths() -> None:
    """The configuration layer keeps the lab's section as given; where the configuration is
    assembled, the lab validates it and its problems name their keys under ``sim``."""
    base = {"sim": {"seed": 3, "faults": {"drop_rate": 2.0}, "vicon": {"bogus": 1}}}
    with pytest.raises(ConfigError) as err:
        check_config(validate_config(base, "t.yaml"), "t.yaml")
    paths = {path for path, _, _ in err.value.problems}
    assert paths == {"sim.faults.drop_rate", "sim.vicon.bogus"}
    config = check_config(validate_config({"sim": {"seed": 3}}))
    assert type(config.sim).__name__ == "SimConfig"
    assert config.sim.model_dump()["seed"] == 3


def test_announcement_round_trip_and_refusal() -> None:
    a = Announcement("/dev/pts/7", ("127.0.0.1", 51001), Path("/tmp/t.npz"))
    line = a.to_json()
    assert json.loads(line) == {"serial_port": "/dev/pts/7",
                                "vicon_target": ["127.0.0.1", 51001],
                                "truth_file": "/tmp/t.npz"}
    assert Announcement.from_json(line + "\n") == a
    for bad in ("virtual X-3D on /dev/pts/7 (57600 baud)", "{}", '{"serial_port": 1}', ""):
        with pytest.raises(ValueError, match="not a lab announcement"):
            Announcement.from_json(bad)


@pytest.mark.virtual_vehicle
def test_sim_device_announces_itself_as_json(tmp_path: Path) -> None:
    """``gs sim-device --json`` prints the announcement first; the pty it names opens."""
    import serial

    config = tmp_path / "sim.yaml"
    config.write_text((ROOT / "config" / "sim.yaml").read_text(encoding="utf-8"))
    truth = tmp_path / "truth.npz"
    child = subprocess.Popen(
        [sys.executable, "-c", "from groundstation.cli import main; main()", "sim-device",
         "--json", "--config", str(config), "--truth-file", str(truth), "--duration", "2"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT)
    try:
        assert child.stdout is not None
        announced = Announcement.from_json(child.stdout.readline())
        assert announced.truth_file == truth
        assert announced.vicon_target[1] == load_config(config).vicon.port
        with serial.Serial(announced.serial_port, 57600, timeout=0.5):
            pass
        rest = child.stdout.read()  # to the end: the lab stops after --duration
        child.wait(timeout=60)
        assert child.stderr is not None
        err = child.stderr.read()
    finally:
        if child.poll() is None:
            child.kill()
            child.communicate()
    assert child.returncode == 0, err
    assert "virtual X-3D on" in rest  # the human-readable lines follow
    assert truth.exists()
