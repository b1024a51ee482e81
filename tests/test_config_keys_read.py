"""Every key of the ground station's configuration is read (no key that nothing
reads; `estimator.ignore_variance`, `safety.gravity_check_deg` and
`safety.takeoff_height_m` were validated, documented and never read).

Reads of configuration fields are recorded (``ConfigModel.__getattribute__`` wrapped) while
the ground station does what a configuration drives: the flight core for every controller
type, a short real-time flight of the daemon against the virtual lab over a pty and UDP
(serial link, Vicon, telemetry, flight log, real-time settings), ``gs synth hinf`` (the
H-infinity design keys), the request socket with CURVE keys, the virtual lab's parameters
(the vehicle it simulates), and in the AscTec LL dialect the flight core, the lab and
``gs motors start`` over its link (the ``serial.ll`` keys). The
configurations are built before recording starts, so a key that only a validator looks at
counts as unread. The ``sim:`` section has its own test (``test_sim_config_keys.py``), which
also shows each of its keys changing the lab.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import pytest
import zmq.auth
from lab_helpers import realtime_sim_config
from pydantic import BaseModel
from typer.testing import CliRunner

from groundstation.app.api import MotionApi
from groundstation.app.daemon import FlightDaemon
from groundstation.app.motors import motor_gesture_command
from groundstation.cli import app
from groundstation.config import (
    ConfigModel,
    GroundStationConfig,
    apply_overrides,
    dump_config,
)
from groundstation.endpoints import free_udp_port
from groundstation.flight.assembly import assemble
from groundstation.flight.core import FlightCore
from groundstation.telemetry.requests import RequestServer
from sim_device.params import LabParams
from sim_device.realtime import SimDeviceProcess

ROOT = Path(__file__).resolve().parents[1]

Read = tuple[type, str]


def leaves(model: type[BaseModel], prefix: str = "") -> dict[str, Read]:
    """Every leaf key of ``model`` as ``dotted.path -> (owning model, field name)``."""
    out: dict[str, Read] = {}
    for name, field in model.model_fields.items():
        kind = field.annotation
        if isinstance(kind, type) and issubclass(kind, BaseModel):
            out.update(leaves(kind, f"{prefix}{name}."))
        else:
            out[prefix + name] = (model, name)
    return out


@contextmanager
def recording(reads: set[Read]) -> Iterator[None]:
    """Record ``(model class, field)`` for every field read on any configuration model."""
    original = ConfigModel.__getattribute__

    def getattribute(self: ConfigModel, name: str) -> Any:
        cls = type(self)
        if name in cls.model_fields:
            reads.add((cls, name))
        return original(self, name)

    ConfigModel.__getattribute__ = getattribute  # type: ignore[method-assign]
    try:
        yield
    finally:
        ConfigModel.__getattribute__ = original  # type: ignore[method-assign]


def unread(reads: set[Read], model: type[BaseModel] = GroundStationConfig) -> list[str]:
    return [path for path, key in leaves(model).items() if key not in reads]


def test_the_recorder_finds_an_unread_key() -> None:
    """The check can fail: a field nobody reads is reported, one that is read is not."""

    class Section(ConfigModel):
        used: int = 1
        forgotten: int = 2

    class Top(ConfigModel):
        section: Section = Section()

    top = Top()
    reads: set[Read] = set()
    with recording(reads):
        assert top.section.used == 1
    assert unread(reads, Top) == ["section.forgotten"]


def _fly_briefly(cfg: GroundStationConfig, tmp_path: Path) -> int:
    """One 1 s hover of the daemon against the virtual lab in its own process."""
    cfg_file = tmp_path / "lab.yaml"
    cfg_file.write_text(dump_config(cfg), encoding="utf-8")
    with SimDeviceProcess(cfg_file, tmp_path / "truth.npz") as device:
        flying = apply_overrides(cfg, {"serial.port": device.pty_path})
        out: dict[str, int] = {}
        runner = threading.Thread(
            target=lambda: out.setdefault("exit", int(FlightDaemon(assemble(flying), duration_s=1.0)
                                                      .run().outcome)))
        runner.start()
        runner.join(90.0)
    assert not runner.is_alive()
    return out["exit"]


def _motors(cfg: GroundStationConfig, tmp_path: Path) -> int:
    """`gs motors start` against the virtual AscTec LL vehicle (reads the link's and the
    gesture's keys)."""
    cfg_file = tmp_path / "ll.yaml"
    cfg_file.write_text(dump_config(cfg), encoding="utf-8")
    with SimDeviceProcess(cfg_file, tmp_path / "ll-truth.npz") as device:
        flying = apply_overrides(cfg, {"serial.port": device.pty_path})
        return motor_gesture_command(assemble(flying).link, start=True,
                                     echo=lambda _line: None)


def _api(cfg: GroundStationConfig) -> MotionApi:
    """The run-time API of a commanded flight (reads the ``api`` keys)."""
    core = FlightCore(assemble(cfg))
    return MotionApi(core, core.params)


@pytest.mark.realtime
@pytest.mark.slow
def test_every_configuration_key_is_read(tmp_path: Path) -> None:
    base = apply_overrides(realtime_sim_config(), {
        "trajectory.name": "hover", "vicon.port": free_udp_port(),
        "telemetry.endpoint": "tcp://127.0.0.1:*",
        "telemetry.control_endpoint": "tcp://127.0.0.1:*",
        "logging.flight_log_dir": str(tmp_path / "logs"),
        "sim.truth_file": str(tmp_path / "truth.npz"),
    })
    kinds = {kind: apply_overrides(base, {"controller.type": kind})
             for kind in ("lqr-ff", "lqr-cv", "lqr-cp", "pid", "hinf")}
    keys = tmp_path / "keys"
    (keys / "clients").mkdir(parents=True)
    _, server_secret = zmq.auth.create_certificates(str(keys), "server")
    zmq.auth.create_certificates(str(keys / "clients"), "client")
    curve = apply_overrides(base, {"telemetry.control_server_key": server_secret,
                                   "telemetry.control_client_keys": str(keys / "clients")})
    ll = apply_overrides(base, {"serial.protocol": "asctec-ll"})
    commanded = apply_overrides(base, {"trajectory.name": "none"})
    hinf_file = tmp_path / "hinf.yaml"
    hinf_file.write_text(dump_config(base), encoding="utf-8")
    steps: dict[str, Callable[[], object]] = {
        **{f"flight core ({kind})": (lambda c=cfg: FlightCore(assemble(c)))
           for kind, cfg in kinds.items()},
        "virtual lab parameters": lambda: LabParams.from_config(base),
        "gs synth hinf": lambda: CliRunner().invoke(
            app, ["synth", "hinf", "--config", str(hinf_file), "--out",
                  str(tmp_path / "g.npz")]),
        "request socket with CURVE": lambda: RequestServer.from_params(
            assemble(curve).requests).close(),
        "real-time flight": lambda: _fly_briefly(base, tmp_path),
        "flight core (asctec-ll)": lambda: FlightCore(assemble(ll)),
        "virtual lab parameters (asctec-ll)": lambda: LabParams.from_config(ll),
        "gs motors start (asctec-ll)": lambda: _motors(ll, tmp_path),
        "run-time API (trajectory none)": lambda: _api(commanded),
    }
    reads: set[Read] = set()
    results = {}
    with recording(reads):
        for name, step in steps.items():
            results[name] = step()
    assert results["real-time flight"] == 0  # a completed mission, so every stage ran
    assert results["gs motors start (asctec-ll)"] == 0  # the gesture ran to its end
    assert results["gs synth hinf"].exit_code == 0  # type: ignore[attr-defined]
    assert unread(reads) == []
