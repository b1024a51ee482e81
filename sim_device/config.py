"""The virtual lab's configuration: the ``sim:`` section of a configuration file.

The ground station does not know this section: it hands it to the lab that
registered itself (:mod:`groundstation.lab`), which validates it with
:class:`SimConfig` under the same rules as every other section (unknown keys,
strict numbers, finite values; :class:`groundstation.config.ConfigModel`), and
errors name the field as ``sim.faults.drop_rate``. :func:`sim_section` gives the
lab's code the validated section of a loaded configuration.
"""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import AfterValidator, Field, ValidationError

from groundstation.config import (
    DAY_S,
    VICON_RATE_MAX_HZ,
    CommandDelay,
    ConfigModel,
    FifoPriority,
    FilePath,
    GroundStationConfig,
    HostAddress,
    LabCoordinate,
    TurnDeg,
    raise_problems,
    validation_problems,
    within,
)

Probability = Annotated[float, within(0.0, 1.0, "a probability")]
SimTime = Annotated[float, within(0.0, DAY_S, "s: a simulated flight lasts less than a day")]
DeliveryDelay = Annotated[float, within(
    0.0, 60.0, "s: a frame a minute late is a lost link 30 times over (safety.link_loss_s "
    "<= 2 s)")]
TrueOverModel = Annotated[float, within(
    0.1, 10.0, "true / model: a factor of 10 either way is another vehicle, not a model "
    "error")]


def _ordered(value: tuple[float, float]) -> tuple[float, float]:
    if not value[0] < value[1]:
        raise ValueError("volume bounds must be (min, max) with min < max")
    return value


LiftScale = Annotated[float, within(
    0.0, 10.0, "true / model lift: 0 is a total loss, ten times is another vehicle")]
LabBounds = Annotated[tuple[LabCoordinate, LabCoordinate], AfterValidator(_ordered)]
"""A volume's (min, max) along one axis, NED [m]."""


class SimFaultsConfig(ConfigModel):
    """Fault injection in the virtual X-3D link, all off by default."""

    corruption_rate: Probability = 0.0  # probability per byte of a bit flip
    drop_rate: Probability = 0.0  # probability per DATA frame of dropping it
    stall_at_s: SimTime | None = None  # DATA stream stalls at this simulated time
    stall_duration_s: SimTime = 0.0
    burst_delay_s: DeliveryDelay = 0.0  # hold DATA and deliver it in bursts of this length
    delay_s: DeliveryDelay = 0.0  # constant extra delivery delay of every DATA frame
    thrust_faults: list[tuple[SimTime, SimTime, LiftScale]] = Field(default_factory=list)
    # (start_s, duration_s, lift_scale): the rotors give lift_scale x their lift meanwhile


class SimViconConfig(ConfigModel):
    """The virtual Vicon sender."""

    target_address: HostAddress = "127.0.0.1"  # loopback: never send outside this machine
    rate_hz: Annotated[float, within(
        0.0, VICON_RATE_MAX_HZ, "Hz: Vicon cameras stream at most ~2000 Hz",
        lo_open=True)] = 100.0  # thesis lab 100 Hz; Ch. 11.1 also flew 10 and 1 Hz
    latency_s: Annotated[float, within(
        0.0, 0.5, "s: spec: Tracker and the network add a few ms")] = 0.005
    # matches vicon.latency_s default
    noise: bool = True  # Table 6.1 variances from the vehicle section
    angle_noise: bool = True
    # false: exact angles, noise on the position only, as a simulator's Vicon sender (a
    # level vehicle at heading 0 reports rotation exactly (0, 0, 0))
    loss_encoding: Literal["missing", "zero", "held-identity"] = "held-identity"
    # spec "lost tracking" encodings; held-identity is the thesis lab's (Alg. 2)
    outages: list[tuple[SimTime, SimTime]] = Field(default_factory=list)
    # (start_s, duration_s)
    tilt_limit_deg: Annotated[float, within(0.0, 180.0, "deg: a tilt is at most 180",
                                            lo_open=True)] = 60.0
    # tracking lost beyond this tilt; markers occluded
    pad_to: Annotated[int, within(
        80, 65507, "bytes: from one object item with the header (spec) to the largest "
        "UDP/IPv4 payload")] | None = 1024  # Tracker's data block size (spec)
    volume_x: LabBounds = (-1.5, 1.5)  # tracked volume, Table B.1 [m]
    volume_y: LabBounds = (-1.5, 1.5)  # Table B.1
    volume_z: LabBounds = (-2.0, 0.05)  # Table B.1: 0..2 m height, NED


