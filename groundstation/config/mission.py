"""What is flown and within which limits: the ``trajectory`` section (thesis Ch. 11) and
the ``safety`` section (the volume, the limits and the failsafes the supervisor keeps)."""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field, field_validator, model_validator

from groundstation.config.base import ConfigModel
from groundstation.config.ranges import (
    FLIGHT_MAX_S,
    LAB_EXTENT_M,
    FilePath,
    LabCoordinate,
    LabLength,
    LapTime,
    Speed,
    TiltDeg,
    TurnDeg,
    within,
)
from groundstation.model.sensors import GRAVITY_CHECK_DEG

TrajectoryName = Literal[
    "hover", "step-x", "step-y", "step-z", "square", "yz-rectangle", "low-hover",
    "figure-eight", "yaw-turn", "waypoints", "sysid", "none",
]
# sysid: the identification flight (doublets on each rate stick, climbs and descents;
# groundstation/control/excitation.py), at center, heading yaw_deg (null: north)


class TrajectoryConfig(ConfigModel):
    """The trajectory flown after take-off (thesis Ch. 11)."""

    name: TrajectoryName = "square"
    center: list[LabCoordinate] = Field(default_factory=lambda: [0.0, 0.0, -1.0],
                                        min_length=3, max_length=3)
    # hover point / square centre, NED [m]: 1 m above the floor as Ch. 11.1 and 11.3;
    # in the lab's frame (from Tracker's origin on the floor), not from the take-off
    # point: a flight climbs above where it stands, then flies here (docs/lab-setup.md)
    size_m: LabLength = 0.75  # square side, Ch. 11.3 (0.75 m x 0.75 m)
    period_s: LapTime = 20.0  # one lap, Ch. 11.3
    step_m: LabLength = 0.5  # step amplitude for step-x/y/z, tuned to stay in the volume
    low_height_m: LabLength = 0.02  # low-hover height, Ch. 11.4 (2 cm)
    corner_smoothing_s: Annotated[float, within(
        0.0, FLIGHT_MAX_S, "s: no longer than the longest lap (FLIGHT_MAX_S)")] = 0.0
    # 0 = sharp corners as in the thesis
    file: FilePath | None = None
    # for name 'waypoints': a waypoint CSV (t, x, y, z[, yaw]) or a uav_trajectories /
    # Crazyswarm polynomial file (Duration,x^0,...), told apart by the header (README)
    yaw_deg: TurnDeg | None = None
    # heading to fly at [deg from north]; null keeps the heading the vehicle was placed at
    # (a waypoint CSV's yaw column, when present, gives the heading instead)
    yaw_turn_deg: Annotated[float, within(
        -3600.0, 3600.0, "deg: at most ten turns either way in one lap")] = 360.0
    # 'yaw-turn': turn this far over period_s, holding position
    shaping: Literal["min-jerk", "none"] = "min-jerk"
    # min-jerk: make the reference flyable before flight (start and stop at rest, corners
    # and velocity steps blended within the safety limits, path through the corners);
    # none: the thesis's raw reference (sharp corners), for the Ch. 11 comparison
    polynomial_positions: Literal["relative", "absolute"] = "relative"
    # a polynomial file's positions: relative to its start, which is placed at center (as
    # the Crazyflie's start_trajectory(relative=True)), or absolute lab coordinates

    @model_validator(mode="after")
    def _file(self) -> TrajectoryConfig:
        if self.name == "waypoints" and self.file is None:
            raise ValueError("trajectory 'waypoints' needs 'file'")
        return self


