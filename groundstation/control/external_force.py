"""External force from the accelerometer: what the vehicle measures against what it was told.

Beyond the thesis. The integral action of ``lqr-ff`` and the constant-disturbance observer
of ``lqr-cp``/``lqr-cv`` (:mod:`.disturbance`) remove constant errors in seconds; a payload
picked up, a gust or a battery losing lift in flight act at once (a +20 % payload sank the
vehicle 7.5-10.6 cm, a 1 s, 4 m/s gust pushed it 12-16 cm: ``gs eval --perturb 1-5``).
The accelerometer shows such a force within one sample: it measures the specific force
``f`` (non-gravitational force / m, body FRD), and the model predicts it from what was
sent. Their difference is the external acceleration ``d`` in

    v_dot = f_model + g_b - omega x v + d,        f_model = (L + I_i v_3) / m e_3

(eq. 3.21 with ``L`` the rotor lift: the thrust map's force for the COMMAND sent, after
the command delay and the motors' lag). A heavier vehicle, wind, drag, ground effect, a
thrust map that is off and a battery that sags all appear in ``d``; the controller
subtracts it from the acceleration it asks of the vehicle (the tilt and the vertical
force), which is incremental nonlinear dynamic inversion's correction (Smeur, de Croon and
Chu, "Cascaded incremental nonlinear dynamic inversion for MAV disturbance rejection",
Control Engineering Practice 73, 2018; Agilicious's INDI) written as a disturbance
observer: INDI's ``u = u_f + G^-1 (nu - a_f)``, with the measured acceleration ``a_f`` and
the applied input ``u_f`` passed through the same filter, is ``G^-1 nu - G^-1 d_f`` with
``d_f`` the filtered difference computed here (the same filter on both is what keeps the
lag honest: they are compared at the same instants). The integral action stays for what the
estimate gets wrong (an accelerometer bias the EKF has not learnt, the scale error at
other thrusts).

**The lift model.** The command sent at step ``k`` reaches the rotors ``D`` later (the
design model's input delay, :mod:`.augmented`: the age of the IMU sample plus the
COMMAND's travel), and the lift follows it as a first-order lag ``tau_m``. With
``D = (l - 1) T + m`` (``T`` the command period, ``0 < m <= T``) the lift at the sample
instants obeys exactly (zero-order hold, Åström and Wittenmark Ch. 2.3)::

    L(k + 1) = a L(k) + b_0 u(k - l) + b_1 u(k - l + 1)
    a = exp(-T / tau_m),  b_1 = 1 - exp(-(T - m) / tau_m),  b_0 = 1 - a - b_1

(``u`` the lift sent: ``F_z - m g``), so ``L(k)`` is the lift the accelerometer sample of
step ``k`` felt, had the vehicle been the model.

**Filters, bandwidth and noise** (figures for Table 6.3's accelerometer noise, 0.068,
0.051, 0.059 m/s^2 per sample, read at the 50 Hz command rate; the horizontal axes take
the larger, the heading mixes them; :mod:`.tracking_filter` gives them in closed form).
``d`` is estimated in earth axes, where a payload's weight and the wind stay put while the
vehicle turns, with its rate (alpha-beta filters: a ramp is followed without lag):

* vertical: one alpha-beta filter, ``sqrt(q)`` = 10 m/s^4: alpha 0.31, beta 0.056, -3 dB at
  24.8 rad/s (4.0 Hz); the accelerometer's noise leaves 0.029 m/s^2 on the estimate (18 mN,
  0.3 % of the weight) and 0.23 m/s^3 on its rate;
* horizontal, while nothing moves: a first-order low-pass of 2 s (-3 dB at 0.5 rad/s,
  0.08 Hz; 0.005 m/s^2). A fast estimate there feeds the accelerometer's noise back at
  the horizontal position loop's 0.4 Hz mode: measured, 0.1 cm more hover error;
* horizontal, while a disturbance moves: an alpha-beta filter, ``sqrt(q)`` = 600 m/s^4
  (alpha 0.92, beta 1.02, no -3 dB point below Nyquist: nearly the samples themselves,
  0.063 m/s^2 of noise on the value and 4.7 m/s^3 on the rate, 0.48 rad/s of tilt rate fed
  forward while it is on: the price of following a gust), switched on when one
  innovation of the quiet estimate passes 4 standard deviations of the noise
  (0.27 m/s^2), or the mean of the last 8 passes 4 of the mean's (0.096 m/s^2): for
  Gaussian noise a false switch every ~80 s, each 0.5 s of the fast filter's noise; a
  4 m/s gust is seen 0.17 s after it begins. The fast filter stays on 0.5 s after the
  last detection, then hands back to the quiet one started from the mean of the last 16
  samples.

The controller (``lqr-ff``) asks the vehicle for the reference's acceleration less ``d``
(the tilt and the vertical force) and for the reference's jerk less ``d``'s rate (the body
rates fed forward); the thrust, which acts after the input delay and the motors' lag, takes
the vertical estimate ``vertical_lead_s`` = 70 ms ahead (``d + 0.07 d_dot``).

**The loop through the estimate.** A lift the model mispredicts returns in ``d`` and is
subtracted from the next command: the vertical loop gains a path
``(P_true(s) / P_model(s) - 1) F(s)`` with ``F`` the estimate taken ahead
(``H_d + lead H_r``) and ``P`` the lift per newton asked, after the delay and the motors.
In size (thrust map and mass 15 % off: ``P_true / P_model`` 0.74-1.35) this is what
corrects a wrong thrust map within a tenth of a second. In time it decides stability:

* a prediction that *lags* the true lift (``motor_tau_s`` longer than the motors, the delay
  no shorter than the COMMAND's) sees the controller's own change of thrust arrive early,
  as an upward ``d``, and takes it back: the path opposes the command's transient;
* one that *leads* it sees the change late, as a downward ``d``, and adds to it: the path
  piles onto the vertical loop's own lag. With the prediction at the nominal 20 ms, motors
  of 35 ms (a COMMAND delay of 30 ms, lift 1.35 x the model) ran away in the take-off, and
  50 ms or a 45 ms delay at either end of the lift; without the estimate the same vehicles
  fly (``gs eval`` plants, +20 % payload).

So the prediction is set at the slow end of what a vehicle may be: ``motor_tau_s`` = 80 ms
(:data:`DEFAULT_MOTOR_TAU_S`), which flies motors of 10-50 ms with COMMAND delays of 5-45 ms
and lift 0.62-1.35 x the model (tests/test_evaluation_disturbances.py, judged by the truth).
The price is in the payload's recovery: the controller's answering thrust arrives before the
prediction says, so ``d`` is underestimated meanwhile (+20 % payload, worst of seeds 1-5
with the lab's motors at 20 ms: peak 2.2 -> 2.9 cm, back within 1 cm in 0.77 -> 1.10 s).
A lab that knows its vehicle's lift lag (motors and delay) may set it closer, never below
it.
The path's small gain in size and pure delay alone (``|((1 + e) e^{-s Delta} - 1) F|``
below 1, 0.72 for lift 0.74-1.35 and a delay 15 ms off, tested) is necessary, not
sufficient: it leaves out the vertical loop the path closes around, and a lead of 0.1 s at
0.83 ran away on the corner vehicle. A faster filter or a longer lead buys a smaller payload
peak and loses stability first. Horizontally the
accelerometer does not see the tilt the controller commands (the thrust turns with the
body): ``d_x, d_y`` leave out the tilted share of the vertical error, so no loop closes
through them; they are the wind and drag alone.

**The lift per newton.** The path's size is the vehicle's lift per newton asked against
the model's, ``k``; a payload lowers it (+20 % mass: ``k / 1.2``), a thrust map that is off
moves it. Where ``k > 1`` the path takes the surplus of the controller's own change back,
a negative feedback that holds on every corner. Where ``k < 1`` it adds the shortfall to
the next command: at low frequencies that is what makes up a weak vehicle's thrust, but
around the vertical loop's 1 Hz it is a positive feedback of ``1 - k`` through the filter's
lag, and the loop rang (thrust map 0.93, mass 1.13, then the payload: ``k`` = 0.69;
+2.9, -2.3, +1.0, -0.9 cm at 1 Hz, back within 1 cm after 1.42 s). So the prediction
takes the lift per newton into account where it is below the model's: with ``L_s`` and
``f_s`` the lift predicted and the vertical specific force measured, both low-passed over
``effectiveness_tau_s`` (1 s), the estimate is ``k_hat = min(f_s m / L_s, 1)`` (at least
0.5; only while ``L_s`` holds at least half the weight: a hover or a climb), and the lift
predicted becomes ``L_s + k_hat (L - L_s)``: unchanged below ``1 / tau``, where ``d`` still
makes up the weak vehicle's thrust, and the command's own change at its true size above
it, where it no longer returns in ``d``. Measured (+20 % payload in hover, worst of seeds
1-5): back within 1 cm in 0.72 s (1.42 s without), peak 3.12 cm (3.03); a time constant of
0.5 s gave 1.17 s and 2 s 0.90 s; letting ``k_hat`` above 1 ran the 1.35 x lift, 95 ms
corner away.

**What it refuses to learn from.** A sample beyond 97 % of the accelerometer's range on any
axis (saturated: ``vehicle.acc_saturation``, Ch. 6.2); a step after a COMMAND that was not
all the controller's own (pilot channels, a handover blend: the lift sent is not the one
modelled); and the vehicle on the floor: the contact force is an external force the
controller cannot cancel (asking for less lift against it winds up like an integrator),
so the estimate learns only ``min_height`` above where the vehicle stood when the
controller was reset (the flight core resets it on the floor at take-off). It then holds
its value. The estimate is clamped to ``limit`` per axis.
"""