WindSpeed = Annotated[float, within(
    -20.0, 20.0, "m/s: 20 m/s is a gale; no motion-capture lab flies in one")]
GustTime = Annotated[float, within(
    0.0, 60.0, "s: a gust longer than a minute is a wind, not a gust", lo_open=True)]
MassFactor = Annotated[float, within(
    0.2, 5.0, "true mass after / before: five times is another vehicle, not a payload")]


class SimWindConfig(ConfigModel):
    """Air that moves, and the drag the vehicle feels on its airspeed (its velocity less the
    wind's). RotorPy's aerodynamics (``rotorpy/vehicles/multirotor.py``: rotor drag linear
    in the airspeed and in the rotor speed, parasitic drag quadratic) with the thesis's
    induced inflow (eq. 3.9) as the rotors' drag along body z."""

    velocity_m_s: list[WindSpeed] = Field(default_factory=lambda: [0.0, 0.0, 0.0],
                                          min_length=3, max_length=3)
    # steady wind, NED [m/s] (3 m/s north: [3, 0, 0])
    gusts: list[tuple[SimTime, GustTime, WindSpeed, WindSpeed, WindSpeed]] = Field(
        default_factory=list)
    # (start_s, duration_s, north, east, down [m/s]): a 1-cosine gust on top of the steady
    # wind, peaking at (north, east, down) halfway (the discrete gust of MIL-HDBK-1797)
    rotor_drag_n_s_m: Annotated[float, within(
        0.0, 10.0, "N s/m: ten times the eq. C.8 inflow would stop the vehicle in the air")] \
        = 0.217
    # in-plane rotor drag at the hover rotor speed [N s/m]: RotorPy's AscTec Hummingbird
    # ratio k_d / k_z = 1.19e-4 / 2.32e-4 times the thesis's induced inflow 0.423 (eq. C.8);
    # it scales with the rotor speed, sqrt(lift / weight)
    body_drag_n_s2_m2: list[Annotated[float, within(
        0.0, 1.0, "N s^2/m^2: 1 is a 1.6 m^2 flat plate, a sail, not a frame")]] = Field(
        default_factory=lambda: [0.005, 0.005, 0.01], min_length=3, max_length=3)
    # parasitic drag of the frame along body x, y, z [N s^2/m^2] (RotorPy's Hummingbird
    # c_Dx, c_Dy, c_Dz)


class SimGroundEffectConfig(ConfigModel):
    """More lift near the floor (Cheeseman and Bennett 1955: T / T_inf = 1 / (1 - (R / 4h)^2)
    for a rotor of radius R at height h, held at its value for h = R / 2 below that)."""

    rotor_radius_m: Annotated[float, within(
        0.0, 1.0, "m: a rotor over a metre is no miniature quadrotor's", lo_open=True)] = 0.10
    # the X-3D class's 8-inch rotors (RotorPy's Hummingbird: rotor_radius 0.10 m)
    rotor_height_m: Annotated[float, within(
        0.0, 1.0, "m: the rotor plane's height above the floor when standing")] = 0.08
    # rotor plane above the floor when the vehicle stands (skids and arms), estimated


