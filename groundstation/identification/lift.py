"""Thrust map and induced inflow from a flight log (``gs identify thrust|inflow LOG``).

The thesis measured both on a stand (App. C.1: the scale reading per thrust stick; App.
C.2: steady climbs). In flight the accelerometer gives the same force, as specific force
along body z: ``m f_z = F_lift(u) + I_i v3`` (eq. 3.9, with ``v3`` the body-z velocity),
``f_z`` the accelerometer less the estimator's bias, ``u`` the thrust stick the vehicle
applied one command delay earlier (the command on the thrust channel when the vehicle
took it from us, else the pilot's):

* **thrust** (:func:`identify_thrust_log`): samples off the floor and nearly level
  in z (``|v3|`` below :data:`STEADY_V3`), so the inflow term is small and is taken
  out with the configured ``I_i``. A flight covers the sticks near hover only, so the
  fit is a scale on the configured polynomial, ``F_lift = s F_cfg(u)`` (what a new
  battery or propeller changes), with its 95 % interval; the configuration's
  ``vehicle.thrust_poly`` times ``s`` is reported.
* **inflow** (:func:`identify_inflow_log`): samples in vertical motion (``|v3|`` above
  :data:`MOVING_V3`, the App. C.2 climbs and descents of a ``step-z`` trajectory):
  ``I_i`` is the slope of ``m f_z - s F_cfg(u)`` against ``v3``.

Before any log (a thrust-automatic flight needs a thrust map to take off with, and the
map is fitted from such a flight's log) :func:`thrust_from_hover_stick` scales the
configured polynomial so that it lifts the weight at the thrust stick the pilot hovers
at by hand (``gs identify hover-stick STICK``; ``gs link-check --expect-switch off``
reports the pilot's sticks while the pilot hovers).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from groundstation.errors import IdentificationError
from groundstation.identification.rates import SYSID_HINT, FlightLog, load_flight_log
from groundstation.types import FloatArray

STEADY_V3 = 0.1
"""Samples with a body-z speed below this [m/s] measure the thrust map."""
MOVING_V3 = 0.2
"""Samples with a body-z speed above this [m/s] measure the induced inflow."""
STEADY_ACC = 0.2
"""Only samples whose body-z velocity changes slower than this [m/s^2] are used: in a
changing climb the lift lags the stick (motors) and the fit would take the lag for
inflow (App. C.2 measured steady climbs)."""
MIN_SAMPLES = 200


@dataclass(frozen=True)
class ThrustLogFit:
    """A flight's thrust map: scale ``s`` on the configured polynomial (95 % interval),
    the scaled coefficients, the residual [N]."""

    scale: float
    scale_ci: tuple[float, float]
    coeffs: tuple[float, float, float, float]
    rms_residual: float
    samples: int
    u_range: tuple[float, float]
    u: FloatArray
    force: FloatArray
    configured: tuple[float, float, float, float]

    def config_fields(self) -> dict[str, Any]:
        """``{"vehicle.thrust_poly": [a3, a2, a1, a0]}``: the configured map scaled."""
        return {"vehicle.thrust_poly": list(self.coeffs)}

    def summary(self) -> str:
        """Human-readable lines with units."""
        lo, hi = self.scale_ci
        lines = [f"thrust map from {self.samples} steady samples, sticks "
                 f"{self.u_range[0]:.0f}..{self.u_range[1]:.0f}: lift = {self.scale:.4f} "
                 f"(95 % {lo:.4f}..{hi:.4f}) x the configured eq. 3.7 polynomial, "
                 f"residual RMS {self.rms_residual:.3f} N",
                 "  thrust_poly (a3, a2, a1, a0) = "
                 + ", ".join(f"{c:.4g}" for c in self.coeffs)]
        lines.append("  (a flight covers the sticks near hover: the whole map's shape comes from "
                     "a stand, App. C.1)")
        return "\n".join(lines)

    def figure(self, path: str | Path) -> Path:
        """Measured lift against the stick, with the configured and the fitted maps."""
        from groundstation.evaluation.plotting import pyplot, save

        plt = pyplot()
        fig, ax = plt.subplots(figsize=(8, 5))
        ax.plot(self.u, self.force, ".", ms=2, alpha=0.4, color="C0", label="measured (flight)")
        grid = np.linspace(self.u_range[0], self.u_range[1], 100)
        ax.plot(grid, np.polyval(self.configured, grid), "k--", lw=1,
                label="configured eq. 3.7")
        ax.plot(grid, np.polyval(self.coeffs, grid), "C3", lw=1.5,
                label=f"fitted: {self.scale:.3f} x configured")
        ax.set(xlabel="thrust stick [RC units]", ylabel="lift along body z [N] (negative up)",
               title="gs identify thrust: lift against the thrust stick")
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=8, loc="upper right")
        return save(fig, Path(path))


@dataclass(frozen=True)
class InflowLogFit:
    """A flight's induced-inflow constant ``I_i`` [N s/m] (eq. 3.9) with its 95 % interval."""

    inflow: float
    inflow_ci: tuple[float, float]
    samples: int
    v3: FloatArray
    residual_force: FloatArray

    def config_fields(self) -> dict[str, Any]:
        """``{"vehicle.induced_inflow": I_i}``."""
        return {"vehicle.induced_inflow": self.inflow}

    def summary(self) -> str:
        """One line with units."""
        lo, hi = self.inflow_ci
        return (f"induced inflow from {self.samples} samples in vertical motion: I_i = "
                f"{self.inflow:.4f} N s/m (95 % {lo:.4f}..{hi:.4f}; thesis eq. C.8: -0.423)")

    def figure(self, path: str | Path) -> Path:
        """Force not explained by the thrust map against the body-z velocity."""
        from groundstation.evaluation.plotting import pyplot, save

        plt = pyplot()
        fig, ax = plt.subplots(figsize=(8, 5))
        ax.plot(self.v3, self.residual_force, ".", ms=2, alpha=0.4, label="measured (flight)")
        grid = np.linspace(float(self.v3.min()), float(self.v3.max()), 50)
        ax.plot(grid, self.inflow * grid, "C3", lw=1.5, label=f"I_i = {self.inflow:.3f} N s/m")
        ax.set(xlabel="body-z velocity v3 [m/s]", ylabel="m f_z - F_lift(u) [N]",
               title="gs identify inflow: the induced-inflow force (eq. 3.9)")
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=8, loc="upper right")
        return save(fig, Path(path))