from __future__ import annotations

import math
from collections import deque

from groundstation.control.tracking_filter import alpha_beta
from groundstation.errors import ControlError
from groundstation.model import QuadrotorParams
from groundstation.model.sensors import ACC_SATURATION_M_S2, ACC_VARIANCE_TABLE_6_3
from groundstation.types import StateEstimate

DEFAULT_FAST_JERK = 10.0
"""Rate noise ``sqrt(q)`` [m/s^4] of the vertical alpha-beta filter: -3 dB at 4.0 Hz (see
the module docstring for its noise and the small-gain margin it keeps)."""
DEFAULT_HORIZONTAL_JERK = 600.0
"""Rate noise ``sqrt(q)`` [m/s^4] of the fast horizontal filter, on only while a disturbance
moves: nearly the samples themselves and their rate (a 4 m/s gust: 2.3-2.8 cm at 600,
2.9-3.6 cm at 200, 4.4-4.7 cm at 20; ``gs eval --perturb 1-5``)."""
DEFAULT_QUIET_TAU_S = 2.0
"""Time constant [s] of the horizontal estimate while nothing moves: 0.08 Hz, below the
horizontal position loop's 0.4 Hz mode, where the accelerometer's noise fed back through
a fast estimate added 0.1 cm to the still-air hover (measured, ``gs eval --perturb``)."""
DEFAULT_DETECT_SIGMAS = 4.0
"""A horizontal disturbance that moves is detected when one innovation of the quiet
estimate passes this many standard deviations of Table 6.3's noise, or the mean of the
last :data:`DETECT_MEAN_STEPS` passes as many of the mean's: for Gaussian noise 6.3e-5 per
test, axis and step, a false switch every ~80 s at 50 Hz."""
DETECT_MEAN_STEPS = 8
"""Samples in the mean of innovations that detects a slower change (160 ms at 50 Hz)."""
DEFAULT_HOLD_S = 0.5
"""The fast filter stays on this long after the last detection [s]."""
ANCHOR_STEPS = 16
"""When the fast horizontal filter hands back, the quiet estimate starts from the mean of
the last this many samples (0.32 s at 50 Hz: a quarter of the fast value's noise)."""
DEFAULT_VERTICAL_LEAD_S = 0.07
"""How far ahead [s] the thrust takes the vertical estimate: the input delay (31 ms), the
motors' lag (20 ms) and the loop's response to the velocity lost meanwhile; tuned on
``gs eval --perturb`` (+20 % payload in hover, worst of 5 with the lab's motors at 20 ms,
lift predicted 80 ms behind:
2.94 cm and back within 1 cm in 1.10 s at 0.07; 2.63 cm and 1.39 s at 0.1; at 0.04 the
slow corner vehicle of tests/test_evaluation_disturbances.py ran away)."""
DEFAULT_MOTOR_TAU_S = 0.08
"""Lag [s] of the lift behind the command in the prediction: the slow end of what a vehicle
may be, not its nominal 20 ms (thesis silent; the virtual lab's ``sim.motor_tau_s``). A
prediction that lags the true lift is stable, one that leads it is not (module docstring,
"The loop through the estimate"): 80 ms covers motors up to 50 ms with a COMMAND up to
25 ms later than ``vehicle.command_delay_s`` (flown, tests/test_evaluation_disturbances.py)."""
DEFAULT_MIN_HEIGHT_M = 0.01
"""Height above the floor [m] (where the vehicle stood at reset) from which the estimate
learns: below it the floor's contact force may be acting; the EKF's height is good to a
millimetre."""
DEFAULT_LIMIT_M_S2 = 8.0
"""Clamp on each axis of the estimate [m/s^2]: 0.8 g, what a +20 % payload asks of a vehicle
whose mass and thrust map are 15 % off the model and whose battery has lost 10 %."""
DEFAULT_EFFECTIVENESS_TAU_S = 1.0
"""Time constant [s] over which the lift predicted and the specific force measured are
compared for the lift per newton (module docstring, "The lift per newton"): back within
1 cm of a +20 % payload in 0.72 s at 1 s, 1.17 s at 0.5 s, 0.90 s at 2 s (worst of seeds
1-5); 0 leaves the prediction at the model's lift per newton."""
EFFECTIVENESS_MIN = 0.5
"""The lift per newton is taken as at least this fraction of the model's [-]: half the
lift is a vehicle that cannot hover, not one to model."""
EFFECTIVENESS_MIN_LIFT = 0.5
"""The lift per newton is estimated only while the low-passed lift predicted holds at
least this fraction of the weight [-] (a hover or a climb; a landing's low thrust says
little about it)."""
SATURATION_MARGIN = 0.97
"""A raw accelerometer reading beyond this fraction of its range counts as saturated."""


