"""Plain parameters of the virtual lab, validated once at construction.

The simulation classes take these frozen dataclasses, not the pydantic
configuration, so they can be built in a test with keywords only.
:meth:`LabParams.from_config` maps a :class:`~groundstation.config.GroundStationConfig`
onto them (its ``sim`` section, the vehicle model, the serial link and the
Vicon stream); fields that have no configuration key yet keep the defaults
below, each of which names its source.

Units are SI; frames NED (earth) and FRD (body); quaternions scalar first.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Literal, get_args

import numpy as np
import numpy.typing as npt

from groundstation.asctec.decoder import FRAME_OVERHEAD
from groundstation.asctec.ll import LL_MESSAGE_TYPES
from groundstation.config import LlConfig
from groundstation.errors import ConfigError
from groundstation.model.quadrotor import QuadrotorParams
from groundstation.model.sensors import (
    ACC_SATURATION_M_S2,
    ACC_VARIANCE_TABLE_6_3,
    GYRO_VARIANCE_TABLE_6_3,
    K_ACC_TABLE_6_2,
    K_GYRO_TABLE_6_2,
    VICON_POSITION_VARIANCE_TABLE_6_1,
    VICON_QUATERNION_VARIANCE_TABLE_6_1,
)
from groundstation.types import Dialect
from groundstation.vicon.frames import rotation_from_euler_deg
from sim_device.config import SimConfig, SimGroundEffectConfig, SimWindConfig

if TYPE_CHECKING:
    from groundstation.config import GroundStationConfig

Vec3 = tuple[float, float, float]
LossEncoding = Literal["missing", "zero", "held-identity"]
LOSS_ENCODINGS: tuple[LossEncoding, ...] = ("missing", "zero", "held-identity")
DIALECTS: tuple[Dialect, ...] = get_args(Dialect)
"""The serial dialects the virtual vehicle speaks (``serial.protocol``)."""
X3D_COUNT_RANGE = (0, 4095)
"""The X-3D DATA stream's 12-bit ADC counts (spec 3.3)."""
LL_COUNT_RANGE = (-32768, 32767)
"""The AscTec LL IMU_RAWDATA's int16 counts."""
LL_MAX_FRAME = max(max(c.PAYLOAD_SIZES) for c in LL_MESSAGE_TYPES.values()) + FRAME_OVERHEAD
"""The largest LL packet on the wire [bytes] (IMU_CALCDATA, 103)."""

_VEHICLE = QuadrotorParams()
"""The vehicle model's defaults (groundstation.model.quadrotor): the design model."""


_LL = LlConfig()
"""The ``serial.ll`` section's defaults (the LL dialect's link schedule)."""

_SIM = SimConfig()
"""The ``sim:`` section's defaults (:mod:`sim_device.config`): the one place the lab's
defaults are declared; the dataclasses below take theirs from it."""


def _tuple3(values: list[float]) -> tuple[float, float, float]:
    return (float(values[0]), float(values[1]), float(values[2]))


_GYRO_BIAS, _ACC_BIAS = _tuple3(_SIM.gyro_bias), _tuple3(_SIM.acc_bias)
_SIM_WIND = SimWindConfig()
"""The ``sim.wind`` section's defaults (drag coefficients)."""
_WIND, _BODY_DRAG = _tuple3(_SIM_WIND.velocity_m_s), _tuple3(_SIM_WIND.body_drag_n_s2_m2)
_SIM_GROUND = SimGroundEffectConfig()
"""The ``sim.ground_effect`` section's defaults."""


def _require(ok: bool, name: str, value: object, reason: str) -> None:
    """Raise ConfigError naming the parameter unless ``ok``."""
    if not ok:
        raise ConfigError(f"{name}: {value!r}: {reason}", [(name, value, reason)])


def _finite(*values: float) -> bool:
    return all(math.isfinite(v) for v in values)