def _force_and_stick(log: FlightLog) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """(u, m f_z, v3, dv3/dt) at the IMU samples off the floor (see the module docstring)."""
    rows = log.rows[log.imu]
    air = log.airborne[log.imu]
    cfg = log.config
    t = rows["imu_t"]
    mask = rows["vehicle_mask"].astype(int)
    stick = np.where((mask >> 3) & 1 == 1, rows["cmd_thrust"], rows["pilot_thrust"])
    u = np.interp(t - cfg.vehicle.command_delay_s, t, stick.astype(float))
    f_z = rows["acc"][:, 2] - rows["est_acc_bias"][:, 2]
    v3 = rows["est_velocity_body"][:, 2]
    v3_dot = np.gradient(v3, t) if len(t) > 2 else np.full_like(v3, np.nan)
    ok = air & np.isfinite(f_z) & np.isfinite(v3) & np.isfinite(u) & np.isfinite(v3_dot)
    return u[ok], cfg.vehicle.mass_kg * f_z[ok], v3[ok], v3_dot[ok]


def _slope_ci(x: FloatArray, y: FloatArray) -> tuple[float, tuple[float, float]]:
    """Least-squares slope of ``y = k x`` (through the origin) and its 95 % interval."""
    k = float(x @ y / (x @ x))
    resid = y - k * x
    se = float(np.sqrt((resid @ resid) / (len(x) - 1) / (x @ x)))
    return k, (k - 1.96 * se, k + 1.96 * se)


def identify_thrust_log(log_dir: str | Path) -> ThrustLogFit:
    """Thrust map from a flight (see the module docstring); IdentificationError if the log
    has too few steady samples off the floor."""
    log = load_flight_log(log_dir, min_height_m=0.1)
    u, force_meas, v3, v3_dot = _force_and_stick(log)
    cfg = log.config.vehicle
    configured = (cfg.thrust_poly[0], cfg.thrust_poly[1], cfg.thrust_poly[2],
                  cfg.thrust_poly[3])
    steady = (np.abs(v3) < STEADY_V3) & (np.abs(v3_dot) < STEADY_ACC)
    if int(steady.sum()) < MIN_SAMPLES:
        raise IdentificationError(f"{log_dir}: only {int(steady.sum())} steady samples off the "
                                  f"floor (|v3| < {STEADY_V3} m/s; {MIN_SAMPLES} needed): "
                                  f"{SYSID_HINT}")
    u_s = u[steady]
    lift = force_meas[steady] - cfg.induced_inflow * v3[steady]
    nominal: FloatArray = np.asarray(np.polyval(configured, u_s), dtype=float)  # eq. 3.7
    scale, ci = _slope_ci(nominal, lift)
    coeffs = tuple(scale * c for c in configured)
    resid = lift - scale * nominal
    return ThrustLogFit(scale=scale, scale_ci=ci, coeffs=(coeffs[0], coeffs[1], coeffs[2],
                                                          coeffs[3]),
                        rms_residual=float(np.sqrt(np.mean(resid**2))),
                        samples=int(steady.sum()),
                        u_range=(float(u_s.min()), float(u_s.max())), u=u_s, force=lift,
                        configured=configured)


