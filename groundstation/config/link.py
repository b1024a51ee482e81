"""The links to the vehicle and to Vicon: the ``serial``, ``channels`` and ``vicon``
sections."""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field, field_validator, model_validator

from groundstation.config.base import ConfigModel
from groundstation.config.ranges import (
    COMMAND_RATE_MAX_HZ,
    LAB_EXTENT_M,
    VICON_RATE_MAX_HZ,
    HostAddress,
    RcChannel,
    TurnDeg,
    within,
)
from groundstation.types import CHANNELS, Channel, Dialect, SensorBlockName


def _default_sensors() -> list[SensorBlockName]:
    return ["status", "gyro", "acc", "rc"]


def _all_channels() -> list[Channel]:
    return list(CHANNELS)


class LlConfig(ConfigModel):
    """The AscTec LL dialect's link schedule (``serial.protocol: asctec-ll``; docs/protocol.md).

    The vehicle sends only what is polled: IMU_RAWDATA every ``serial.data_period_ms``,
    LL_STATUS and RC_DATA with every ``status_every``-th and ``rc_every``-th of those polls.
    """

    status_every: Annotated[int, within(1, 1000, "polls per LL_STATUS: at 100 Hz polls "
                                        "1000 is one every 10 s; rarer and the battery "
                                        "and the pilot's switch go unseen")] = 10
    # LL_STATUS (battery, serial switch, commands applied) at 10 Hz with 100 Hz IMU polls:
    # 27 B each, 5 % of the line; slower delays the supervisor's "pilot took over"
    rc_every: Annotated[int, within(1, 1000, "polls per RC_DATA: at 100 Hz polls 1000 is "
                                    "one every 10 s; rarer and the pilot's sticks go "
                                    "unseen")] = 10
    # RC_DATA (the pilot's sticks) at 10 Hz; design choice within the line budget
    answer_timeout_ms: Annotated[float, within(
        0, 500.0, "the round trip is ~40 ms; half a second is 50 unanswered polls at 100 Hz",
        lo_open=True)] = 80.0
    # a poll not answered completely by then is counted unanswered: above the round trip
    # (57600 baud: 1 ms up, 7 ms down, the radio's latency: 30-40 ms in the virtual lab)
    ack_timeout_ms: Annotated[float, within(
        0, 500.0, "the round trip is ~40 ms; half a second is 25 commands at 50 Hz",
        lo_open=True)] = 80.0
    # a command whose 5-byte acknowledgement has not arrived by then is counted missing
    fallback_ms: Annotated[float, within(
        20.0, 1000.0, "the firmware's fallback: AscTec's SDK used 200 ms; below 20 ms no "
        "command link keeps it, beyond a second the vehicle flies on a stale command")] = 100.0
    # the LL firmware's fallback after the last command: undocumented; AscTec's later SDK
    # used 200 ms; 100 ms like the X-3D's watchdog until measured on the vehicle
    rc_channels: tuple[RcChannel, RcChannel, RcChannel, RcChannel] = (0, 1, 2, 3)
    # RC_DATA channels_out index of pitch, roll, thrust, yaw: AscTec SDK order, unverified
    motor_start_yaw: Literal[-2047, 2047] = -2047
    # the motor gesture's yaw to start (the opposite stops): drivers disagree on the sign
    motor_gesture_s: Annotated[float, within(
        0, 3.0, "public drivers hold the gesture about half a second; 3 s is ample",
        lo_open=True)] = 0.5  # how long the gesture is held

    @field_validator("rc_channels")
    @classmethod
    def _distinct(cls, value: tuple[int, ...]) -> tuple[int, ...]:
        if len(set(value)) != len(value):
            raise ValueError("a channel index given twice: pitch, roll, thrust and yaw are "
                             "four different sticks")
        return value


