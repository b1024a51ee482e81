"""H-infinity controller (thesis Ch. 10): synthesis entry point, gain file, controller.

:func:`synthesise_hinf` solves the LMI of :mod:`.hinf_design` (needs the
optional ``hinf`` extra, cvxpy) and returns a :class:`HinfGain`; ``save`` and
:func:`load_hinf_gain` store it as a small ``.npz`` so the loop (and the tests)
fly a synthesised gain without cvxpy. :class:`HinfController` applies
``u = F_s (x_s - T r) + F_i x_i`` with ``r`` the reference outputs
``[x, y, z, q3]`` and, for a gain designed with the rate-loop lag, the measured
body rates in ``x_s``; ``x_i`` are the integrated output errors when the gain
was designed with integrators. The noise weight's states are unknown to the
controller and taken as zero.

Beyond the thesis, the packaged gain flown by default (``hinf_rate_loop.npz``)
is *robust*: synthesised with integrators in the standard problem, at the
vertices of the rate-gain, rate-loop and thrust uncertainty (+-30 % each) with one
Lyapunov matrix per axis, and with its poles kept in a disc the 50 Hz, delayed
command link can carry, and left of a minimum decay rate (:func:`synthesise_hinf`
with ``robust_range``, ``pole_radius`` and ``min_decay``). The first design with
the rate-loop lag (the thesis's own Ch. 10.3 fix) fed the yaw rate back
positively: with the yaw rate gain 36 % above the configured one the rate loop
lost its own damping and the heading went into a limit cycle.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Literal

import numpy as np

from groundstation.control.base import HeadingFrame, OutputIntegrator, fill_heading_state
from groundstation.control.hinf_design import (
    HinfWeights,
    plant_model,
    solve_lmi,
    standard_problem,
    uncertainty_vertices,
)
from groundstation.control.lqr_design import saturate
from groundstation.control.sticks import CommandLimits, StickParams
from groundstation.errors import ControlError
from groundstation.model import QuadrotorParams
from groundstation.types import ControlOutput, FloatArray, Reference, StateEstimate

DATA_DIR = Path(__file__).with_name("data")
"""Where the committed gains live (``hinf_thesis.npz``, ``hinf_rate_loop.npz``)."""


@dataclass(frozen=True, slots=True)
class HinfGain:
    """A synthesised state-feedback gain ``u = F_s x_s + F_r r`` (+ ``F_n x_n``, unused).

    F_s : (4, n_s) on the reduced state (n_s = 9) or with body rates (n_s = 12);
    F_r : (4, 4) on the reference outputs [x, y, z, q3]; F_n : (4, 4) on the
    noise-weight states; gamma : the H-infinity bound the LMI was solved for;
    include_rate_loop, rate_tau [s]: the design model; weights : as a dict;
    objective : "feasibility" or "min-gain"; F_i : (4, 4) on the integrated
    [x, y, z, q3] errors, or (4, 0) for a design without integrators;
    robust_range : the +- fraction of rate gains and rate-loop time constant the
    gain was designed for (0: the nominal plant only); pole_radius [rad/s] : the
    disc the closed-loop poles were kept in, or None; min_decay [1/s] : the decay
    rate every pole was kept above, or None. Input order [omega (3), F_z].
    """

    F_s: FloatArray
    F_r: FloatArray
    F_n: FloatArray
    gamma: float
    include_rate_loop: bool
    rate_tau: float
    weights: dict[str, object]
    objective: str
    F_i: FloatArray = field(default_factory=lambda: np.zeros((4, 0)))
    robust_range: float = 0.0
    pole_radius: float | None = None
    min_decay: float | None = None

    def save(self, path: str | Path) -> None:
        """Write the gain and its design metadata to an ``.npz`` file."""
        meta = {"gamma": self.gamma, "include_rate_loop": self.include_rate_loop,
                "rate_tau": self.rate_tau, "weights": self.weights, "objective": self.objective,
                "robust_range": self.robust_range, "pole_radius": self.pole_radius,
                "min_decay": self.min_decay}
        with Path(path).open("wb") as fh:
            np.savez(fh, F_s=self.F_s, F_r=self.F_r, F_n=self.F_n, F_i=self.F_i,
                     meta=np.array(json.dumps(meta, sort_keys=True)))


def load_hinf_gain(path: str | Path) -> HinfGain:
    """Read a gain written by :meth:`HinfGain.save`; ControlError if unreadable or malformed."""
    try:
        with np.load(Path(path), allow_pickle=False) as data:
            F_s, F_r, F_n = (np.array(data[k], dtype=float) for k in ("F_s", "F_r", "F_n"))
            F_i = (np.array(data["F_i"], dtype=float) if "F_i" in data.files
                   else np.zeros((4, 0)))
            meta = json.loads(str(data["meta"]))
    except (OSError, KeyError, ValueError) as exc:
        raise ControlError(f"{path}: not an H-infinity gain file: {exc}") from exc
    n_s = 12 if meta.get("include_rate_loop") else 9
    if (F_s.shape != (4, n_s) or F_r.shape != (4, 4) or F_n.shape != (4, 4)
            or F_i.shape not in ((4, 0), (4, 4))):
        raise ControlError(f"{path}: gain shapes {F_s.shape}, {F_r.shape}, {F_n.shape}, "
                           f"{F_i.shape} do not match a {n_s}-state design")
    radius, decay = meta.get("pole_radius"), meta.get("min_decay")
    return HinfGain(F_s, F_r, F_n, float(meta["gamma"]), bool(meta["include_rate_loop"]),
                    float(meta["rate_tau"]), dict(meta["weights"]), str(meta["objective"]),
                    F_i, float(meta.get("robust_range", 0.0)),
                    None if radius is None else float(radius),
                    None if decay is None else float(decay))


def synthesise_hinf(
    params: QuadrotorParams | None = None,
    *,
    include_rate_loop: bool,
    weights: HinfWeights | None = None,
    gamma: float = 1.0,
    objective: Literal["feasibility", "min-gain"] = "feasibility",
    rate_tau: float | None = None,
    solver: str = "CLARABEL",
    robust_range: float = 0.0,
    pole_radius: float | None = None,
    min_decay: float | None = None,
    decouple: bool = True,
) -> HinfGain:
    """Synthesise the Ch. 10 state-feedback gain (continuous-time LMI, eq. 10.12-10.17).

    params : the vehicle; include_rate_loop : design on the model with the
    first-order rate-loop lag (time constant ``rate_tau``, default
    ``params.rate_tau``) instead of the thesis's model; weights : the standard
    problem's weights (``integral_scale`` adds integrators); gamma : the bound (the
    thesis's LMI is normalised to 1: ``R_1 = I - D11ᵀD11``); objective :
    "feasibility" returns the solver's feasible point, as the thesis's LMI solver
    did, "min-gain" the point with the smallest ``|W|`` under ``Y >= I`` (a bound
    on ``|F|``). robust_range : > 0 imposes the LMI at the vertices of rate gains,
    rate-loop time constant and force per newton of ``F_z`` (mass and thrust map)
    ``1 -+ robust_range`` times nominal (:func:`.hinf_design.uncertainty_vertices`;
    needs ``include_rate_loop``);
    pole_radius [rad/s], min_decay [1/s] : keep the closed-loop poles in that disc
    and left of ``-min_decay``; decouple : solve axis by axis (default) or as one joint
    LMI as the thesis did (see :func:`.hinf_design.solve_lmi`).
    Needs cvxpy (the ``hinf`` extra); ControlError if infeasible.
    """
    p = params if params is not None else QuadrotorParams()
    w = weights if weights is not None else HinfWeights()
    tau = p.rate_tau if rate_tau is None else rate_tau
    if robust_range > 0.0:
        if not include_rate_loop:
            raise ControlError("a robust design needs the rate-loop model (include_rate_loop)")
        problems = uncertainty_vertices(p, tau, w, robust_range, robust_range, robust_range)
    else:
        A_s, B_s = plant_model(p, include_rate_loop, tau)
        problems = [standard_problem(A_s, B_s, w)]
    F = solve_lmi(problems, gamma=gamma, objective=objective, solver=solver,
                  pole_radius=pole_radius, min_decay=min_decay, decouple=decouple)
    sp = problems[0]
    n_s, n_w = sp.n_s, sp.n_s + sp.n_r + sp.n_n
    return HinfGain(
        F_s=F[:, :n_s], F_r=F[:, n_s:n_s + 4], F_n=F[:, n_s + 4:n_w], gamma=gamma,
        include_rate_loop=include_rate_loop, rate_tau=tau if include_rate_loop else 0.0,
        weights=asdict(w), objective=objective, F_i=F[:, n_w:], robust_range=robust_range,
        pole_radius=pole_radius, min_decay=min_decay,
    )


class HinfController:
    """Fly a stored H-infinity gain: ``u = F_s (x_s - x_ref) + F_i x_i``, saturated.

    gain : a :class:`HinfGain` (e.g. from :func:`load_hinf_gain`); params : the
    vehicle (for the default saturation limits); limits : output saturation.

    The reference enters through the static prefilter ``-F_s T`` (T puts r on the
    x, y, z, q3 states), which makes hover at the reference an equilibrium: the
    standard problem models the reference as the output of the low-pass ``W_r``
    that decays to zero, so the synthesised ``F_r`` would only follow a fraction
    of a constant reference (about 0.66 for the thesis-model gain). Stability
    depends on ``F_s`` only. As for the LQR, the state is taken relative to the
    reference in the vehicle's heading frame (:func:`.base.fill_heading_state`),
    velocity included (``x_ref`` holds the reference's position, heading and velocity;
    beyond the thesis, so that a ramp does not wind up the integrators).
    """

    lead_s = 0.0

    def __init__(self, gain: HinfGain, *, params: QuadrotorParams | None = None,
                 dt: float = 0.02, integral_limit: float = 2.0,
                 limits: CommandLimits | None = None) -> None:
        p = params if params is not None else QuadrotorParams()
        self.gain = gain
        self._n_s = gain.F_s.shape[1]
        if self._n_s not in (9, 12):
            raise ControlError(f"F_s must have 9 or 12 columns, found {self._n_s}")
        n_i = gain.F_i.shape[1]
        self._K = np.hstack([gain.F_s, gain.F_i])
        self._z = np.zeros(self._n_s + n_i)  # [x_s - T r; x_i]
        self._integral = OutputIntegrator(range(n_i), dt, integral_limit)
        self._u = np.zeros(4)
        self._frame = HeadingFrame()
        lim = limits or CommandLimits.from_stick_params(StickParams.from_quadrotor(p))
        self._lo = [*lim.omega_min.tolist(), lim.f_z_min]  # saturation, as Python floats
        self._hi = [*lim.omega_max.tolist(), lim.f_z_max]

    def reset(self) -> None:
        """Zero the integrators (a static state feedback otherwise)."""
        self._integral.reset()

    def sent(self, output: ControlOutput, automatic: bool) -> None:
        """Nothing to record: the state is measured."""

    def step(self, t: float, estimate: StateEstimate, reference: Reference,
             preview: Reference | None = None) -> ControlOutput:
        """``u = F_s (x_s - T r) + F_i x_i`` with the rates fed back for a lag-model gain;
        the integrators hold while the output saturates."""
        z = self._z
        frame = self._frame
        fill_heading_state(frame, estimate, reference, z)
        # the velocity relative to the reference's (beyond the thesis, which gives the
        # reference position only): a ramp such as the take-off climb is then followed
        # without winding the integrators up
        v0, v1, v2 = reference.velocity.tolist()
        vx, vy = frame.to_heading(v0, v1)
        z[6] -= vx
        z[7] -= vy
        z[8] -= v2
        n = self._n_s
        if n == 12:
            z[9:12] = estimate.omega
        xi = z[n:]
        self._integral.update(frame, z, xi)
        u = np.dot(self._K, z, out=self._u)
        if saturate(u, self._lo, self._hi) is not None:
            self._integral.update(frame, z, xi, undo=True)
        return ControlOutput(omega=u[0:3].copy(), f_z=float(u[3]))


DEFAULT_GAIN_FILES = {False: "hinf_thesis.npz", True: "hinf_rate_loop.npz"}
"""Committed gains: designed on the thesis's model / on the model with the rate-loop lag."""


