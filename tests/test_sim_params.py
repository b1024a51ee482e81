"""LabParams.from_config maps the configuration onto the virtual lab; bad values are refused.

Expected values are the ones written into the overrides below (and sim.yaml's own).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path

import pytest

from groundstation.config import apply_overrides, load_config
from groundstation.errors import ConfigError
from sim_device import (
    FaultParams,
    ImuParams,
    LabParams,
    PlantParams,
    ViconSimParams,
    VirtualLab,
)


def test_from_config_maps_every_section(repo: Path) -> None:
    config = apply_overrides(load_config(repo / "config" / "sim.yaml"), {
        "serial.baud": 38400, "sim.thrust_scale": 0.9, "sim.seed": 11,
        "sim.initial_yaw_deg": 90.0, "sim.faults.drop_rate": 0.1,
        "sim.faults.stall_at_s": 3.0, "sim.faults.stall_duration_s": 0.5,
        "sim.vicon.rate_hz": 10.0, "sim.vicon.loss_encoding": "zero",
        "sim.vicon.outages": [[1.0, 2.0]], "vicon.object_name": "quad",
        "vehicle.mass_kg": 0.55, "sim.pilot_thrust": 1200,
    })
    p = LabParams.from_config(config)
    assert (p.seed, p.dt, p.link.baud) == (11, 0.002, 38400)
    assert (p.plant.thrust_scale, p.plant.mass) == (0.9, 0.55)
    assert p.plant.initial_yaw == pytest.approx(math.pi / 2)
    assert p.plant.rate_tau == 0.064 and p.link.command_delay == 0.02  # sim.yaml
    assert (p.faults.drop_rate, p.faults.stall_at, p.faults.stall_duration) == (0.1, 3.0, 0.5)
    assert (p.vicon.rate_hz, p.vicon.loss_encoding, p.vicon.outages) == (10.0, "zero",
                                                                         ((1.0, 2.0),))
    assert p.vicon.object_name == "quad" and p.pilot.thrust == 1200
    assert p.imu.acc_scale == (0.0086, 0.0077, 0.0111)  # Table 6.2 via vehicle
    lab = VirtualLab(config)
    assert lab.seed == 11 and lab.firmware.stalls == [(3_000_000_000, 3_500_000_000)]


@pytest.mark.parametrize(
    "build",
    [
        lambda: PlantParams(mass=-1.0),
        lambda: PlantParams(initial_position=(0.0, 0.0, 0.5)),  # below the floor
        lambda: ImuParams(acc_scale=(0.0, 0.0077, 0.0111)),
        lambda: FaultParams(drop_rate=1.5),
        lambda: ViconSimParams(volume_x=(1.0, -1.0)),
        lambda: ViconSimParams(loss_encoding="vanish"),  # type: ignore[arg-type]  # bad on purpose
        lambda: LabParams(dt=0.05),
    ],
)
def test_bad_parameters_raise_config_error(build: Callable[[], object]) -> None:
    with pytest.raises(ConfigError):
        build()
