"""The vehicle and its estimator: the ``vehicle`` section (the X-3D's model and sensors,
thesis Ch. 3 and 6) and the ``estimator`` section (the EKF, Ch. 7)."""

from __future__ import annotations

from typing import Annotated

import numpy as np
from pydantic import Field, field_validator, model_validator

from groundstation.config.base import (
    ConfigModel,
    Covariance,
    FieldValueError,
    check_covariance,
    covariance_matrix,
)
from groundstation.config.ranges import (
    GRAVITY_RANGE_M_S2,
    LAB_EXTENT_M,
    THRUST_MAX_N,
    AccScale,
    AccVariance,
    AdcZero,
    CommandDelay,
    GyroScale,
    GyroVariance,
    RateGain,
    RateLoopTau,
    ViconPositionVariance,
    ViconQuaternionVariance,
    variance_band,
    within,
)
from groundstation.model.quadrotor import QuadrotorParams
from groundstation.model.sensors import (
    ACC_SATURATION_M_S2,
    ACC_VARIANCE_TABLE_6_3,
    GYRO_VARIANCE_TABLE_6_3,
    INITIAL_STATE_VARIANCE,
    K_ACC_TABLE_6_2,
    K_GYRO_TABLE_6_2,
    VICON_POSITION_VARIANCE_TABLE_6_1,
    VICON_QUATERNION_VARIANCE_TABLE_6_1,
)
from groundstation.model.thrust import THRUST_POLY_EQ37

_QUAD = QuadrotorParams()
"""The vehicle model's defaults (groundstation.model.quadrotor): mass, g, rate gains,
induced inflow, rate-loop time constant; the vehicle section takes them from it."""


