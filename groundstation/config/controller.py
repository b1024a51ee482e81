"""Which controller flies and how it is tuned: the ``controller`` section (the thesis's
LQR with its reference models, Ch. 9; PID, Ch. 8; H-infinity, Ch. 10; the feed-forward
LQR and its external-force estimate, beyond the thesis)."""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field, model_validator

from groundstation.config.base import ConfigModel
from groundstation.config.ranges import (
    FilePath,
    IntegralLimit,
    IntegralWeights4,
    LoopGain,
    LoopRate,
    TiltDeg,
    VelocityGain,
    Weight,
    Weights4,
    within,
)

ControllerType = Literal["lqr-ff", "lqr-cv", "lqr-cp", "pid", "hinf"]
"""The controllers ``controller.type`` names (``gs fly --controller`` offers the same)."""


class LqrConfig(ConfigModel):
    """LQR with a reference model (thesis Ch. 9). Weights on the error e = r - y."""

    q_error: Weights4 = Field(default_factory=lambda: [8.0, 8.0, 20.0, 2.0])
    # Q_e on [x, y, z, q3] errors (eq. 9.18) [1/m^2, -]; tuned for ~0.2 Hz x/y as Ch. 11.2
    r_input: Weights4 = Field(default_factory=lambda: [4.0, 4.0, 4.0, 2.0])
    # R on [omega_x, omega_y, omega_z, F_z] [1/(rad/s)^2, 1/N^2]: the body-rate form of
    # eq. 4.31's input (sticks = omega / K), tuned
    q_integral: IntegralWeights4 | None = None
    # weights on the integrated [x, y, z, q3] errors; None = no integrators (the
    # disturbance observer below already removes the steady-state error)
    integral_limit: IntegralLimit = 2.0
    # anti-windup clamp on each integrated error [m s]; 0.5 saturated under a 10 % thrust
    # error in the virtual lab (tests/test_control_disturbance.py)
    disturbance_tau_s: Annotated[float, within(
        0.0, 100.0, "s: an observer slower than 100 s (five 20 s laps) removes nothing "
        "within a flight", lo_open=True)] | None = 1.0
    # constant-disturbance observer time constant; beyond the thesis: zero steady-state
    # error under thrust error, droop, wrong mass or accelerometer bias
    velocity_source: Literal["reference", "samples"] = "reference"
    # constant-velocity model: the trajectory's own velocity, or filtered sample
    # differences as the thesis did (eq. 9.22-9.26)
    velocity_filter: Annotated[float, within(
        0.0, 1.0, "a weight of the previous velocity: at 1 the velocity never changes",
        hi_open=True)] = 0.5
    # weight of the previous velocity when velocity_source is "samples", tuned
    design_model: Literal["rate-loop", "thesis"] = "rate-loop"
    # rate-loop: design on the hover model with the rate-loop lag and the command delay
    # (vehicle section), as the thesis concludes it must (Ch. 10.3, 12); thesis: its
    # ideal-rate-loop model (Ch. 9)


class PidConfig(ConfigModel):
    """Cascaded position/velocity/attitude PID (thesis Ch. 8 baseline)."""

    position_kp: list[LoopGain] = Field(default_factory=lambda: [0.8, 0.8, 1.2],
                                        min_length=3, max_length=3)  # [1/s], tuned
    velocity_kp: list[VelocityGain] = Field(default_factory=lambda: [0.25, 0.25, 4.0],
                                            min_length=3, max_length=3)
    # x/y: rad tilt per m/s; z: N per m/s; tuned
    velocity_ki: list[VelocityGain] = Field(default_factory=lambda: [0.05, 0.05, 1.5],
                                            min_length=3, max_length=3)  # tuned
    velocity_kd: list[VelocityGain] = Field(default_factory=lambda: [0.0, 0.0, 0.0],
                                            min_length=3, max_length=3)  # tuned
    attitude_kp: list[LoopGain] = Field(default_factory=lambda: [4.0, 4.0, 2.0],
                                        min_length=3, max_length=3)
    # rate set point per rad of attitude error [1/s], tuned
    max_tilt_deg: TiltDeg = 20.0  # tilt command limit, tuned


