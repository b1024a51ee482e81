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

LAZY_PACKAGES = ("groundstation.model", "groundstation.control", "groundstation.estimation",
                 "groundstation.flight", "groundstation.app", "sim_device")


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


@pytest.mark.parametrize("light", ["groundstation.cli", "groundstation.client.fleet",
                                   "groundstation.export", "groundstation.app.recorder"])
def test_the_start_up_and_the_log_readers_load_no_flight_controller_or_scipy(light: str
                                                                           ) -> None:
    # a fresh interpreter, as `gs status`, `gs fleet status` or `gs export` starts: what a
    # flight needs is loaded when a command flies, not by the start-up or by reading a log
    heavy = ["scipy", "groundstation.control.lqr_design", "groundstation.estimation.ekf",
             "groundstation.flight.assembly", "groundstation.app.daemon", "sim_device.lab",
             "sim_device.realtime", "matplotlib"]
    code = (f"import json, sys; import groundstation.cli, {light}; "
            f"print(json.dumps([m for m in {heavy!r} if m in sys.modules]))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=60, check=True)
    assert json.loads(out.stdout) == []