class VehicleConfig(ConfigModel):
    """The X-3D model parameters (thesis Ch. 3 and 6)."""

    mass_kg: Annotated[float, within(
        0.01, 20.0, "kg: from a 27 g micro quadrotor to a 20 kg lifter")] = _QUAD.mass
    # not printed in the thesis: 0.60 kg makes the eq. 3.7 polynomial hover near mid-stick
    # (F_lift(2000) = -5.93 N = -0.603 kg * 9.82), DESIGN.md errata
    gravity: Annotated[float, within(*GRAVITY_RANGE_M_S2, "m/s^2: gravity at the Earth's "
                                     "surface (GRAVITY_RANGE_M_S2)")] = _QUAD.g
    # thesis eq. 3.8, Denmark
    k_rate: list[RateGain] = Field(default_factory=lambda: list(_QUAD.k_rate),
                                   min_length=3, max_length=3)
    # [K_phi, K_theta, K_psi] rad/s per stick unit: max roll step 2047 gave 2.25 rad/s
    # (Ch. 3.3.1), identified values not printed (DESIGN.md errata); yaw assumed the same
    thrust_poly: list[float] = Field(
        default_factory=lambda: list(THRUST_POLY_EQ37), min_length=4, max_length=4,
    )  # eq. 3.7, [a3, a2, a1, a0], body-z force [N] (negative = up); App. C.1's a2 is a typo
    induced_inflow: Annotated[float, within(
        _QUAD.inflow * 100, _QUAD.inflow / 100, "N s/m, negative (a climb meets the "
        "inflow's drag): two decades either side of eq. C.8's")] = _QUAD.inflow
    # I_i, eq. 3.9 and eq. C.8 [N s/m]
    gyro_scale: list[GyroScale] = Field(default_factory=lambda: list(K_GYRO_TABLE_6_2),
                                        min_length=3, max_length=3)
    # Table 6.2 K_gyro [rad/s per count]; negative for an axis mounted reversed
    acc_scale: list[AccScale] = Field(default_factory=lambda: list(K_ACC_TABLE_6_2),
                                      min_length=3, max_length=3)
    # Table 6.2 K_acc [m/s^2 per count]; negative for an axis mounted reversed
    gyro_zero: list[AdcZero] = Field(default_factory=lambda: [2048.0, 2048.0, 2048.0],
                                     min_length=3, max_length=3)
    # spec section 3.3: 12-bit counts, zero at mid-range (calibrate per vehicle)
    acc_zero: list[AdcZero] = Field(default_factory=lambda: [2048.0, 2048.0, 2048.0],
                                    min_length=3, max_length=3)  # as gyro_zero
    gyro_variance: list[GyroVariance] = Field(
        default_factory=lambda: list(GYRO_VARIANCE_TABLE_6_3), min_length=3, max_length=3)
    # Table 6.3 [(rad/s)^2]
    acc_variance: list[AccVariance] = Field(
        default_factory=lambda: list(ACC_VARIANCE_TABLE_6_3), min_length=3, max_length=3)
    # Table 6.3 [(m/s^2)^2]
    vicon_position_variance: list[ViconPositionVariance] = Field(
        default_factory=lambda: list(VICON_POSITION_VARIANCE_TABLE_6_1),
        min_length=3, max_length=3)
    # Table 6.1 [m^2]
    vicon_quaternion_variance: list[ViconQuaternionVariance] = Field(
        default_factory=lambda: list(VICON_QUATERNION_VARIANCE_TABLE_6_1),
        min_length=4, max_length=4)  # Table 6.1, q0..q3
    acc_saturation: Annotated[float, within(
        GRAVITY_RANGE_M_S2[1], 160.0, "m/s^2: above 1 g (the accelerometer must read the "
        "hover) and at most a MEMS accelerometer's widest range, 16 g")] = ACC_SATURATION_M_S2
    # Ch. 6.2: accelerometer saturation
    rate_loop_tau_s: RateLoopTau = _QUAD.rate_tau
    # on-board rate loop as a first-order lag: Fig. 3.8 rises (10-90 %) in 0.14 s = 2.2 tau.
    # The controller design, the virtual lab and the evaluation all use this one value
    command_delay_s: CommandDelay = 0.02
    # transport delay of a COMMAND (radio and firmware) before the vehicle applies it;
    # Ch. 3.3.1 identified the rate gains "with a time delay" without printing it; 20 ms
    # is one 50 Hz command period (XBee at 57600 baud, thesis App. A)

    @field_validator("thrust_poly")
    @classmethod
    def _lift_in_range(cls, value: list[float]) -> list[float]:
        # Horner in Python floats: a huge coefficient overflows to inf (or inf - inf to
        # nan), which the comparison refuses, without numpy's overflow warnings
        def lift(u: float) -> float:
            out = 0.0
            for a in value:
                out = out * u + a
            return out

        worst = next((f for f in (lift(u) for u in range(0, 4097, 64))
                      if not abs(f) <= THRUST_MAX_N), 0.0)
        if worst:
            raise ValueError(f"gives {worst:g} N within the stick range 0..4095: outside "
                             f"[-{THRUST_MAX_N:g}, {THRUST_MAX_N:g}] N (THRUST_MAX_N: the "
                             "heaviest vehicle accepted at a thrust-to-weight ratio of 2.5)")
        return value

    @model_validator(mode="after")
    def _can_hover(self) -> VehicleConfig:
        max_lift = -min(float(np.polyval(self.thrust_poly, u)) for u in range(0, 4097, 64))
        weight = self.mass_kg * self.gravity
        if max_lift <= weight:
            # blame the field the file set: the mass, unless only thrust_poly was given
            given = self.model_fields_set
            if "thrust_poly" in given and "mass_kg" not in given:
                raise FieldValueError("thrust_poly", self.thrust_poly, (
                    f"lifts at most {max_lift:.2f} N, less than the weight {weight:.2f} N "
                    f"(mass_kg {self.mass_kg:g} kg): the vehicle could not hover"))
            raise FieldValueError("mass_kg", self.mass_kg, (
                f"weighs {weight:.2f} N, more than thrust_poly lifts at most "
                f"({max_lift:.2f} N): the vehicle could not hover (the mass of this "
                "vehicle, or a thrust_poly fitted to it: gs identify thrust)"))
        return self


DiagonalBand = tuple[int, int, float, float, str]
"""Entries ``[start, stop)`` of a covariance's diagonal lie in ``[lo, hi]``: what they are."""

R_DIAGONAL_BANDS: tuple[DiagonalBand, ...] = (
    (0, 3, *variance_band(VICON_POSITION_VARIANCE_TABLE_6_1),
     "Vicon position variances [m^2], 1/1000 to 10^4 x Table 6.1's"),
    (3, 7, *variance_band(VICON_QUATERNION_VARIANCE_TABLE_6_1),
     "Vicon quaternion variances, 1/1000 to 10^4 x Table 6.1's"),
)

P0_DIAGONAL_BANDS: tuple[DiagonalBand, ...] = (
    # the lower bound: a prior tighter than 1e-12 is below what the filter's doubles
    # separate from its other variances; the upper: a spread no lab or vehicle has
    (0, 3, 1e-12, LAB_EXTENT_M ** 2, "position variances [m^2], at most a lab's extent "
     "squared"),
    (3, 7, 1e-12, 1.0, "quaternion variances: a unit quaternion's entries lie in [-1, 1]"),
    (7, 10, 1e-12, 2500.0, "velocity variances [(m/s)^2], at most (50 m/s)^2"),
    (10, 13, 1e-12, 1.0, "gyro bias variances [(rad/s)^2], at most (1 rad/s)^2"),
    (13, 16, 1e-12, 100.0, "accelerometer bias variances [(m/s^2)^2], at most 1 g squared"),
)