@dataclass(frozen=True, slots=True)
class WindParams:
    """Moving air and the drag the plant feels on its airspeed (``sim.wind``).

    velocity : steady wind, NED [m/s]
    gusts : ``(start [s], duration [s], peak (3,) NED [m/s])`` 1-cosine gusts on top:
        ``peak (1 - cos(2 pi (t - start) / duration)) / 2`` while they last
    rotor_drag : in-plane rotor drag at the nominal vehicle's hover rotor speed [N s/m]
        (RotorPy's ``k_d`` summed over the rotors); it scales with the rotor speed,
        ``sqrt(|lift| / (m g))``. Along body z the rotors' drag is the thesis's induced
        inflow ``I_i v_3`` (eq. 3.9), on the airspeed.
    body_drag : parasitic drag of the frame along body x, y, z [N s^2/m^2] (RotorPy's
        ``c_D``): ``-c_D,i |v_air| v_air,i``
    """

    velocity: Vec3 = _WIND
    gusts: tuple[tuple[float, float, Vec3], ...] = ()
    rotor_drag: float = _SIM_WIND.rotor_drag_n_s_m
    body_drag: Vec3 = _BODY_DRAG

    def __post_init__(self) -> None:
        _require(len(self.velocity) == 3 and _finite(*self.velocity), "wind.velocity",
                 self.velocity, "three finite speeds [m/s]")
        _require(all(len(g) == 3 and _finite(g[0], g[1], *g[2]) and g[1] > 0
                     for g in self.gusts), "wind.gusts", self.gusts,
                 "(start, duration > 0, (north, east, down)) triples")
        _require(self.rotor_drag >= 0 and len(self.body_drag) == 3
                 and all(c >= 0 for c in self.body_drag), "wind.drag",
                 (self.rotor_drag, self.body_drag), "drag coefficients >= 0")

    def at(self, t: float) -> Vec3:
        """The wind at time ``t`` [s], NED [m/s]."""
        wn, we, wd = self.velocity
        for start, duration, (gn, ge, gd) in self.gusts:
            if start <= t <= start + duration:
                k = 0.5 * (1.0 - math.cos(math.tau * (t - start) / duration))
                wn, we, wd = wn + k * gn, we + k * ge, wd + k * gd
        return wn, we, wd


@dataclass(frozen=True, slots=True)
class GroundEffectParams:
    """More lift near the floor (``sim.ground_effect``): Cheeseman and Bennett's
    ``T / T_inf = 1 / (1 - (R / 4 h)^2)`` for rotors of radius ``R`` at height ``h`` above
    the floor, ``h = rotor_height - z`` (z NED, 0 on the floor), floored at ``R / 2``
    where the formula stops holding (its value there, 4/3, is kept below it).

    rotor_radius : R [m]; rotor_height : the rotor plane above the floor when the vehicle
        stands [m]
    """

    rotor_radius: float = _SIM_GROUND.rotor_radius_m
    rotor_height: float = _SIM_GROUND.rotor_height_m

    def __post_init__(self) -> None:
        _require(self.rotor_radius > 0 and self.rotor_height >= 0, "ground_effect",
                 (self.rotor_radius, self.rotor_height), "radius > 0, height >= 0")

    def factor(self, z: float) -> float:
        """Lift in ground effect / lift out of it at NED height ``z`` [m] (z <= 0)."""
        h = max(self.rotor_height - z, 0.5 * self.rotor_radius)
        r = self.rotor_radius / (4.0 * h)
        return 1.0 / (1.0 - r * r)