class SafetyConfig(ConfigModel):
    """Limits and failsafe times the supervisor enforces."""

    volume_x: tuple[LabCoordinate, LabCoordinate] = (-1.5, 1.5)  # Table B.1 tracked volume [m]
    volume_y: tuple[LabCoordinate, LabCoordinate] = (-1.5, 1.5)  # Table B.1
    volume_z: tuple[LabCoordinate, LabCoordinate] = (-2.0, 0.05)
    # Table B.1 height 0..2 m, NED (z up is -)
    max_tilt_deg: TiltDeg = 35.0  # beyond this Vicon tracking is unreliable; tuned
    handback_tilt_deg: Annotated[float, within(0.0, 180.0, "deg: a tilt is at most 180",
                                               lo_open=True)] = 60.0
    # a landing that tilts this far has lost the attitude (the controller that tripped
    # max_tilt_deg is still flying): hand back to the pilot at once
    # The failsafe times are bounded: a finite but huge value would switch the failsafe off.
    vicon_loss_hold_s: Annotated[float, within(
        0.0, 5.0, "s: the IMU alone drifts; a hold on it longer than 5 s flies blind",
        lo_open=True)] = 0.5
    # hold on the IMU estimate after this (PX4 figure); at most 5 s: the IMU alone drifts
    vicon_loss_land_s: Annotated[float, within(
        0.0, 30.0, "s: the landing on the IMU alone must begin within 30 s",
        lo_open=True)] = 2.0  # land if Vicon has not returned
    link_loss_s: Annotated[float, within(
        0.0, 2.0, "s: the vehicle's own watchdog is 100 ms; at 2 s a lost link goes "
        "unnoticed for 200 DATA frames", lo_open=True)] = 0.3
    # no DATA this long = link lost; at most 2 s (the vehicle's own watchdog is 100 ms)
    takeoff_speed_m_s: Speed = 0.5  # climb rate for take-off, tuned
    land_speed_m_s: Speed = 0.3  # descent rate when landing, tuned
    takeoff_land_accel_m_s2: Annotated[float, within(
        0.0, 5.0, "m/s^2: half a g asks the rotors for half the hover thrust again, "
        "more than a take-off needs", lo_open=True)] = 0.5
    # acceleration limit of the take-off's and the landing's moves (thesis silent; gs eval's
    # figures are flown at 0.5): a move lasts as long as its mean speed says, or longer if
    # this limit asks for it (a 1 m climb: 3.4 s at 0.5 m/s^2, 2.5 s at 1); the jerk is
    # limited to 4 per second of it
    preflight_timeout_s: Annotated[float, within(
        0.0, 600.0, "s: ten minutes of preflight is a hung check", lo_open=True)] = 10.0
    # give up if checks do not pass
    takeoff_timeout_s: Annotated[float, within(
        0.0, 300.0, "s: a take-off not done in five minutes is a stuck one",
        lo_open=True)] = 20.0
    # land if the take-off has not reached the trajectory's start in this time (a 1 m
    # climb at 0.5 m/s takes ~4 s after the 1 s handover blend); tuned
    trajectory_tilt_deg: TiltDeg = 20.0
    # most tilt a reference may ask for; the rest of max_tilt_deg is left to the feedback
    max_speed_m_s: Speed = 1.5  # fastest reference speed accepted [m/s]
    max_yaw_rate_deg_s: Annotated[float, within(
        0.0, 3600.0, "deg/s: ten turns a second, beyond any quadrotor's yaw authority",
        lo_open=True)] = 90.0  # fastest heading change of a reference, tuned
    volume_margin_m: Annotated[float, within(0.0, LAB_EXTENT_M, "m: within a lab "
                                             "(LAB_EXTENT_M)")] = 0.1
    # a reference must stay this far inside volume_x/y/z (tracking error, braking room)
    gravity_check_deg: Annotated[float, within(
        0.0, 180.0, "deg: an angle between two directions is at most 180",
        lo_open=True)] = GRAVITY_CHECK_DEG
    # [deg] preflight: the accelerometer's gravity must agree with the Vicon attitude
    on_signal: Literal["land", "handback"] = "land"  # what SIGINT/SIGTERM does
    on_geofence: Literal["handback", "land"] = "handback"
    # what leaving the volume does (the estimate or Vicon outside safety.volume_x/y/z):
    # hand back to the pilot at once by default, as PX4's geofence "return to the pilot"
    # action: a vehicle that left the volume is beyond what the controller was trusted with
    on_overruled: Literal["handback", "land"] = "handback"
    # what an estimate proven wrong does (Vicon poses that agree with each other re-anchored
    # it: a thrust fault or a knock the IMU could not measure): hand back at once, or land
    # on the re-anchored estimate (a forged stream that outlived the real one would then
    # fly the landing)
    on_second_stream: Literal["land", "hold"] = "land"
    # what a second Vicon pose stream for our object does (another sender, a misconfigured
    # Tracker): land, or hold position until it stops (landing if it lasts vicon_loss_land_s)
    landing_confirm_s: Annotated[float, within(
        0.0, 30.0, "s: the landing creeps down at 0.15 m/s meanwhile; in 30 s that is "
        "4.5 m, more than the lab is high", lo_open=True)] = 5.0
    # a landing whose estimate reached the floor without evidence (Vicon, or the
    # accelerometer's floor contact) for this long hands back with thrust at hover [s]:
    # the landing creeps on down at 0.15 m/s meanwhile, 0.75 m, more than the
    # supervisor's contact_height_m of dead-reckoning drift
    second_signal_after_s: Annotated[float, within(
        0.0, 10.0, "s: a signal 10 s after the first is a new request, never the same one")] = 0.5
    # a second SIGINT/SIGTERM hands back at once only this long after the first [s];
    # closer ones are the same request: GNU `timeout` signals the process and then its
    # group within ~1 ms, and a person pressing Ctrl-C twice on purpose takes
    # longer than half a second
    battery_land_v: Annotated[float, within(
        0.0, 65.535, "V: the X-3D's STATUS carries the voltage as uint16 mV (spec section "
        "3.3)", lo_open=True)] | None = 10.5
    # land when the battery the X-3D reports (STATUS) stays below this [V]; 10.5 V is a
    # 3S LiPo at 3.5 V a cell, ArduPilot's copter default (BATT_LOW_VOLT); also refuses a
    # take-off. null: no battery failsafe (a vehicle without the STATUS block)
    battery_grace_s: Annotated[float, within(
        0.0, 120.0, "s: two minutes below the landing voltage drains a LiPo",
        lo_open=True)] = 10.0
    # ... for this long without a sample above it [s]: a voltage sag under load is not an
    # empty battery (ArduPilot's BATT_LOW_TIMER default, 10 s)

    @field_validator("volume_x", "volume_y", "volume_z")
    @classmethod
    def _ordered(cls, value: tuple[float, float]) -> tuple[float, float]:
        if not value[0] < value[1]:
            raise ValueError("volume bounds must be (min, max) with min < max")
        return value

    @model_validator(mode="after")
    def _order(self) -> SafetyConfig:
        if self.handback_tilt_deg <= self.max_tilt_deg:
            raise ValueError("handback_tilt_deg must exceed max_tilt_deg")
        if self.vicon_loss_land_s < self.vicon_loss_hold_s:
            raise ValueError("vicon_loss_land_s must not be shorter than vicon_loss_hold_s")
        return self