def default_gain_path(include_rate_loop: bool) -> Path:
    """Path of the committed gain for the thesis's model (False) or the lagged one (True)."""
    return DATA_DIR / DEFAULT_GAIN_FILES[include_rate_loop]


ROBUST_RANGE = 0.3
"""The packaged rate-loop gain is designed for rate gains, rate-loop time constant and
thrust per newton within +-30 % of nominal (the spread `gs eval --perturb` draws: rate
gains and time constant +-30 %, mass and thrust map +-15 % each)."""
POLE_RADIUS = 12.0
"""Disc [rad/s] the packaged rate-loop gain's poles are kept in: at most 24 rad/s, a
loop the 50 Hz command link with ~40 ms of delay carries with margin."""
MIN_DECAY = 0.6
"""Every pole of the packaged rate-loop gain left of -0.6 /s: without it the LMI's
feasible point hovered 2 cm off on the perturbed plants (a sluggish horizontal loop)."""
INTEGRAL_SCALE = (0.3, 0.3, 1.0, 0.1)
"""Weights of the integrated [x, y, z, q3] errors in the packaged rate-loop design (z
more: a thrust-map or mass error is the largest constant disturbance)."""


def write_default_gains(directory: str | Path = DATA_DIR,
                        params: QuadrotorParams | None = None) -> list[Path]:
    """Synthesise both committed gains (gamma = 1, feasibility).

    This is how ``data/hinf_thesis.npz`` (the thesis's model and weights and its one
    joint LMI, Ch. 10)
    and ``data/hinf_rate_loop.npz`` (the rate-loop model, robust, with integrators,
    :data:`ROBUST_RANGE`, :data:`POLE_RADIUS`, :data:`MIN_DECAY`,
    :data:`INTEGRAL_SCALE`) were made,
    with the default vehicle.
    """
    thesis = Path(directory) / DEFAULT_GAIN_FILES[False]
    synthesise_hinf(params, include_rate_loop=False, decouple=False).save(thesis)
    robust = Path(directory) / DEFAULT_GAIN_FILES[True]
    synthesise_hinf(params, include_rate_loop=True,
                    weights=HinfWeights(integral_scale=INTEGRAL_SCALE),
                    robust_range=ROBUST_RANGE, pole_radius=POLE_RADIUS,
                    min_decay=MIN_DECAY).save(robust)
    return [thesis, robust]