@dataclass(frozen=True, slots=True)
class PlantParams:
    """Rigid-body plant: thesis eq. 3.19-3.22 plus the dynamics Ch. 10.3/12 found missing.

    mass : [kg]; g : [m/s^2] (eq. 3.8)
    k_rate : (K_phi, K_theta, K_psi) body-rate set point per stick unit [rad/s per unit]
    thrust_poly : eq. 3.7 coefficients (a3, a2, a1, a0): body-z lift [N] (negative = up)
    inflow : induced-inflow constant I_i [N s/m] (eq. 3.9)
    rate_tau : on-board rate loop as a first-order lag [s]; 0 = ideal (thesis model).
        0.064 s gives the 0.14 s 10-90 % rise of Fig. 3.8 (rise = 2.2 tau).
    motor_tau_s : motor/rotor lag of the lift [s]; 0 = instantaneous. Thesis silent;
        0.02 s is typical of ~10 cm brushless rotors.
    thrust_scale : true lift / polynomial lift (0.9 = 10 % less lift than the model)
    battery_droop : fraction of lift lost over ``battery_droop_time`` (Ch. 5.2), linear in time
    battery_droop_time : [s]
    initial_position : NED [m]; z = 0 is the floor
    initial_yaw : heading [rad]
    impact_time : a touchdown stops the vehicle over this long [s] as far as the
        accelerometer is concerned (the body rests at once): the IMU feels the
        deceleration -v/impact_time, and clips it like the real one. 0.05 s: skids
        and foam feet of a small quadrotor; thesis silent.
    thrust_faults : ``(start [s], duration [s], lift_scale)`` windows in which the rotors
        give ``lift_scale`` times their lift (fault injection; none by default)
    payload_steps : ``(time [s], factor)``: from ``time`` on the mass is ``factor`` times
        what it was (a payload picked up or dropped; none by default)
    wind : moving air and drag on the airspeed (:class:`WindParams`); None: still air and
        no drag, the thesis's model
    ground_effect : more lift near the floor (:class:`GroundEffectParams`); None: none
    """

    mass: float = _VEHICLE.mass
    g: float = _VEHICLE.g
    k_rate: Vec3 = _VEHICLE.k_rate
    thrust_poly: tuple[float, ...] = _VEHICLE.thrust_poly
    inflow: float = _VEHICLE.inflow
    rate_tau: float = _VEHICLE.rate_tau
    motor_tau_s: float = _SIM.motor_tau_s
    thrust_scale: float = _SIM.thrust_scale
    battery_droop: float = _SIM.battery_droop
    battery_droop_time: float = _SIM.battery_droop_time_s
    initial_position: Vec3 = (0.0, 0.0, 0.0)
    initial_yaw: float = 0.0
    impact_time: float = 0.05
    thrust_faults: tuple[tuple[float, float, float], ...] = ()
    payload_steps: tuple[tuple[float, float], ...] = ()
    wind: WindParams | None = None
    ground_effect: GroundEffectParams | None = None

    def __post_init__(self) -> None:
        _require(self.mass > 0 and self.g > 0, "plant.mass/g", (self.mass, self.g), "must be > 0")
        _require(len(self.k_rate) == 3 and _finite(*self.k_rate), "plant.k_rate", self.k_rate,
                 "three finite gains")
        _require(len(self.thrust_poly) == 4 and _finite(*self.thrust_poly), "plant.thrust_poly",
                 self.thrust_poly, "four finite coefficients (a3, a2, a1, a0)")
        _require(self.rate_tau >= 0 and self.motor_tau_s >= 0, "plant.rate_tau/motor_tau_s",
                 (self.rate_tau, self.motor_tau_s), "must be >= 0")
        _require(self.thrust_scale > 0, "plant.thrust_scale", self.thrust_scale, "must be > 0")
        _require(self.impact_time > 0, "plant.impact_time", self.impact_time, "must be > 0")
        _require(0 <= self.battery_droop < 0.5 and self.battery_droop_time > 0,
                 "plant.battery_droop", (self.battery_droop, self.battery_droop_time),
                 "droop in [0, 0.5) over a positive time")
        _require(all(len(f) == 3 and _finite(*f) and f[1] >= 0 and f[2] >= 0
                     for f in self.thrust_faults), "plant.thrust_faults", self.thrust_faults,
                 "(start, duration >= 0, lift scale >= 0) triples")
        _require(all(len(p) == 2 and _finite(*p) and p[1] > 0 for p in self.payload_steps),
                 "plant.payload_steps", self.payload_steps, "(time, mass factor > 0) pairs")
        _require(len(self.initial_position) == 3 and self.initial_position[2] <= 0,
                 "plant.initial_position", self.initial_position, "NED, z <= 0 (floor at 0)")