class HinfConfig(ConfigModel):
    """H-infinity controller (thesis Ch. 10): the loop uses a stored gain."""

    gain_file: FilePath | None = None
    # a gain written by `gs synth hinf`; None = the packaged design selected below
    include_rate_loop: bool = True
    # design on the model with the rate-loop lag (Ch. 10.3): the thesis's model without
    # it gave a controller that did not stabilise the real vehicle
    # The packaged rate-loop gain is robust and has integral action (control/hinf.py):
    # the weights below are what `gs synth hinf` designs a new gain with
    epsilon: Weight = 0.1  # D12 input weight (eq. 10.5), tuned
    reference_pole: LoopRate = 1.0  # a_i of W_r (eq. 10.10) [rad/s], tuned
    noise_gain: Weight = 0.01  # k of W_n (eq. 10.9), tuned
    integral_scale: IntegralWeights4 | None = Field(
        default_factory=lambda: [0.3, 0.3, 1.0, 0.1])
    # weights of the integrated [x, y, z, q3] errors (beyond the thesis: zero steady-state
    # error under a thrust-map error); null: the thesis's design, no integrators
    robust_range: Annotated[float, within(
        0.0, 1.0, "a fraction: at 1 a rate gain or the thrust could be zero",
        hi_open=True)] = 0.3
    # design for rate gains, rate-loop time constant and thrust per newton within +- this
    # fraction (30 %: the spread `gs eval --perturb` draws); 0 = the nominal plant only,
    # as the thesis
    pole_radius_rad_s: LoopRate | None = 12.0
    # keep the closed-loop poles in this disc: no loop faster than the 50 Hz, ~40 ms
    # delayed command link carries; null = unconstrained, as the thesis
    min_decay_per_s: LoopRate | None = 0.6
    # and left of -min_decay: no loop slower (tuned on `gs eval --perturb`; must stay
    # below reference_pole); null = unconstrained, as the thesis
    integral_limit: IntegralLimit = 2.0  # anti-windup clamp on each integrated error [m s]


class ExternalForceConfig(ConfigModel):
    """The external force from the accelerometer (control/external_force.py): the specific
    force measured against the lift the COMMANDs sent predict, cancelled by the controller
    (INDI's correction as a disturbance observer; beyond the thesis)."""

    enabled: bool = True
    # false: the integrators alone reject disturbances (as before)
    fast_jerk_m_s4: Annotated[float, within(
        0.0, 1000.0, "m/s^4: the rate noise of a filter; at 1000 it passes the noise",
        lo_open=True)] = 10.0
    # the vertical alpha-beta filter (4.0 Hz): the loop it closes through a mispredicted
    # lift stays below 1 (small gain) for lift 0.74-1.35 x the model, delay +-15 ms
    horizontal_jerk_m_s4: Annotated[float, within(
        0.0, 1000.0, "m/s^4: the rate noise of a filter; at 1000 it passes the noise",
        lo_open=True)] = 600.0
    # the fast horizontal alpha-beta filter, on while a horizontal disturbance moves
    quiet_tau_s: Annotated[float, within(
        0.002, 60.0, "s: from a fifth of the fastest command period to a minute (the "
        "integrators' job)")] = 2.0
    # the horizontal estimate while nothing moves (0.08 Hz): below the position loop's 0.4 Hz
    # mode, where the accelerometer's noise (vehicle.acc_variance) would add to the hover
    detect_sigmas: Annotated[float, within(
        2.0, 20.0, "innovation standard deviations: below 2 the noise switches the fast "
        "filter on all the time, above 20 a payload would go unseen")] = 4.0
    # a change is detected beyond this many standard deviations of the noise (Gaussian:
    # a false switch every ~80 s, each 0.5 s of the fast filter)
    hold_s: Annotated[float, within(
        0.0, 10.0, "s: the fast filter's noise for longer than 10 s is the quiet one's job")] \
        = 0.5
    # the fast filter stays on this long after the last detection
    vertical_lead_s: Annotated[float, within(
        0.0, 1.0, "s: a lead longer than a second extrapolates noise, not a disturbance")] \
        = 0.07
    # the thrust takes the vertical estimate this far ahead (estimate + lead x rate): the
    # input delay, the motors' lag and the loop's response; tuned on gs eval --perturb
    motor_tau_s: Annotated[float, within(
        0.0, 1.0, "s: motors slower than a second could not hold a hover")] = 0.08
    # the lift's lag behind the command in the prediction: the slow end of what the vehicle
    # may be (its motors, 20 ms nominal, plus any COMMAND delay beyond
    # vehicle.command_delay_s), never faster: a prediction that leads the true lift lets the
    # vertical loop run away; 80 ms covers motors up to 50 ms and 25 ms of extra delay
    effectiveness_tau_s: Annotated[float, within(
        0.0, 60.0, "s: over a minute a payload is never learnt; 0 turns it off")] = 1.0
    # the lift per newton asked, against the model's (a payload or a thrust map that is off
    # lowers it), from the lift predicted and the specific force low-passed over this time;
    # where it is below the model's the prediction scales the command's own changes by it,
    # or the estimate feeds the shortfall back and the vertical loop rings (payload in
    # hover, worst of 5: back within 1 cm in 0.72 s, 1.42 s with 0)
    min_height_m: Annotated[float, within(
        0.0, 1.0, "m: above a metre the estimate would never learn in a lab")] = 0.01
    # learns only this far above where the vehicle stood at take-off: below, the floor's
    # contact force may act, and cancelling it winds up like an integrator
    limit_m_s2: Annotated[float, within(
        0.0, 14.0, "m/s^2: the accelerometer's range (vehicle.acc_saturation)",
        lo_open=True)] = 8.0
    # clamp per axis: 0.8 g, what a +20 % payload asks on a vehicle whose mass and thrust
    # map are 15 % off the model and whose battery has lost 10 % (1.2 x 1.15 / 0.85 / 0.9)