class SerialConfig(ConfigModel):
    """The serial link to the vehicle (X-3D dialect ``docs/protocol.md`` or the
    AscTec LL dialect; docs/protocol.md)."""

    protocol: Dialect = "x3d"
    # the vehicle's dialect: configured, never guessed from the bytes (the dialects share
    # descriptor 0x01 for different packets)
    port: str = "/dev/ttyUSB0"  # the lab's XBee adapter; a pty path or pyserial URL also works
    baud: Annotated[int, within(1200, 4_000_000, "from the slowest rate an XBee radio "
                                "offers (BD=0) to the 4 Mbaud of the fastest USB UARTs")] = 57600
    # spec section 1 default (design choice)
    crc_profile: Literal["asctec", "kermit", "mcrf4xx"] = "asctec"  # spec section 2
    sensors: list[SensorBlockName] = Field(default_factory=_default_sensors)
    # STATUS+GYRO+ACC+RC = 41 B/frame, 71% of 57600 baud at 100 Hz (spec section 6)
    data_period_ms: Annotated[int, within(1, 1000, "the X-3D streams at most every 1 ms; "
                                          "slower than 1 Hz is no IMU to fly on")] = 10
    # 100 Hz IMU, thesis Ch. 1.2.2
    command_rate_hz: Annotated[float, within(
        20.0, COMMAND_RATE_MAX_HZ, "spec section 4's target is 50-100 Hz; below 20 Hz a "
        "command period exceeds half the vehicle's 100 ms watchdog")] = 50.0
    # 50 Hz: spec section 4 target 50-100 Hz; thesis flew 33 Hz over XBee (App. A.3).
    stale_command_s: Annotated[float, within(
        0, 1.0, "the keep-alive flies the loop's last command this long: beyond a second "
        "a stalled loop would steer the vehicle", lo_open=True)] = 0.25
    # keep-alive resends the loop's last command only this long, then hands back (mask 0)
    handover_blend_s: Annotated[float, within(
        0.0, 10.0, "a blend longer than 10 s leaves the vehicle half with the pilot for "
        "longer than a take-off takes")] = 1.0  # bumpless-transfer blend time; thesis silent
    ll: LlConfig = LlConfig()  # read with protocol asctec-ll only

    @field_validator("sensors")
    @classmethod
    def _needs_imu(cls, value: list[str]) -> list[str]:
        if len(set(value)) != len(value):
            raise ValueError("sensor blocks listed twice")
        if "gyro" not in value or "acc" not in value:
            raise ValueError("the estimator needs the 'gyro' and 'acc' blocks")
        return value

    @model_validator(mode="after")
    def _commands_within_the_fallback(self) -> SerialConfig:
        if self.protocol == "asctec-ll" and 2000.0 / self.command_rate_hz > self.ll.fallback_ms:
            raise ValueError(
                f"command_rate_hz {self.command_rate_hz:g}: a command period of "
                f"{1000.0 / self.command_rate_hz:.0f} ms is more than half the vehicle's "
                f"{self.ll.fallback_ms:g} ms fallback (serial.ll.fallback_ms)")
        return self



class ChannelsConfig(ConfigModel):
    """Which channels the ground station controls (the rest stay with the RC pilot)."""

    auto: list[Channel] = Field(default_factory=_all_channels)

    @field_validator("auto")
    @classmethod
    def _unique(cls, value: list[str]) -> list[str]:
        if len(set(value)) != len(value):
            raise ValueError("channel listed twice")
        return value


class RotationConfig(ConfigModel):
    """A fixed rotation given as intrinsic X-Y-Z Euler angles in degrees."""

    euler_xyz_deg: list[TurnDeg] = Field(default_factory=lambda: [180.0, 0.0, 0.0],
                                         min_length=3, max_length=3)