@dataclass(frozen=True, slots=True)
class ImuParams:
    """On-board gyro/accelerometer as the DATA stream reports them (spec 3.3).

    gyro_scale, acc_scale : Table 6.2 K [rad/s or m/s^2 per count] (what the ground
        station assumes; the true scale differs by the scale error)
    gyro_zero, acc_zero : zero offsets [counts]
    gyro_variance, acc_variance : Table 6.3 white-noise variances [(rad/s)^2, (m/s^2)^2]
    gyro_bias, acc_bias : constant biases, FRD [rad/s, m/s^2]
    scale_error : each axis's true scale differs from nominal by a factor drawn
        uniformly in [1 - e, 1 + e] (seeded)
    acc_saturation : the physical accelerometer clips at +/- this [m/s^2] (Ch. 6.2)
    gyro_saturation : physical gyro range [rad/s]; None = only the ADC clips
    pressure_noise : standard deviation of the raw pressure reading [Pa]
    count_range : (min, max) the ADC's counts clip to: the X-3D's 12 bits (0, 4095) or
        the AscTec LL dialect's int16 (-32768, 32767) [counts]
    """

    gyro_scale: Vec3 = K_GYRO_TABLE_6_2
    acc_scale: Vec3 = K_ACC_TABLE_6_2
    gyro_zero: Vec3 = (2048.0, 2048.0, 2048.0)
    acc_zero: Vec3 = (2048.0, 2048.0, 2048.0)
    gyro_variance: Vec3 = GYRO_VARIANCE_TABLE_6_3
    acc_variance: Vec3 = ACC_VARIANCE_TABLE_6_3
    gyro_bias: Vec3 = _GYRO_BIAS
    acc_bias: Vec3 = _ACC_BIAS
    scale_error: float = _SIM.scale_error
    acc_saturation: float = ACC_SATURATION_M_S2
    gyro_saturation: float | None = None
    pressure_noise: float = 2.0
    count_range: tuple[int, int] = X3D_COUNT_RANGE

    def __post_init__(self) -> None:
        lo, hi = self.count_range
        _require(lo < hi, "imu.count_range", self.count_range, "(min, max) with min < max")
        for name in ("gyro_scale", "acc_scale"):
            v = getattr(self, name)
            _require(len(v) == 3 and all(x != 0 for x in v) and _finite(*v), f"imu.{name}", v,
                     "three finite non-zero scales")
        for name in ("gyro_variance", "acc_variance"):
            v = getattr(self, name)
            _require(len(v) == 3 and all(x >= 0 for x in v), f"imu.{name}", v, "three >= 0")
        _require(0 <= self.scale_error < 0.5, "imu.scale_error", self.scale_error, "in [0, 0.5)")
        _require(self.acc_saturation > 0, "imu.acc_saturation", self.acc_saturation, "> 0")


