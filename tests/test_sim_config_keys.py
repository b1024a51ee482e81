"""Every key of the virtual lab's ``sim:`` section changes the lab (no key that
nothing reads).

Each leaf key has a changed value below; the test requires the table to cover every
key (a new key without an entry fails) and each change to reach the lab's parameters
(:meth:`sim_device.params.LabParams.from_config`) or, for the three keys the real-time
runner reads itself, what it does with them.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
from pydantic import BaseModel

from groundstation.config import apply_overrides, validate_config
from sim_device.config import SimConfig
from sim_device.params import LabParams
from sim_device.realtime import default_truth_path

CHANGES: dict[str, Any] = {
    "seed": 7,
    "dt_s": 0.001,
    "rate_loop_tau_s": 0.05,
    "command_delay_s": 0.03,
    "k_rate_scale": [1.2, 1.0, 1.0],
    "mass_scale": 1.1,
    "motor_tau_s": 0.03,
    "battery_droop": 0.1,
    "battery_droop_time_s": 100.0,
    "thrust_scale": 0.9,
    "gyro_bias": [0.0, 0.0, 0.0],
    "acc_bias": [0.0, 0.0, 0.0],
    "scale_error": 0.05,
    "initial_position": [0.5, 0.0, 0.0],
    "initial_yaw_deg": 90.0,
    "pilot_thrust": 100,
    "pilot_rate_sticks": [0, 10, 0],
    "serial_enable": False,
    "pilot_holds_thrust": False,
    "rc_link": False,
    "battery_mv": 11000,
    "faults.corruption_rate": 0.01,
    "faults.drop_rate": 0.01,
    "faults.stall_at_s": 5.0,
    "faults.stall_duration_s": 1.0,
    "faults.burst_delay_s": 0.1,
    "faults.delay_s": 0.01,
    "faults.thrust_faults": [[12.0, 0.3, 2.0]],
    "vicon.rate_hz": 10.0,
    "vicon.latency_s": 0.01,
    "vicon.noise": False,
    "vicon.angle_noise": False,
    "vicon.loss_encoding": "zero",
    "vicon.outages": [[1.0, 2.0]],
    "vicon.tilt_limit_deg": 45.0,
    "vicon.pad_to": 512,
    "vicon.volume_x": [-1.0, 1.0],
    "vicon.volume_y": [-1.0, 1.0],
    "vicon.volume_z": [-1.0, 0.05],
    "payload_steps": [[20.0, 1.2]],
    "wind": {},
    "wind.velocity_m_s": [3.0, 0.0, 0.0],
    "wind.gusts": [[20.0, 1.0, 4.0, 0.0, 0.0]],
    "wind.rotor_drag_n_s_m": 0.3,
    "wind.body_drag_n_s2_m2": [0.01, 0.01, 0.02],
    "ground_effect": {},
    "ground_effect.rotor_radius_m": 0.12,
    "ground_effect.rotor_height_m": 0.1,
}

OPTIONAL_SECTIONS = ("wind", "ground_effect")
"""Sections that are null by default (the thesis's model): the section itself is a key
(null against the defaults), and each of its keys is changed against the section given
with its defaults."""

READ_BY_THE_RUNNER = {
    "fifo_priority": "run_sim_device: the real-time loop's SCHED_FIFO priority",
    "truth_file": "default_truth_path: where the truth is written",
    "vicon.target_address": "run_sim_device: where the Vicon datagrams are sent",
}


def _section(kind: object) -> type[BaseModel] | None:
    """The model of a section field (``Model`` or ``Model | None``), else None."""
    for k in (kind, *getattr(kind, "__args__", ())):
        if isinstance(k, type) and issubclass(k, BaseModel):
            return k
    return None


def _leaves(model: type[BaseModel], prefix: str = "") -> list[str]:
    out = []
    for name, field in model.model_fields.items():
        section = _section(field.annotation)
        if section is None:
            out.append(prefix + name)
            continue
        if field.default is None:  # an optional section is a key of its own
            out.append(prefix + name)
        out += _leaves(section, f"{prefix}{name}.")
    return out


BASE = validate_config({"sim": {}})


def test_the_table_covers_every_key() -> None:
    assert sorted(_leaves(SimConfig)) == sorted([*CHANGES, *READ_BY_THE_RUNNER])


@pytest.mark.parametrize("key", sorted(CHANGES))
def test_every_key_changes_the_lab(key: str) -> None:
    section = key.split(".")[0]
    base = (apply_overrides(BASE, {f"sim.{section}": {}})
            if section in OPTIONAL_SECTIONS and key != section else BASE)
    changed = apply_overrides(base, {f"sim.{key}": CHANGES[key]})
    assert LabParams.from_config(changed) != LabParams.from_config(base), key


def test_the_truth_file_key_names_the_truth_file(tmp_path: Path) -> None:
    changed = apply_overrides(BASE, {"sim.truth_file": str(tmp_path / "t.npz")})
    assert default_truth_path(changed) == tmp_path / "t.npz"
    assert default_truth_path(BASE) != tmp_path / "t.npz"


def test_the_runner_reads_its_keys() -> None:
    """fifo_priority and the Vicon target act only in a real-time run: the runner's
    source must read them (a weak check; they are exercised by bench_flight and the
    real-time tests)."""
    import inspect

    from sim_device import realtime

    source = inspect.getsource(realtime.run_sim_device)
    assert "sim.fifo_priority" in source
    assert "sim.vicon.target_address" in source