class ViconConfig(ConfigModel):
    """The Vicon UDP object stream (``docs/vicon-udp.md``)."""

    bind_address: HostAddress = "0.0.0.0"  # IPv4 (the client is AF_INET); 0.0.0.0: all
    port: Annotated[int, within(1, 65535, "a UDP port")] = 51001
    # Tracker's conventional UDP object-stream port
    object_name: str = Field("X3D", min_length=1, max_length=23)  # spec: at most 23 characters
    world_to_ned: RotationConfig = RotationConfig()  # Vicon z-up -> NED: 180 deg about x (spec)
    body_to_object: RotationConfig = RotationConfig()  # FRD body -> object frame: 180 deg about x
    latency_s: Annotated[float, within(0.0, 0.5, "spec: Tracker and the network add a few "
                                       "ms; half a second is no motion capture")] = 0.005
    # spec: "a few ms"; Tracker + network latency
    expected_rate_hz: Annotated[float, within(
        1.0, VICON_RATE_MAX_HZ, "the thesis flew down to 1 Hz (Ch. 11.1); Vicon cameras "
        "stream at most ~2000 Hz")] = 100.0  # thesis lab streamed 100 Hz (App. B)
    min_rate_hz: Annotated[float, within(
        0.0, VICON_RATE_MAX_HZ, "Vicon cameras stream at most ~2000 Hz",
        lo_open=True)] = 8.0  # warn below: the thesis flew at 10 Hz (Ch. 11.1)
    max_speed_m_s: Annotated[float, within(
        0.0, 50.0, "an outlier gate [m/s] (spec: 'a few m/s'); at 50 m/s it lets a pose "
        "cross the lab in one 100 Hz frame and gates nothing", lo_open=True)] = 5.0
    max_rotation_rate_rad_s: Annotated[float, within(
        0.0, 200.0, "an outlier gate [rad/s] (spec: 'tens of rad/s'); 200 rad/s is 32 turns "
        "a second, beyond any quadrotor", lo_open=True)] = 30.0
    restart_silence_s: Annotated[float, within(
        0.0, 60.0, "a longer silence is a Tracker restart (spec); the flight has landed on "
        "Vicon loss (safety.vicon_loss_land_s <= 30 s) long before a minute",
        lo_open=True)] = 1.0
    restart_backjump_frames: Annotated[int, within(
        1, 1_000_000, "frames [-]: a larger backward jump is a Tracker restart; 10^6 "
        "frames is 2.8 h at 100 Hz, beyond any reordering")] = 1000
    plausibility_margin_m: Annotated[float, within(
        0.0, LAB_EXTENT_M, "a margin beyond LAB_EXTENT_M accepts any pose [m]")] = 0.5
    # [m] a pose further than this outside safety.volume_x/y/z is refused as impossible
    #. The supervisor lands at the volume's edge; braking from the fastest
    # reference (safety.max_speed_m_s, 1.5 m/s) at the 35 deg tilt limit takes 0.16 m,
    # and the cameras see a little beyond the volume (Table B.1): 0.5 m covers both
    reanchor_poses: Annotated[int, within(
        2, 100, "poses [-]: never one (a stray pose); 100 is 10 s at 10 Hz, longer than "
        "Vicon may be lost before the flight lands")] = 3
    # consistent poses in a row before a pose stream is believed: at start-up, after a
    # gap, for a new stream, and before the estimator re-anchors on poses it gated (never
    # one pose). 3: 20 ms late at 100 Hz, 0.2 s at 10 Hz; one stray pose is not enough,
    # and a chance agreement of three is as unlikely as the gate allows
    source: Literal["udp", "zenoh"] = "udp"
    # where the object's datagrams come from: "udp", Tracker's stream on bind_address:port;
    # "zenoh", the fleet's `gs vicon-relay`, which receives that stream once for every
    # vehicle (key <fleet.name>/vicon/<object_name>; needs the fleet: section). Either
    # way the same pose filter, latency model and failsafes (groundstation/fleet)

    @field_validator("object_name")
    @classmethod
    def _printable(cls, value: str) -> str:
        if not value.isprintable():
            raise ValueError("holds a control character: Tracker's names are printable "
                             "text, NUL-padded on the wire (spec), so it would never match")
        return value

    @model_validator(mode="after")
    def _rates(self) -> ViconConfig:
        if self.min_rate_hz > self.expected_rate_hz:
            raise ValueError("min_rate_hz must not exceed expected_rate_hz")
        return self