@dataclass(frozen=True, slots=True)
class LinkParams:
    """The serial link and the vehicle's firmware behaviour (spec sections 1-4).

    baud : bits per second, 10 bits per byte (8N1); output is paced at this rate
    crc_profile : spec section 2 CRC profile name
    command_delay : transport delay of the ground -> vehicle link [s] (radio, firmware)
    watchdog : no valid COMMAND for this long hands every channel to the pilot [s]
        (X-3D: the spec's 100 ms; LL: ``serial.ll.fallback_ms``)
    battery_mv : STATUS battery voltage with a full battery [mV]; droops with the lift
    protocol : the dialect the vehicle speaks: "x3d" (:mod:`sim_device.firmware`) or
        "asctec-ll" (:mod:`sim_device.ll_firmware`)
    rc_channels : LL RC_DATA channels_out indices of pitch, roll, thrust, yaw
        (``serial.ll.rc_channels``)
    rc_switch_channel : LL RC_DATA channel of the pilot's serial-enable switch (AscTec's
        channel 5, index 4; unverified)
    tx_buffer : LL firmware's transmit buffer [bytes]: a poll's answer that does not fit
        behind the bytes still queued is not sent (unknown on the vehicle; 512 B holds
        every packet of one poll twice over)
    motor_start_yaw, motor_gesture : LL motor gesture: thrust 0 with the yaw at this value
        (the opposite stops) held this long [s] starts the motors (``serial.ll``)
    """

    baud: int = 57600
    crc_profile: str = "asctec"
    command_delay: float = 0.02
    watchdog: float = 0.100
    battery_mv: int = _SIM.battery_mv
    protocol: Dialect = "x3d"
    rc_channels: tuple[int, int, int, int] = _LL.rc_channels
    rc_switch_channel: int = 4
    tx_buffer: int = 512
    motor_start_yaw: int = _LL.motor_start_yaw
    motor_gesture: float = 0.4

    def __post_init__(self) -> None:
        _require(self.baud > 0, "link.baud", self.baud, "must be > 0")
        _require(self.command_delay >= 0 and self.watchdog > 0, "link.command_delay/watchdog",
                 (self.command_delay, self.watchdog), "delay >= 0, watchdog > 0")
        _require(self.protocol in DIALECTS, "link.protocol", self.protocol,
                 f"one of {DIALECTS}")
        channels = (*self.rc_channels, self.rc_switch_channel)
        _require(len(self.rc_channels) == 4 and len(set(channels)) == 5
                 and all(0 <= c <= 7 for c in channels), "link.rc_channels",
                 (self.rc_channels, self.rc_switch_channel),
                 "four distinct RC_DATA channels 0..7 besides the serial-enable switch's")
        _require(self.tx_buffer >= LL_MAX_FRAME, "link.tx_buffer", self.tx_buffer,
                 f"at least the largest LL packet ({LL_MAX_FRAME} bytes)")


@dataclass(frozen=True, slots=True)
class FaultParams:
    """Link faults, all off by default.

    corruption_rate : probability per byte of one flipped bit, both directions
    drop_rate : probability per DATA frame that the radio loses it whole
    stall_at, stall_duration : the DATA stream stops at this time for this long [s]
    burst_delay_s : hold DATA and release it every this many seconds (0 = off)
    data_delay : extra constant delay of every DATA frame [s]
    """

    corruption_rate: float = 0.0
    drop_rate: float = 0.0
    stall_at: float | None = None
    stall_duration: float = 0.0
    burst_delay_s: float = 0.0
    data_delay: float = 0.0

    def __post_init__(self) -> None:
        _require(0 <= self.corruption_rate <= 1 and 0 <= self.drop_rate <= 1, "faults.rates",
                 (self.corruption_rate, self.drop_rate), "probabilities in [0, 1]")
        _require(self.stall_duration >= 0 and self.burst_delay_s >= 0 and self.data_delay >= 0,
                 "faults.times", (self.stall_duration, self.burst_delay_s, self.data_delay),
                 "must be >= 0")