class ExternalForceObserver:
    """The external acceleration ``d`` [m/s^2, NED] and its rate from the accelerometer
    (see the module docstring).

    params : the vehicle model (mass, g, inflow, thrust map through ``F_z``, ``input_delay``)
    period : the command period [s]: :meth:`update` once per COMMAND, before the step's
        output, and :meth:`sent` after it
    fast_jerk : the fast filters' rate noise ``sqrt(q)`` [m/s^4]; quiet_tau_s : the quiet
        horizontal estimate's time constant [s]
    detect_sigmas : detection threshold [standard deviations]; hold_s : how long the fast
        horizontal filter stays on after a detection [s]
    motor_tau_s : the lift's lag [s] (0: none); delay_s : the input delay [s] (default
        ``params.input_delay``)
    effectiveness_tau_s : time constant [s] of the lift-per-newton estimate (0: none)
    min_height_m : learns only this far above the floor [m]; limit_m_s2 : clamp per axis
    acc_variance : the accelerometer's noise per sample per body axis [(m/s^2)^2]
        (Table 6.3); acc_saturation : its range [m/s^2] (Ch. 6.2)
    """

    def __init__(self, params: QuadrotorParams, period: float, *,
                 fast_jerk: float = DEFAULT_FAST_JERK,
                 horizontal_jerk: float = DEFAULT_HORIZONTAL_JERK,
                 quiet_tau_s: float = DEFAULT_QUIET_TAU_S,
                 detect_sigmas: float = DEFAULT_DETECT_SIGMAS, hold_s: float = DEFAULT_HOLD_S,
                 vertical_lead_s: float = DEFAULT_VERTICAL_LEAD_S,
                 motor_tau_s: float = DEFAULT_MOTOR_TAU_S, delay_s: float | None = None,
                 effectiveness_tau_s: float = DEFAULT_EFFECTIVENESS_TAU_S,
                 min_height_m: float = DEFAULT_MIN_HEIGHT_M,
                 limit_m_s2: float = DEFAULT_LIMIT_M_S2,
                 acc_variance: tuple[float, float, float] = ACC_VARIANCE_TABLE_6_3,
                 acc_saturation: float = ACC_SATURATION_M_S2) -> None:
        delay = params.input_delay if delay_s is None else delay_s
        if not (period > 0.0 and fast_jerk > 0.0 and horizontal_jerk > 0.0
                and quiet_tau_s >= period
                and detect_sigmas > 0.0 and hold_s >= 0.0 and vertical_lead_s >= 0.0
                and motor_tau_s >= 0.0 and effectiveness_tau_s >= 0.0
                and delay >= 0.0 and min_height_m >= 0.0 and limit_m_s2 > 0.0
                and acc_saturation > 0.0 and min(acc_variance) > 0.0):
            raise ControlError(
                "external force observer: need period > 0, fast_jerk > 0, quiet_tau_s >= "
                "period, detect_sigmas > 0, hold_s, vertical_lead_s, motor_tau_s, "
                "effectiveness_tau_s, delay and min_height_m >= 0, limit, acc_saturation and "
                "acc_variance > 0; found "
                f"{period!r}, {fast_jerk!r}, {quiet_tau_s!r}, {detect_sigmas!r}, {hold_s!r}, "
                f"{vertical_lead_s!r}, {motor_tau_s!r}, {effectiveness_tau_s!r}, {delay!r}, "
                f"{min_height_m!r}, {limit_m_s2!r}, "
                f"{acc_saturation!r}, {acc_variance!r}")
        self.params = params
        self.period = period
        self.vertical_lead_s = vertical_lead_s
        """How far ahead [s] a controller should take the vertical estimate
        (``estimate + vertical_lead_s * rate``) for the thrust it sends now."""
        # earth axes: the heading mixes body x and y, so they take the larger noise
        sig_h = math.sqrt(max(acc_variance[0], acc_variance[1]))
        sig_z = math.sqrt(acc_variance[2])
        self.fast = (alpha_beta(horizontal_jerk, sig_h, period),
                     alpha_beta(fast_jerk, sig_z, period))
        """The fast filters (horizontal, vertical): :class:`.tracking_filter.AlphaBeta`."""
        self.quiet_alpha = -math.expm1(-period / quiet_tau_s)
        """The quiet horizontal estimate's gain per step (a first-order low-pass)."""
        self._gains = [(f.alpha, f.beta / period) for f in (self.fast[0], self.fast[0],
                                                             self.fast[1])]
        # the quiet estimate's innovation: the sample's noise plus the estimate's own
        quiet_sd = sig_h * math.sqrt(1.0 + self.quiet_alpha / (2.0 - self.quiet_alpha))
        self._one = detect_sigmas * quiet_sd
        self._mean = detect_sigmas * quiet_sd / math.sqrt(DETECT_MEAN_STEPS)
        self._hold = max(1, round(hold_s / period))
        past = max(1, math.ceil(delay / period - 1e-12))  # l of the module docstring
        m = delay - (past - 1) * period
        if motor_tau_s > 0.0:
            a = math.exp(-period / motor_tau_s)
            b1 = -math.expm1(-(period - m) / motor_tau_s)
        else:
            a, b1 = 0.0, 1.0
        self._lag = (a, 1.0 - a - b1, b1)  # (a, b_0, b_1)
        self._sent: deque[float] = deque([0.0] * (past + 1), maxlen=past + 1)
        self._weight = params.mass * params.g
        self._slow = (-math.expm1(-period / effectiveness_tau_s)
                      if effectiveness_tau_s > 0.0 else 0.0)  # low-pass gain per step
        self._inv_m = 1.0 / params.mass
        self._inflow = params.inflow
        self._min_height = min_height_m
        self._limit = limit_m_s2
        self._saturated = SATURATION_MARGIN * acc_saturation
        self.estimate = [0.0, 0.0, 0.0]
        """The external acceleration, NED [m/s^2] (Python floats)."""
        self.rate = [0.0, 0.0, 0.0]
        """Its rate of change, NED [m/s^3] (Python floats)."""
        self.learning = False
        """Whether the last :meth:`update` learnt (False: it held the estimate)."""
        self.fast_steps = [0, 0]
        """Steps the fast horizontal filter stays on, north and east (0: the quiet one)."""
        self._window = [deque([0.0] * DETECT_MEAN_STEPS, maxlen=DETECT_MEAN_STEPS)
                        for _ in range(2)]
        self._samples = [deque([0.0] * ANCHOR_STEPS, maxlen=ANCHOR_STEPS) for _ in range(2)]
        self._lift = 0.0
        self._automatic = False
        self._floor: float | None = None
        self._slow_lift: float | None = None  # L_s [N]
        self._slow_force = 0.0  # f_s [m/s^2]
        self.effectiveness = 1.0
        """The lift per newton asked, against the model's, that the prediction uses
        (``k_hat`` of the module docstring, in [0.5, 1])."""
        self.reset()

    def reset(self) -> None:
        """Forget everything: the estimate, the lifts sent, the floor (taken again from the
        next estimate: the vehicle stands on it)."""
        self.estimate = [0.0, 0.0, 0.0]
        self.rate = [0.0, 0.0, 0.0]
        self.fast_steps = [0, 0]
        for w in self._window:
            w.extend([0.0] * DETECT_MEAN_STEPS)
        for w in self._samples:
            w.extend([0.0] * ANCHOR_STEPS)
        for k in range(len(self._sent)):
            self._sent[k] = 0.0
        self._lift = 0.0
        self._automatic = False
        self._floor = None
        self.learning = False
        self._slow_lift = None
        self._slow_force = 0.0
        self.effectiveness = 1.0

    @property
    def predicted_lift(self) -> float:
        """The lift [N] (negative up) the model says the rotors gave at the last sample
        :meth:`update` judged (the COMMANDs sent, delayed and lagged)."""
        return self._lift

    def sent(self, f_z: float, automatic: bool) -> None:
        """The vertical force ``F_z = F_lift + m g`` [N] the vehicle was sent this step, and
        whether every channel was the controller's (see ``Controller.sent``)."""
        self._sent.append(f_z - self._weight)
        self._automatic = automatic

    def _lift_predicted(self, force: float) -> float:
        """The lift [N] predicted for this sample with the lift per newton estimated from
        the low-passed lift and specific force ``force`` [m/s^2] (module docstring)."""
        if self._slow == 0.0:
            return self._lift
        if self._slow_lift is None:
            self._slow_lift, self._slow_force = self._lift, force
        self._slow_lift += self._slow * (self._lift - self._slow_lift)
        self._slow_force += self._slow * (force - self._slow_force)
        slow = self._slow_lift
        if slow < -EFFECTIVENESS_MIN_LIFT * self._weight:  # the lift is negative up
            ratio = self._slow_force * self.params.mass / slow
            self.effectiveness = min(max(ratio, EFFECTIVENESS_MIN), 1.0)
        else:
            self.effectiveness = 1.0
        return slow + self.effectiveness * (self._lift - slow)

    def update(self, estimate: StateEstimate) -> list[float]:
        """Advance the lift model one period and, if the sample can be trusted, learn from
        ``estimate.specific_force``; returns :attr:`estimate` (NED [m/s^2])."""
        a, b0, b1 = self._lag
        sent = self._sent
        self._lift = a * self._lift + b0 * sent[0] + b1 * sent[1]
        pz = float(estimate.position[2])
        if self._floor is None:
            self._floor = pz
        fx, fy, fz = estimate.specific_force.tolist()
        bx, by, bz = estimate.acc_bias.tolist()
        sat = self._saturated
        self.learning = (self._automatic and self._floor - pz >= self._min_height
                         and abs(fx + bx) < sat and abs(fy + by) < sat and abs(fz + bz) < sat)
        if not self.learning:  # also refuses NaN: every comparison with it is False
            return self.estimate
        force = fz - self._inflow * float(estimate.velocity_body[2]) * self._inv_m
        dz = force - self._lift_predicted(force) * self._inv_m
        q0, q1, q2, q3 = estimate.quaternion.tolist()
        # d in earth axes: eCb [fx, fy, dz], without the tilted share of dz in the horizontal
        # (see the module doc: it would close a loop through the tilt)
        sample = ((q0 * q0 + q1 * q1 - q2 * q2 - q3 * q3) * fx + 2.0 * (q1 * q2 - q0 * q3) * fy,
                  2.0 * (q1 * q2 + q0 * q3) * fx + (q0 * q0 - q1 * q1 + q2 * q2 - q3 * q3) * fy,
                  2.0 * (q1 * q3 - q0 * q2) * fx + 2.0 * (q2 * q3 + q0 * q1) * fy
                  + (q0 * q0 - q1 * q1 - q2 * q2 + q3 * q3) * dz)
        T, lim = self.period, self._limit
        est, rate = self.estimate, self.rate
        for i in (0, 1):
            d, r = est[i], rate[i]
            nu = sample[i] - (d + T * r)
            window = self._window[i]
            window.append(nu)
            samples = self._samples[i]
            samples.append(sample[i])
            if abs(nu) > self._one or abs(sum(window)) > self._mean * DETECT_MEAN_STEPS:
                self.fast_steps[i] = self._hold
            if self.fast_steps[i] > 0:
                k, kr = self._gains[i]
                est[i] = min(max(d + T * r + k * nu, -lim), lim)
                rate[i] = r + kr * nu
                self.fast_steps[i] -= 1
                if self.fast_steps[i] == 0:  # the change is over: a constant from here, the
                    rate[i] = 0.0  # mean of the last samples (the fast value is noisy)
                    est[i] = min(max(sum(samples) / ANCHOR_STEPS, -lim), lim)
                    window.extend([0.0] * DETECT_MEAN_STEPS)
            else:
                est[i] = d + self.quiet_alpha * nu
        k, kr = self._gains[2]
        nu = sample[2] - (est[2] + T * rate[2])
        est[2] = min(max(est[2] + T * rate[2] + k * nu, -lim), lim)
        rate[2] += kr * nu
        return est
