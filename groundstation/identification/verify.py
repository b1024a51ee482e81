"""``gs verify-model LOG``: the thesis's Ch. 5 model verification on a recorded flight.

At every airborne sample of the log, the nonlinear model (eq. 3.19-3.22,
:class:`~groundstation.model.quadrotor.QuadrotorModel`) and its linearisation about
hover (Ch. 4, :func:`~groundstation.model.linear.hover_model`) predict the quaternion
derivative ``q_dot`` (4,) and the body-frame velocity derivative ``v_dot`` (3,) from the
state and the sticks the vehicle applied; the log's own derivatives (central differences
of the estimated attitude and body velocity over :data:`SPAN` samples each side, the
predictions averaged over the same window; samples within :data:`MIN_HEIGHT_M` of the
floor left out) are the measurement, as the thesis compares the models with flight
data (Fig. 5.1-5.4). The sticks are those in force ``vehicle.command_delay_s`` earlier
(the command link's delay, Ch. 3.3.1), taken from the commands on the channels the
vehicle took from us and from the pilot's sticks on the others.

Reported per component: the RMS of the measured derivative, the RMS and mean of each
model's error. A model that fits leaves an error well below the signal; a constant
error in ``v3_dot`` is a thrust-map or mass error of that size [m/s^2].
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from groundstation.app.recorder import read_flight
from groundstation.config import validate_config
from groundstation.errors import IdentificationError
from groundstation.flight.assembly import link_params, vehicle_model
from groundstation.flight.supervisor import AIRBORNE
from groundstation.identification.rates import SYSID_HINT
from groundstation.model.linear import hover_model
from groundstation.model.quadrotor import QuadrotorModel, inputs_from_sticks
from groundstation.types import FloatArray, Sticks

COMPONENTS = ("q0_dot", "q1_dot", "q2_dot", "q3_dot", "v1_dot", "v2_dot", "v3_dot")
"""The compared derivatives: quaternion [1/s] and body velocity [m/s^2]."""
MIN_SAMPLES = 200
"""Fewer airborne samples than this cannot verify a model."""


class VerificationError(IdentificationError):
    """A log that cannot verify the model (not a flight, too short, not airborne)."""


@dataclass(frozen=True)
class ModelVerification:
    """Measured against predicted derivatives (see the module docstring).

    t : (N,) times [s] from the first sample; measured, nonlinear, linear : (N, 7)
    the derivatives in :data:`COMPONENTS` order; rms_signal, rms_nonlinear,
    rms_linear, mean_nonlinear, mean_linear : per component.
    """

    t: FloatArray = field(repr=False)
    measured: FloatArray = field(repr=False)
    nonlinear: FloatArray = field(repr=False)
    linear: FloatArray = field(repr=False)
    samples: int = 0

    def _stats(self, predicted: FloatArray, kind: str) -> dict[str, float]:
        err = predicted - self.measured
        out = {}
        for k, name in enumerate(COMPONENTS):
            out[f"{kind}_rms_{name}"] = float(np.sqrt(np.mean(err[:, k] ** 2)))
            out[f"{kind}_mean_{name}"] = float(np.mean(err[:, k]))
        return out

    def figures(self) -> dict[str, Any]:
        """Per component: measured RMS, each model's error RMS and mean (JSON-ready)."""
        out: dict[str, Any] = {"samples": self.samples}
        for k, name in enumerate(COMPONENTS):
            out[f"signal_rms_{name}"] = float(np.sqrt(np.mean(self.measured[:, k] ** 2)))
        out.update(self._stats(self.nonlinear, "nonlinear"))
        out.update(self._stats(self.linear, "linear"))
        return out

    def summary(self) -> str:
        """A table with units: signal RMS, and each model's error RMS and mean."""
        f = self.figures()
        lines = [f"model verification on {self.samples} airborne samples (thesis Ch. 5): "
                 "error = model - measured",
                 f"  {'':8s} {'signal RMS':>11s} {'nonlinear RMS':>14s} {'mean':>9s} "
                 f"{'linear RMS':>11s} {'mean':>9s}"]
        for name in COMPONENTS:
            unit = "1/s" if name.startswith("q") else "m/s^2"
            lines.append(
                f"  {name:8s} {f['signal_rms_' + name]:11.4f} "
                f"{f['nonlinear_rms_' + name]:14.4f} {f['nonlinear_mean_' + name]:9.4f} "
                f"{f['linear_rms_' + name]:11.4f} {f['linear_mean_' + name]:9.4f}  [{unit}]")
        return "\n".join(lines)

    def figure(self, path: Path) -> Path:
        """Measured against both models per component (the analogue of Fig. 5.1-5.4)."""
        from groundstation.evaluation.plotting import pyplot, save

        plt = pyplot()
        fig, axes = plt.subplots(4, 2, figsize=(12, 10), sharex=True)
        for k, name in enumerate(COMPONENTS):
            ax = axes[k % 4, k // 4]
            ax.plot(self.t, self.measured[:, k], color="k", lw=0.8, label="measured")
            ax.plot(self.t, self.nonlinear[:, k], color="C0", lw=0.8, label="nonlinear model")
            ax.plot(self.t, self.linear[:, k], color="C1", lw=0.8, ls="--",
                    label="linear model")
            unit = "1/s" if name.startswith("q") else "m/s^2"
            ax.set(ylabel=f"{name} [{unit}]")
            ax.grid(True, alpha=0.3)
        axes[3, 1].axis("off")
        handles, labels = axes[0, 0].get_legend_handles_labels()
        axes[3, 1].legend(handles, labels, loc="center")
        for ax in (axes[3, 0], axes[2, 1]):
            ax.set_xlabel("time [s]")
            ax.tick_params(labelbottom=True)
        fig.suptitle("gs verify-model: one-step derivatives, measured and predicted (Ch. 5)")
        return save(fig, path)


SPAN = 3
"""Derivatives are central differences over +-SPAN IMU samples (60 ms at 100 Hz), and
the models' predictions are averaged over the same window, so both are compared over
one interval (a one-sample difference of the estimate is mostly its noise)."""
MIN_HEIGHT_M = 0.1
"""Samples closer to the floor than this are left out: the models have no ground."""


def _central_difference(t: FloatArray, values: FloatArray, span: int = SPAN) -> FloatArray:
    out = np.full_like(values, np.nan)
    dt = (t[2 * span:] - t[:-2 * span])[:, None]
    out[span:-span] = (values[2 * span:] - values[:-2 * span]) / dt
    return out


def _window_mean(values: FloatArray, span: int = SPAN) -> FloatArray:
    kernel = np.ones(2 * span + 1) / (2 * span + 1)
    out = np.column_stack([np.convolve(values[:, k], kernel, mode="same")
                           for k in range(values.shape[1])])
    out[:span] = np.nan
    out[-span:] = np.nan
    return out


def verify_model(log_dir: str | Path) -> ModelVerification:
    """Compare the models with the flight in ``log_dir`` (see the module docstring).

    VerificationError if the log has too few airborne samples; RecorderError if it is
    not a readable flight log.
    """
    rows, _, config_text = read_flight(log_dir)
    cfg = validate_config(yaml.safe_load(config_text) or {})
    params = vehicle_model(cfg.vehicle, link_params(cfg.serial))
    # one sample per IMU sample (ticks without a new one repeat it)
    _, first = np.unique(rows["imu_t"], return_index=True)
    rows = rows[np.sort(first)]
    z = rows["est_position"][:, 2]
    floor = float(z[np.isfinite(z)][0]) if np.isfinite(z).any() else math.nan
    air = np.isin(rows["state"], [int(s) for s in AIRBORNE]) & (z < floor - MIN_HEIGHT_M)
    if int(air.sum()) < MIN_SAMPLES:
        raise VerificationError(f"{log_dir}: only {int(air.sum())} airborne samples (at least "
                                f"{MIN_SAMPLES} needed): {SYSID_HINT}")
    t = rows["imu_t"]
    q = rows["est_quaternion"]
    v = rows["est_velocity_body"]
    q_dot = _central_difference(t, q)
    v_dot = _central_difference(t, v)
    sticks = _applied_sticks(rows)
    delay = cfg.vehicle.command_delay_s
    delayed = np.column_stack([np.interp(t - delay, t, sticks[:, k]) for k in range(4)])
    model = QuadrotorModel(params)
    lin = hover_model(params)
    hover = np.array([0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    n = len(rows)
    nonlinear = np.full((n, 7), np.nan)
    linear = np.full((n, 7), np.nan)
    for i in range(n):
        if not (np.all(np.isfinite(q[i])) and np.all(np.isfinite(v[i]))):
            continue
        s = delayed[i]
        u = inputs_from_sticks(Sticks(roll=round(s[1]), pitch=round(s[0]), yaw=round(s[2]),
                                      thrust=round(s[3])), params)
        x = np.concatenate([rows["est_position"][i], q[i], v[i]])
        dx = x - hover
        dx[0:3] = 0.0  # the position does not enter the dynamics
        nonlinear[i] = model.derivative(x, u)[3:10]
        linear[i] = (lin.A @ dx + lin.B @ u)[3:10]
    measured = np.column_stack([q_dot, v_dot])
    nonlinear, linear = _window_mean(nonlinear), _window_mean(linear)
    use = air & np.all(np.isfinite(measured), axis=1) & np.all(np.isfinite(nonlinear), axis=1)
    if int(use.sum()) < MIN_SAMPLES:
        raise VerificationError(f"{log_dir}: only {int(use.sum())} usable airborne samples")
    ts = t[use]
    return ModelVerification(t=ts - ts[0], measured=measured[use], nonlinear=nonlinear[use],
                             linear=linear[use], samples=int(use.sum()))


def _applied_sticks(rows: Any) -> FloatArray:
    """(N, 4) [pitch, roll, yaw, thrust] the vehicle applied: the command on the channels
    it reports taking from us (``vehicle_mask``), the pilot's stick on the others."""
    mask = rows["vehicle_mask"].astype(int)
    out = np.empty((len(rows), 4))
    for k, name in enumerate(("pitch", "roll", "yaw", "thrust")):
        ours = (mask >> k) & 1 == 1
        out[:, k] = np.where(ours, rows[f"cmd_{name}"], rows[f"pilot_{name}"])
    return out