@dataclass(frozen=True, slots=True)
class ViconSimParams:
    """The virtual Vicon Tracker (``docs/vicon-udp.md``).

    rate_hz : datagrams per second (any rate; the thesis used 100, 10 and 1)
    latency : delay from the pose instant to delivery [s]
    noise : add Table 6.1 noise (variances below)
    angle_noise : with ``noise``, on the attitude too (False: exact angles, noisy position)
    position_variance : (3,) NED [m^2]; quaternion_variance : (4,) q0..q3 [-]
    loss_encoding : how lost tracking is sent (spec "lost tracking" 1-3)
    outages : (start, duration) [s] windows without tracking
    tilt_limit_deg : tracking is lost beyond this tilt from level [deg]
    volume_x, volume_y, volume_z : tracked volume, NED [m] (Table B.1: +/-1.5 m,
        0..2 m height; z up to +0.05 so the vehicle on the floor is tracked)
    object_name : the object's name in the datagrams (at most 23 bytes)
    pad_to : datagram length (Tracker's data block size), None = unpadded
    world_to_ned, body_to_object : (3, 3) rotations as nested tuples (spec; 180 deg about x)
    first_frame : Tracker frame number of the first datagram
    """

    rate_hz: float = _SIM.vicon.rate_hz
    latency: float = _SIM.vicon.latency_s
    noise: bool = _SIM.vicon.noise
    angle_noise: bool = _SIM.vicon.angle_noise
    position_variance: Vec3 = VICON_POSITION_VARIANCE_TABLE_6_1
    quaternion_variance: tuple[float, float, float, float] = VICON_QUATERNION_VARIANCE_TABLE_6_1
    loss_encoding: LossEncoding = _SIM.vicon.loss_encoding
    outages: tuple[tuple[float, float], ...] = ()
    tilt_limit_deg: float = _SIM.vicon.tilt_limit_deg
    volume_x: tuple[float, float] = _SIM.vicon.volume_x
    volume_y: tuple[float, float] = _SIM.vicon.volume_y
    volume_z: tuple[float, float] = _SIM.vicon.volume_z
    object_name: str = "X3D"
    pad_to: int | None = _SIM.vicon.pad_to
    world_to_ned: tuple[Vec3, Vec3, Vec3] = ((1.0, 0.0, 0.0), (0.0, -1.0, 0.0), (0.0, 0.0, -1.0))
    body_to_object: tuple[Vec3, Vec3, Vec3] = ((1.0, 0.0, 0.0), (0.0, -1.0, 0.0), (0.0, 0.0, -1.0))
    first_frame: int = 1

    def __post_init__(self) -> None:
        _require(self.rate_hz > 0 and self.latency >= 0, "vicon.rate_hz/latency",
                 (self.rate_hz, self.latency), "rate > 0, latency >= 0")
        _require(self.loss_encoding in LOSS_ENCODINGS, "vicon.loss_encoding", self.loss_encoding,
                 f"one of {LOSS_ENCODINGS}")
        _require(all(d >= 0 for _, d in self.outages), "vicon.outages", self.outages,
                 "(start, duration) with duration >= 0")
        for name in ("volume_x", "volume_y", "volume_z"):
            lo, hi = getattr(self, name)
            _require(lo < hi, f"vicon.{name}", (lo, hi), "(min, max) with min < max")


@dataclass(frozen=True, slots=True)
class PilotParams:
    """The scripted RC pilot: neutral rate sticks, a held thrust stick.

    thrust : thrust stick the pilot holds (0 = motors off, vehicle on the floor)
    serial_enable : the RC serial-enable switch (commands apply only when on)
    rc_link : the RC link is valid (STATUS flag bit 2)
    hold_thrust : when the thrust channel falls back to the pilot while airborne
        (watchdog, switch, mask-0 COMMAND), the pilot holds the thrust applied at
        that moment, rate sticks as held, instead of jumping to ``thrust``
    rate_sticks : the roll, pitch and yaw sticks the pilot holds (neutral: 0)
    """

    thrust: int = _SIM.pilot_thrust
    serial_enable: bool = _SIM.serial_enable
    rc_link: bool = _SIM.rc_link
    hold_thrust: bool = _SIM.pilot_holds_thrust
    rate_sticks: tuple[int, int, int] = (0, 0, 0)

    def __post_init__(self) -> None:
        _require(0 <= self.thrust <= 4096, "pilot.thrust", self.thrust, "in 0..4096")


