"""The virtual lab's configuration: the ``sim:`` section of a configuration file.

The ground station does not know this section: it hands it to the lab that
registered itself (:mod:`groundstation.lab`), which validates it with
:class:`SimConfig` under the same rules as every other section (unknown keys,
strict numbers, finite values; :class:`groundstation.config.ConfigModel`), and
errors name the field as ``sim.faults.drop_rate``. :func:`sim_section` gives the
lab's code the validated section of a loaded configuration.
"""

from __future__ import annotations

from pathlib import Path
from typing import Literal

from pydantic import Field

from groundstation.config import (
    ConfigModel,
    GroundStationConfig,
    NonNegFloat,
    PositiveFloat,
    Vec3,
)


class SimFaultsConfig(ConfigModel):
    """Fault injection in the virtual X-3D link, all off by default."""

    corruption_rate: float = Field(0.0, ge=0.0, le=1.0)  # probability per byte of a bit flip
    drop_rate: float = Field(0.0, ge=0.0, le=1.0)  # probability per DATA frame of dropping it
    stall_at_s: NonNegFloat | None = None  # DATA stream stalls at this simulated time
    stall_duration_s: NonNegFloat = 0.0
    burst_delay_s: NonNegFloat = 0.0  # hold DATA and deliver it in bursts of this length
    delay_s: NonNegFloat = 0.0  # constant extra delivery delay of every DATA frame
    thrust_faults: list[tuple[NonNegFloat, NonNegFloat, NonNegFloat]] = Field(
        default_factory=list)
    # (start_s, duration_s, lift_scale): the rotors give lift_scale x their lift meanwhile


class SimViconConfig(ConfigModel):
    """The virtual Vicon sender."""

    target_address: str = "127.0.0.1"  # loopback: never send outside this machine
    rate_hz: PositiveFloat = 100.0  # thesis lab 100 Hz; Ch. 11.1 also flew 10 and 1 Hz
    latency_s: NonNegFloat = 0.005  # matches vicon.latency_s default
    noise: bool = True  # Table 6.1 variances from the vehicle section
    angle_noise: bool = True
    # false: exact angles, noise on the position only, as a simulator's Vicon sender (a
    # level vehicle at heading 0 reports rotation exactly (0, 0, 0))
    loss_encoding: Literal["missing", "zero", "held-identity"] = "held-identity"
    # spec "lost tracking" encodings; held-identity is the thesis lab's (Alg. 2)
    outages: list[tuple[float, float]] = Field(default_factory=list)  # (start_s, duration_s)
    tilt_limit_deg: PositiveFloat = 60.0  # tracking lost beyond this tilt; markers occluded
    pad_to: int | None = Field(1024, ge=80)  # Tracker's data block size (spec)
    volume_x: tuple[float, float] = (-1.5, 1.5)  # tracked volume, Table B.1 [m]
    volume_y: tuple[float, float] = (-1.5, 1.5)  # Table B.1
    volume_z: tuple[float, float] = (-2.0, 0.05)  # Table B.1: 0..2 m height, NED


class SimConfig(ConfigModel):
    """The virtual lab's ``sim:`` section: plant, sensors, link and Vicon."""

    seed: int = 1
    dt_s: float = Field(0.002, gt=0, le=0.01)  # 2 ms fixed step, issue 5 (rate loop, motors)
    fifo_priority: int | None = Field(None, ge=1, le=98)
    # SCHED_FIFO priority of the real-time virtual lab (null: the normal policy). 20
    # makes it stand for hardware that the PC's load never stalls (benchmarks/
    # bench_flight.py), but it costs the daemon on the same cores: in a demo flight
    # without the PM QoS request the daemon's DATA->COMMAND p99 rose from 2 to 13 ms
    # Where the simulated vehicle differs from the vehicle model (all off by default:
    # the virtual lab is then the design model; `gs eval --perturb` draws them)
    rate_loop_tau_s: NonNegFloat | None = None
    # true rate-loop time constant; null = vehicle.rate_loop_tau_s; 0 = an ideal rate loop
    command_delay_s: NonNegFloat | None = None  # true transport delay; null = the vehicle's
    k_rate_scale: Vec3 = Field(default_factory=lambda: [1.0, 1.0, 1.0])
    # true rate gains / vehicle.k_rate, per axis (1.3 = a 30 % stronger rate response)
    mass_scale: PositiveFloat = 1.0  # true mass / vehicle.mass_kg
    motor_tau_s: NonNegFloat = 0.02
    # lift lag of motors and rotors; the thesis gives none, 20 ms is typical of the class
    battery_droop: float = Field(0.03, ge=0.0, lt=0.5)
    # lift loss fraction over battery_droop_time_s (Ch. 5.2 observed a growing offset)
    battery_droop_time_s: PositiveFloat = 300.0
    thrust_scale: PositiveFloat = 1.0  # true lift / polynomial lift; 0.9 = 10 % thrust error
    gyro_bias: Vec3 = Field(default_factory=lambda: [0.01, -0.02, 0.005])  # rad/s, plausible
    acc_bias: Vec3 = Field(default_factory=lambda: [0.05, -0.05, 0.1])  # m/s^2, plausible
    scale_error: NonNegFloat = 0.02  # max per-axis IMU scale error fraction ("a few %")
    initial_position: Vec3 = Field(default_factory=lambda: [0.0, 0.0, 0.0])  # on the floor
    initial_yaw_deg: float = 0.0
    pilot_thrust: int = Field(0, ge=0, le=4096)
    # scripted pilot's thrust stick when it has the vehicle (0 = motors idle on the ground)
    serial_enable: bool = True  # the RC serial-enable switch
    pilot_holds_thrust: bool = True
    # a pilot handed the vehicle in the air holds the thrust applied at that moment
    rc_link: bool = True
    battery_mv: int = Field(11800, ge=0)  # reported in STATUS (3S LiPo, spec worked frame)
    truth_file: Path | None = None  # ground truth written here on exit
    faults: SimFaultsConfig = SimFaultsConfig()
    vicon: SimViconConfig = SimViconConfig()


def sim_section(config: GroundStationConfig) -> SimConfig:
    """The configuration's validated ``sim:`` section; the defaults if it has none."""
    section = config.sim
    if section is None:
        return SimConfig()
    if not isinstance(section, SimConfig):  # validate_config put it there, validated
        raise TypeError(f"sim section of type {type(section).__name__}, not SimConfig")
    return section