class LqrFfConfig(ConfigModel):
    """LQR with the feed-forward reference model (beyond the thesis, control/lqr_ff.py),
    designed on the vehicle with its rate loop and command delay. Weights on e = x - x_ref."""

    q_error: Weights4 = Field(default_factory=lambda: [100.0, 100.0, 300.0, 20.0])
    # Q_e on [x, y, z, q3] errors [1/m^2, -]: ~0.8 Hz horizontal bandwidth; tuned for the
    # worst case of `gs eval --perturb` (rate gains +-30 %, tau +-30 %, delay 5-30 ms); z
    # 300: a +20 % payload peaks 2.3 cm (100: 2.6); 1000 lost the vertical loop with the
    # external-force estimate on the corner plant (lift 1.35 x the model, delay 30 ms)
    r_input: Weights4 = Field(default_factory=lambda: [1.0, 1.0, 1.0, 0.5])
    # R on [omega_x, omega_y, omega_z, F_z] [1/(rad/s)^2, 1/N^2], tuned with q_error
    q_integral: IntegralWeights4 = Field(default_factory=lambda: [20.0, 20.0, 60.0, 2.0])
    # weights on the integrated [x, y, z, q3] errors: zero steady-state error under a
    # thrust-map error, a wrong mass or battery droop; 0 turns one off. z is
    # weighted 3x: with mass and thrust map 15 % off, 20 left a 2 cm take-off tail in TRACK
    integral_limit: IntegralLimit = 2.0  # anti-windup clamp on each integrated error [m s]
    external_force: ExternalForceConfig = ExternalForceConfig()
    # cancel the external force the accelerometer measures (payload, wind, drag, ground
    # effect, a sagging battery) within ~0.1 s; the integrators keep what remains


class ControllerConfig(ConfigModel):
    """Which controller flies and how it is tuned. Every controller is designed at the
    command period (1 / serial.command_rate_hz) and steps once per COMMAND."""

    type: ControllerType = "lqr-ff"
    # lqr-ff: feed-forward reference model (beyond the thesis; best in `gs eval`);
    # lqr-cv / lqr-cp: the thesis's constant-velocity / constant-position models (Ch. 9, 11)
    lqr_ff: LqrFfConfig = LqrFfConfig()
    lqr: LqrConfig = LqrConfig()
    pid: PidConfig = PidConfig()
    hinf: HinfConfig = HinfConfig()

    @model_validator(mode="after")
    def _hinf_gain(self) -> ControllerConfig:
        gain = self.hinf.gain_file
        if self.type == "hinf" and gain is not None and not gain.is_file():
            raise ValueError(f"hinf.gain_file {str(gain)!r} does not exist (see `gs synth hinf`)")
        return self