@dataclass(frozen=True, slots=True)
class LabParams:
    """Everything the virtual lab needs.

    dt : fixed plant step [s] (2 ms: fine for the rate-loop and motor lags)
    seed : seeds every random draw (noise, scale errors, faults); same seed, same run
    truth_period : ground-truth log interval [s] (a multiple of dt is exact)
    """

    dt: float = _SIM.dt_s
    seed: int = _SIM.seed
    truth_period: float = 0.01
    plant: PlantParams = field(default_factory=PlantParams)
    imu: ImuParams = field(default_factory=ImuParams)
    link: LinkParams = field(default_factory=LinkParams)
    faults: FaultParams = field(default_factory=FaultParams)
    vicon: ViconSimParams = field(default_factory=ViconSimParams)
    pilot: PilotParams = field(default_factory=PilotParams)

    def __post_init__(self) -> None:
        _require(0 < self.dt <= 0.01, "dt", self.dt, "in (0, 0.01] s")
        _require(self.truth_period > 0, "truth_period", self.truth_period, "must be > 0")
        lo, hi = LL_COUNT_RANGE if self.link.protocol == "asctec-ll" else X3D_COUNT_RANGE
        _require(lo <= self.imu.count_range[0] and self.imu.count_range[1] <= hi,
                 "imu.count_range", self.imu.count_range,
                 f"within the {self.link.protocol} dialect's ({lo}, {hi})")

    @classmethod
    def from_config(cls, config: GroundStationConfig) -> LabParams:
        """Parameters from a validated configuration (``sim`` may be absent: defaults).

        Fields without a configuration key keep their defaults:
        imu.gyro_saturation/pressure_noise, link.rc_switch_channel/tx_buffer and, for the
        X-3D dialect, link.watchdog (the spec's 100 ms). With ``serial.protocol:
        asctec-ll`` the watchdog is ``serial.ll.fallback_ms``, the RC_DATA channels
        ``serial.ll.rc_channels`` and the IMU counts int16.
        """
        from sim_device.config import sim_section

        sim = sim_section(config)
        f = sim.faults
        return cls(
            dt=sim.dt_s, seed=sim.seed, plant=_plant_params(config, sim),
            imu=_imu_params(config, sim), vicon=_vicon_params(config, sim),
            link=_link_params(config, sim),
            faults=FaultParams(corruption_rate=f.corruption_rate, drop_rate=f.drop_rate,
                               stall_at=f.stall_at_s, stall_duration=f.stall_duration_s,
                               burst_delay_s=f.burst_delay_s, data_delay=f.delay_s),
            pilot=PilotParams(thrust=sim.pilot_thrust, serial_enable=sim.serial_enable,
                              rc_link=sim.rc_link, hold_thrust=sim.pilot_holds_thrust,
                              rate_sticks=(sim.pilot_rate_sticks[0], sim.pilot_rate_sticks[1],
                                           sim.pilot_rate_sticks[2])),
        )


def _plant_params(config: GroundStationConfig, sim: SimConfig) -> PlantParams:
    veh = config.vehicle
    k_rate = tuple(k * s for k, s in zip(veh.k_rate, sim.k_rate_scale, strict=True))
    tau = veh.rate_loop_tau_s if sim.rate_loop_tau_s is None else sim.rate_loop_tau_s
    return PlantParams(
        mass=veh.mass_kg * sim.mass_scale, g=veh.gravity, k_rate=_vec3(k_rate),
        thrust_poly=tuple(veh.thrust_poly), inflow=veh.induced_inflow,
        rate_tau=tau, motor_tau_s=sim.motor_tau_s, thrust_scale=sim.thrust_scale,
        battery_droop=sim.battery_droop, battery_droop_time=sim.battery_droop_time_s,
        initial_position=_vec3(sim.initial_position),
        initial_yaw=math.radians(sim.initial_yaw_deg),
        thrust_faults=tuple((float(a), float(b), float(c))
                            for a, b, c in sim.faults.thrust_faults),
        payload_steps=tuple((float(t), float(f)) for t, f in sim.payload_steps),
        wind=None if sim.wind is None else WindParams(
            velocity=_vec3(sim.wind.velocity_m_s),
            gusts=tuple((float(g[0]), float(g[1]), _vec3(g[2:5])) for g in sim.wind.gusts),
            rotor_drag=sim.wind.rotor_drag_n_s_m, body_drag=_vec3(sim.wind.body_drag_n_s2_m2)),
        ground_effect=None if sim.ground_effect is None else GroundEffectParams(
            rotor_radius=sim.ground_effect.rotor_radius_m,
            rotor_height=sim.ground_effect.rotor_height_m),
    )


