"""The packages' re-exports that load on first use (groundstation/lazy.py): every exported
name is the object its module defines, and a `gs` start-up loads only what its command
uses."""

from __future__ import annotations

import importlib
import json
import subprocess
import sys

import pytest

from groundstation.lazy import _homes

LAZY_PACKAGES = ("groundstation.model", "groundstation.control", "sim_device")


@pytest.mark.parametrize("package", LAZY_PACKAGES)
def test_every_exported_name_is_its_modules_object(package: str) -> None:
    module = importlib.import_module(package)
    assert module.__file__ is not None
    with open(module.__file__, encoding="utf-8") as handle:
        homes = _homes(handle.read())
    assert homes, "no names under `if TYPE_CHECKING:`"
    assert set(homes) <= set(module.__all__)
    for name in module.__all__:
        value = getattr(module, name)
        if name in homes:
            where, there = homes[name]
            assert value is getattr(importlib.import_module(where), there), name
    with pytest.raises(AttributeError, match="no attribute 'not_a_name'"):
        module.not_a_name  # noqa: B018


def test_the_command_line_starts_without_the_flight_the_controllers_or_scipy() -> None:
    # a fresh interpreter, as `gs status` or `gs --help` starts: the modules its commands
    # import when they run are not loaded by the start-up
    heavy = ["scipy", "groundstation.control.lqr_design", "groundstation.estimation.ekf",
             "groundstation.flight.assembly", "groundstation.app.daemon", "sim_device.lab",
             "sim_device.realtime", "matplotlib"]
    code = ("import json, sys; import groundstation.cli; "
            f"print(json.dumps([m for m in {heavy!r} if m in sys.modules]))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=60, check=True)
    assert json.loads(out.stdout) == []