def identify_inflow_log(log_dir: str | Path,
                        thrust_scale: float | None = None) -> InflowLogFit:
    """Induced inflow from a flight with vertical motion (see the module docstring).

    thrust_scale : the lift's scale on the configured map (default: identified from the
    same log's steady samples). IdentificationError without enough vertical motion.
    """
    log = load_flight_log(log_dir, min_height_m=0.1)
    u, force_meas, v3, v3_dot = _force_and_stick(log)
    cfg = log.config.vehicle
    s = thrust_scale if thrust_scale is not None else identify_thrust_log(log_dir).scale
    moving = (np.abs(v3) > MOVING_V3) & (np.abs(v3_dot) < STEADY_ACC)  # steady climbs
    if int(moving.sum()) < MIN_SAMPLES // 2:
        raise IdentificationError(f"{log_dir}: only {int(moving.sum())} samples with "
                                  f"|v3| > {MOVING_V3} m/s ({MIN_SAMPLES // 2} needed) for App. "
                                  f"C.2's steady climbs: {SYSID_HINT}")
    residual = force_meas[moving] - s * np.polyval(list(cfg.thrust_poly), u[moving])
    inflow, ci = _slope_ci(v3[moving], residual)
    return InflowLogFit(inflow=inflow, inflow_ci=ci, samples=int(moving.sum()), v3=v3[moving],
                        residual_force=residual)


@dataclass(frozen=True)
class HoverStickFit:
    """A first thrust map from the thrust stick the vehicle hovers at (no flight log yet).

    stick : the hover thrust stick [RC units]; scale : lift = scale x the configured
    polynomial, so that it lifts the weight at ``stick``; coeffs : the scaled eq. 3.7
    coefficients (a3, a2, a1, a0) [N]; configured : the configured ones; weight_n : m g [N];
    configured_lift_n : what the configured map lifts at ``stick`` [N] (positive up)
    """

    stick: float
    scale: float
    coeffs: tuple[float, float, float, float]
    configured: tuple[float, float, float, float]
    weight_n: float
    configured_lift_n: float

    def config_fields(self) -> dict[str, Any]:
        """``{"vehicle.thrust_poly": [a3, a2, a1, a0]}``: the configured map scaled."""
        return {"vehicle.thrust_poly": list(self.coeffs)}

    def summary(self) -> str:
        """Human-readable lines with units."""
        return "\n".join([
            f"hover at thrust stick {self.stick:.0f}: the configured eq. 3.7 polynomial lifts "
            f"{self.configured_lift_n:.3f} N there, the vehicle weighs {self.weight_n:.3f} N: "
            f"lift = {self.scale:.4f} x the configured map",
            "  thrust_poly (a3, a2, a1, a0) = " + ", ".join(f"{c:.4g}" for c in self.coeffs),
            "  (one reading, no interval: the log of the first thrust-automatic flight gives "
            "one, gs identify thrust LOG)"])

    def figure(self, path: str | Path) -> Path:
        """The configured and the scaled maps against the stick, the hover point marked."""
        from groundstation.evaluation.plotting import pyplot, save

        plt = pyplot()
        fig, ax = plt.subplots(figsize=(8, 5))
        grid = np.linspace(0.0, 4096.0, 200)
        ax.plot(grid, -np.polyval(self.configured, grid), "k--", lw=1,
                label="configured eq. 3.7")
        ax.plot(grid, -np.polyval(self.coeffs, grid), "C3", lw=1.5,
                label=f"scaled x {self.scale:.3f}")
        ax.plot([self.stick], [self.weight_n], "o", color="C0", label="hover: lift = m g")
        ax.set(xlabel="thrust stick [RC units]", ylabel="lift, up [N]",
               title="gs identify hover-stick: the map through the hover point")
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=8, loc="upper left")
        return save(fig, Path(path))


def thrust_from_hover_stick(stick: float, *, mass_kg: float, gravity: float,
                            thrust_poly: tuple[float, float, float, float] | list[float]
                            ) -> HoverStickFit:
    """The configured thrust polynomial (eq. 3.7, body-z force [N], negative up) scaled so
    that it lifts the weight ``mass_kg * gravity`` at the hover thrust ``stick`` [RC units]:
    the first map a thrust-automatic flight can take off with, before any flight log.

    IdentificationError if the stick is outside 1..4095 or the configured map gives no
    lift there.
    """
    if not (math.isfinite(stick) and 1.0 <= stick <= 4095.0):
        raise IdentificationError(f"hover stick {stick:g}: a thrust stick is 1..4095 RC units "
                                  "(0 stops the motors)")
    poly = tuple(float(c) for c in thrust_poly)
    if len(poly) != 4:
        raise IdentificationError("thrust_poly must have 4 coefficients (a3, a2, a1, a0)")
    lift = -float(np.polyval(poly, stick))
    if not lift > 0.0:
        raise IdentificationError(f"the configured thrust_poly gives no lift at stick "
                                  f"{stick:.0f} ({-lift:.3f} N along body z): it cannot be "
                                  "scaled to hover there")
    weight = mass_kg * gravity
    scale = weight / lift
    coeffs = tuple(scale * c for c in poly)
    return HoverStickFit(stick=float(stick), scale=scale,
                         coeffs=(coeffs[0], coeffs[1], coeffs[2], coeffs[3]),
                         configured=(poly[0], poly[1], poly[2], poly[3]), weight_n=weight,
                         configured_lift_n=lift)