def _check_diagonal(value: Covariance, n: int, bands: tuple[DiagonalBand, ...]) -> None:
    """Raise ValueError naming the first diagonal entry outside its band."""
    diagonal = np.diag(covariance_matrix(value, n, "covariance"))
    for start, stop, lo, hi, what in bands:
        for i in range(start, stop):
            if not lo <= diagonal[i] <= hi:
                raise ValueError(f"diagonal entry {i} = {diagonal[i]:g} outside "
                                 f"[{lo:g}, {hi:g}]: {what}")


class EstimatorConfig(ConfigModel):
    """The IMU-driven EKF (thesis Ch. 7). Sensor variances come from the vehicle section."""

    gyro_bias_walk: Annotated[float, within(
        1e-10, 1e-2, "(rad/s)^2/s: at 1e-10 the bias is taken as fixed for hours (0.2 mrad/s "
        "in 10 min), at 1e-2 it wanders 0.1 rad/s in a second, no gyro's")] = 1e-8
    # gyro bias random walk [(rad/s)^2/s]: 2.4 mrad/s (0.14 deg/s) in 10 min, a MEMS gyro's
    # temperature drift in a lab (the thesis tuned Q by hand); much larger walks let the
    # bias estimate follow the noise, and dead reckoning through a Vicon loss drifts more
    acc_bias_walk: Annotated[float, within(
        1e-8, 1.0, "(m/s^2)^2/s: at 1e-8 the bias is taken as fixed for an hour (2.4 mm/s^2 "
        "in 10 min), at 1 it wanders 1 m/s^2 in a second, no accelerometer's")] = 1e-7
    # accelerometer bias random walk [(m/s^2)^2/s]: 7.7 mm/s^2 (0.8 mg) in 10 min
    process_noise_scale: Annotated[float, within(
        1e-3, 1e3, "three decades either side of the measured Table 6.3 variances")] = 1.0
    # multiplies the Table 6.3 IMU variances used as process noise (1 = as measured)
    r_override: Covariance | None = None
    # optional 7x7 (or diagonal 7) Vicon R replacing Table 6.1 [m^2, -]
    initial_covariance: Covariance = Field(
        default_factory=lambda: list(INITIAL_STATE_VARIANCE))
    # 16 diagonal: P, q, v, gyro bias, acc bias (model/sensors.py says what each is)
    gate_probability: Annotated[float, within(
        0.5, 1.0, "a probability: at 0.5 the gate refuses half the honest poses, at 1 it "
        "gates nothing", lo_open=True, hi_open=True)] = 0.9999
    # chi-square innovation gate; 1e-4 false-reject rate per update
    divergence_trace: Annotated[float, within(
        0.0, 1e4, "16-layout units: a trace of 10^4 is a 58 m spread per axis, a failsafe "
        "that never fires in a lab", lo_open=True)] = 10.0
    # covariance trace above which the estimate is declared diverged (failsafe)
    max_vicon_delay_s: Annotated[float, within(
        0.0, 1.0, "s: poses arrive a few ms late (spec); a second-old pose is history",
        lo_open=True)] = 0.2  # older poses are dropped instead of re-propagated
    settle_time_s: Annotated[float, within(
        0.0, 60.0, "s: a minute on the ground is 20 times Ch. 7.4's settling",
        lo_open=True)] = 3.0  # on the ground before take-off, thesis Ch. 7.4 (~3 s)

    @field_validator("r_override")
    @classmethod
    def _r_pd(cls, value: Covariance | None) -> Covariance | None:
        if value is not None:
            check_covariance(value, 7, "r_override")
            _check_diagonal(value, 7, R_DIAGONAL_BANDS)
        return value

    @field_validator("initial_covariance")
    @classmethod
    def _p0_pd(cls, value: Covariance) -> Covariance:
        check_covariance(value, 16, "initial_covariance")
        _check_diagonal(value, 16, P0_DIAGONAL_BANDS)
        return value

    @model_validator(mode="after")
    def _starts_converged(self) -> EstimatorConfig:
        p0 = covariance_matrix(self.initial_covariance, 16, "initial_covariance")
        trace = float(np.trace(p0))
        if trace >= self.divergence_trace:
            raise ValueError(f"divergence_trace {self.divergence_trace:g} is not above the "
                             f"trace of initial_covariance ({trace:g}): the estimator would "
                             "be declared diverged before it started")
        return self