def _link_params(config: GroundStationConfig, sim: SimConfig) -> LinkParams:
    serial = config.serial
    delay = config.vehicle.command_delay_s if sim.command_delay_s is None else sim.command_delay_s
    if serial.protocol == "asctec-ll":
        ll = serial.ll
        return LinkParams(baud=serial.baud, crc_profile=serial.crc_profile,
                          command_delay=delay, battery_mv=sim.battery_mv,
                          protocol="asctec-ll", watchdog=ll.fallback_ms / 1000.0,
                          rc_channels=ll.rc_channels, motor_start_yaw=ll.motor_start_yaw)
    return LinkParams(baud=serial.baud, crc_profile=serial.crc_profile, command_delay=delay,
                      battery_mv=sim.battery_mv)


def _imu_params(config: GroundStationConfig, sim: SimConfig) -> ImuParams:
    veh = config.vehicle
    ll = config.serial.protocol == "asctec-ll"
    return ImuParams(
        gyro_scale=_vec3(veh.gyro_scale), acc_scale=_vec3(veh.acc_scale),
        gyro_zero=_vec3(veh.gyro_zero), acc_zero=_vec3(veh.acc_zero),
        gyro_variance=_vec3(veh.gyro_variance), acc_variance=_vec3(veh.acc_variance),
        gyro_bias=_vec3(sim.gyro_bias), acc_bias=_vec3(sim.acc_bias),
        scale_error=sim.scale_error, acc_saturation=veh.acc_saturation,
        count_range=LL_COUNT_RANGE if ll else X3D_COUNT_RANGE,
    )


def _vicon_params(config: GroundStationConfig, sim: SimConfig) -> ViconSimParams:
    sv, vc = sim.vicon, config.vicon
    return ViconSimParams(
        rate_hz=sv.rate_hz, latency=sv.latency_s, noise=sv.noise, angle_noise=sv.angle_noise,
        position_variance=_vec3(config.vehicle.vicon_position_variance),
        quaternion_variance=_vec4(config.vehicle.vicon_quaternion_variance),
        loss_encoding=sv.loss_encoding,
        outages=tuple((float(start), float(length)) for start, length in sv.outages),
        tilt_limit_deg=sv.tilt_limit_deg, object_name=vc.object_name, pad_to=sv.pad_to,
        volume_x=sv.volume_x, volume_y=sv.volume_y, volume_z=sv.volume_z,
        world_to_ned=_mat3(rotation_from_euler_deg(vc.world_to_ned.euler_xyz_deg)),
        body_to_object=_mat3(rotation_from_euler_deg(vc.body_to_object.euler_xyz_deg)),
    )


def _vec3(values: list[float] | tuple[float, ...]) -> Vec3:
    return (float(values[0]), float(values[1]), float(values[2]))


def _vec4(values: list[float]) -> tuple[float, float, float, float]:
    return (float(values[0]), float(values[1]), float(values[2]), float(values[3]))


def _mat3(m: npt.NDArray[np.float64]) -> tuple[Vec3, Vec3, Vec3]:
    return (_vec3(m[0].tolist()), _vec3(m[1].tolist()), _vec3(m[2].tolist()))