class SimConfig(ConfigModel):
    """The virtual lab's ``sim:`` section: plant, sensors, link and Vicon."""

    seed: Annotated[int, within(0, None, "numpy's generators take no negative seed")] = 1
    dt_s: Annotated[float, within(
        0.0, 0.01, "s: the plant's fixed step; coarser than the 10 ms IMU period cannot "
        "resolve the rate loop and the motors", lo_open=True)] = 0.002
    # 2 ms fixed step: resolves the rate loop (64 ms) and the motors (20 ms)
    fifo_priority: FifoPriority | None = None
    # SCHED_FIFO priority of the real-time virtual lab (null: the normal policy). 20
    # makes it stand for hardware that the PC's load never stalls (benchmarks/
    # bench_flight.py), but it costs the daemon on the same cores: in a demo flight
    # without the PM QoS request the daemon's DATA->COMMAND p99 rose from 2 to 13 ms
    # Where the simulated vehicle differs from the vehicle model (all off by default:
    # the virtual lab is then the design model; `gs eval --perturb` draws them)
    rate_loop_tau_s: Annotated[float, within(
        0.0, 1.0, "s: 0 is an ideal rate loop; one slower than a second could not hold a "
        "hover")] | None = None
    # true rate-loop time constant; null = vehicle.rate_loop_tau_s; 0 = an ideal rate loop
    command_delay_s: CommandDelay | None = None  # true transport delay; null = the vehicle's
    k_rate_scale: list[TrueOverModel] = Field(default_factory=lambda: [1.0, 1.0, 1.0],
                                              min_length=3, max_length=3)
    # true rate gains / vehicle.k_rate, per axis (1.3 = a 30 % stronger rate response)
    mass_scale: TrueOverModel = 1.0  # true mass / vehicle.mass_kg
    motor_tau_s: Annotated[float, within(
        0.0, 1.0, "s: motors slower than a second could not hold a hover")] = 0.02
    # lift lag of motors and rotors; the thesis gives none, 20 ms is typical of the class
    battery_droop: Annotated[float, within(
        0.0, 0.5, "a fraction of the lift: half of it lost is an empty battery",
        hi_open=True)] = 0.03
    # lift loss fraction over battery_droop_time_s (Ch. 5.2 observed a growing offset)
    battery_droop_time_s: Annotated[float, within(
        0.0, DAY_S, "s: a simulated flight lasts less than a day", lo_open=True)] = 300.0
    thrust_scale: TrueOverModel = 1.0  # true lift / polynomial lift; 0.9 = 10 % thrust error
    payload_steps: list[tuple[SimTime, MassFactor]] = Field(default_factory=list)
    # (time_s, factor): from time_s on the true mass is factor x what it was (1.2: a payload
    # of 20 % picked up; 1 / 1.2 drops it)
    wind: SimWindConfig | None = None
    # null: still air and no drag (the thesis's model, eq. 3.19-3.22); a section: the plant
    # feels rotor and body drag on its airspeed, in the wind it describes (still by default)
    ground_effect: SimGroundEffectConfig | None = None
    # null: no ground effect (the thesis's model); a section: more lift near the floor
    gyro_bias: list[Annotated[float, within(
        -1.0, 1.0, "rad/s: a MEMS gyro's zero-rate offset is a few deg/s; 1 rad/s is 57")]] \
        = Field(default_factory=lambda: [0.01, -0.02, 0.005], min_length=3, max_length=3)
    # rad/s, plausible
    acc_bias: list[Annotated[float, within(
        -5.0, 5.0, "m/s^2: a MEMS accelerometer's zero-g offset is at most ~0.1 g; 5 m/s^2 "
        "is half a g")]] \
        = Field(default_factory=lambda: [0.05, -0.05, 0.1], min_length=3, max_length=3)
    # m/s^2, plausible
    scale_error: Annotated[float, within(
        0.0, 0.5, "a fraction: a scale 50 % off is a wrong Table 6.2, not an error")] = 0.02
    # max per-axis IMU scale error fraction ("a few %")
    initial_position: list[LabCoordinate] = Field(default_factory=lambda: [0.0, 0.0, 0.0],
                                                  min_length=3, max_length=3)  # on the floor
    initial_yaw_deg: TurnDeg = 0.0
    pilot_thrust: Annotated[int, within(0, 4096, "stick units: the thrust stick's range")] = 0
    # scripted pilot's thrust stick when it has the vehicle (0 = motors idle on the ground)
    pilot_rate_sticks: list[Annotated[int, within(-2048, 2047, "stick units: a rate stick's "
                                                  "range")]] = Field(
        default_factory=lambda: [0, 0, 0], min_length=3, max_length=3)
    # the roll, pitch and yaw sticks the pilot holds on the channels it has (0: neutral, no
    # rotation); a small pitch stick on a channel handed to the pilot is a vehicle that
    # drifts (the fleet's separation tests)
    serial_enable: bool = True  # the RC serial-enable switch
    pilot_holds_thrust: bool = True
    # a pilot handed the vehicle in the air holds the thrust applied at that moment
    rc_link: bool = True
    battery_mv: Annotated[int, within(
        0, 65535, "mV: STATUS carries it as uint16 (spec section 3.3)")] = 11800
    # reported in STATUS (3S LiPo, spec worked frame)
    truth_file: FilePath | None = None  # ground truth written here on exit
    faults: SimFaultsConfig = SimFaultsConfig()
    vicon: SimViconConfig = SimViconConfig()


def sim_section(config: GroundStationConfig) -> SimConfig:
    """The configuration's ``sim:`` section as :class:`SimConfig`; the defaults if it has
    none. The ground station's configuration keeps the section as given until it is
    assembled (``groundstation.flight.assembly.check_config`` has the lab validate it);
    one not validated yet is validated here: ConfigError naming every bad key."""
    section = config.sim
    if section is None:
        return SimConfig()
    if isinstance(section, SimConfig):
        return section
    try:
        return SimConfig.model_validate(section)
    except ValidationError as exc:
        raise_problems(validation_problems(exc, "sim"), "<config>")
