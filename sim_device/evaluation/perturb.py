"""Perturbed plants for ``gs eval --perturb SEED``: the virtual lab made to differ from the
design model, drawn per seed from stated ranges (the spread a controller must stand: rate
gains and their lag +-30 %, mass and thrust map +-15 %, the motors' lag 10-50 ms).

The controllers are designed on the vehicle section of the configuration (rate gains,
rate-loop time constant, command delay, mass, thrust map); the virtual lab equals that
model unless ``sim.*`` says otherwise. :func:`perturbation` draws one plant per seed as
configuration overrides, so the same plant flies in-process and in real time (the
child ``gs sim-device`` reads them from the configuration it is given).

Every quantity is drawn uniformly and independently in its range, in this order, from
``numpy.random.default_rng([PLANT_STREAM, seed])``:

================================  =======================================================
``sim.k_rate_scale`` (3)          true / model rate gain per axis, 1 +- :data:`RATE_GAIN_SPREAD`
``sim.rate_loop_tau_s``           vehicle's rate-loop time constant x (1 +- :data:`RATE_TAU_SPREAD`)
``sim.mass_scale``                1 +- :data:`MASS_SPREAD`
``sim.thrust_scale``              1 +- :data:`THRUST_SPREAD`
``sim.command_delay_s``           in :data:`COMMAND_DELAY_RANGE_S`
``sim.gyro_bias`` (3)             +- :data:`GYRO_BIAS_MAX` per axis
``sim.acc_bias`` (3)              +- :data:`ACC_BIAS_MAX` per axis
``sim.motor_tau_s``               in :data:`MOTOR_TAU_RANGE_S`
================================  =======================================================

and fixed: ``sim.scale_error`` = :data:`IMU_SCALE_ERROR` (the lab draws each axis's
scale error within it from ``sim.seed``) and ``sim.seed`` = the seed (sensor noise).

>>> perturbation(1)["sim.seed"]
1
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterable, Mapping
from typing import Any

import numpy as np

from groundstation.config import VehicleConfig
from groundstation.errors import ConfigError

RATE_GAIN_SPREAD = 0.30
"""Rate gains: true / model in [0.7, 1.3] per axis, independently [-]."""

RATE_TAU_SPREAD = 0.30
"""Rate-loop time constant: true / model in [0.7, 1.3] [-]."""

MASS_SPREAD = 0.15
"""Mass: true / model in [0.85, 1.15] [-]."""

THRUST_SPREAD = 0.15
"""Thrust map: true lift / polynomial lift in [0.85, 1.15] [-]."""

COMMAND_DELAY_RANGE_S = (0.005, 0.030)
"""True transport delay of a COMMAND [s] (the model's is ``vehicle.command_delay_s``)."""

IMU_SCALE_ERROR = 0.03
"""Bound of each IMU axis's scale error [-] (``sim.scale_error``)."""

MOTOR_TAU_RANGE_S = (0.010, 0.050)
"""True lag of the lift behind the command [s]: half to two and a half times the class's
20 ms (the virtual lab's nominal; the thesis is silent). Drawn last, so a seed's other draws
are those of the box before it had this one."""
GYRO_BIAS_MAX = 0.02
"""Gyro bias bound per axis [rad/s]."""

ACC_BIAS_MAX = 0.15
"""Accelerometer bias bound per axis [m/s^2]."""

PLANT_STREAM = 13
"""Mixed into every plant draw, so the plant of seed s is not the noise stream of seed s."""

NOMINAL_RATE_TAU_S = VehicleConfig().rate_loop_tau_s
"""The default vehicle's rate-loop time constant [s] (0.064)."""

RANGES: dict[str, str] = {
    "rate gains": f"+-{100 * RATE_GAIN_SPREAD:g} % per axis, independently",
    "rate-loop time constant": f"+-{100 * RATE_TAU_SPREAD:g} % of the vehicle's",
    "mass": f"+-{100 * MASS_SPREAD:g} %",
    "thrust map": f"+-{100 * THRUST_SPREAD:g} %",
    "command delay": f"{1e3 * COMMAND_DELAY_RANGE_S[0]:g}-{1e3 * COMMAND_DELAY_RANGE_S[1]:g} ms",
    "IMU scale error": f"up to {100 * IMU_SCALE_ERROR:g} % per axis (drawn by the lab)",
    "gyro bias": f"+-{GYRO_BIAS_MAX:g} rad/s per axis",
    "accelerometer bias": f"+-{ACC_BIAS_MAX:g} m/s^2 per axis",
    "motors' lag": f"{1e3 * MOTOR_TAU_RANGE_S[0]:g}-{1e3 * MOTOR_TAU_RANGE_S[1]:g} ms",
    "sensor noise": "seeded by the seed (sim.seed)",
}
"""The ranges in words, for the report."""


def perturbation(seed: int, rate_loop_tau_s: float = NOMINAL_RATE_TAU_S) -> dict[str, Any]:
    """Configuration overrides (dotted paths) of the plant drawn for ``seed``.

    seed : >= 0; the same seed always gives the same plant.
    rate_loop_tau_s : the vehicle's (model's) rate-loop time constant [s], which the
        drawn ``sim.rate_loop_tau_s`` scatters around.
    ConfigError for a negative seed.
    """
    if seed < 0:
        raise ConfigError(f"perturbation seed {seed}: must be >= 0")
    rng = np.random.default_rng([PLANT_STREAM, seed])

    def around_one(spread: float, n: int | None = None) -> Any:
        draw = rng.uniform(1.0 - spread, 1.0 + spread, n)
        return [float(x) for x in draw] if n is not None else float(draw)

    k_rate = around_one(RATE_GAIN_SPREAD, 3)
    tau = around_one(RATE_TAU_SPREAD)
    mass = around_one(MASS_SPREAD)
    thrust = around_one(THRUST_SPREAD)
    delay = float(rng.uniform(*COMMAND_DELAY_RANGE_S))
    gyro = [float(x) for x in rng.uniform(-GYRO_BIAS_MAX, GYRO_BIAS_MAX, 3)]
    acc = [float(x) for x in rng.uniform(-ACC_BIAS_MAX, ACC_BIAS_MAX, 3)]
    motors = float(rng.uniform(*MOTOR_TAU_RANGE_S))
    return {
        "sim.seed": seed, "sim.k_rate_scale": k_rate, "sim.rate_loop_tau_s": tau * rate_loop_tau_s,
        "sim.mass_scale": mass, "sim.thrust_scale": thrust, "sim.command_delay_s": delay,
        "sim.scale_error": IMU_SCALE_ERROR, "sim.gyro_bias": gyro, "sim.acc_bias": acc,
        "sim.motor_tau_s": motors,
    }


_SEEDS = re.compile(r"^\s*(\d+)\s*(?:-\s*(\d+)\s*)?$")


def parse_seeds(values: Iterable[str]) -> list[int]:
    """Seeds from ``--perturb`` values: ``"3"``, a range ``"1-5"`` (inclusive) or a comma list
    ``"1,4"``; in the order given, each once. ConfigError for anything else."""
    seeds: list[int] = []
    for value in values:
        for part in value.split(","):
            match = _SEEDS.match(part)
            if match is None:
                raise ConfigError(f"--perturb {value!r}: expected a seed (3), a range (1-5) "
                                  "or a comma list (1,4) of seeds >= 0")
            lo = int(match.group(1))
            hi = int(match.group(2)) if match.group(2) is not None else lo
            if hi < lo:
                raise ConfigError(f"--perturb {value!r}: the range is empty ({lo} > {hi})")
            seeds += [s for s in range(lo, hi + 1) if s not in seeds]
    return seeds


PLANT_COLUMNS = ("seed", "rate gains x/y/z [%]", "rate loop tau [ms]", "mass [%]",
                 "thrust [%]", "delay [ms]", "gyro bias x/y/z [rad/s]",
                 "acc bias x/y/z [m/s^2]", "motors [ms]")
"""Columns of :func:`plant_row`."""


def plant_row(seed: int, overrides: Mapping[str, Any]) -> list[str]:
    """One row of the report's table of drawn plants: the deviations from the model
    (gains, mass and thrust in per cent off nominal)."""
    def pct(x: float) -> str:
        return f"{100.0 * (x - 1.0):+.1f}"

    def vec(v: Iterable[float], fmt: str) -> str:
        return " / ".join(format(x, fmt) for x in v)

    tau = overrides["sim.rate_loop_tau_s"]
    return [str(seed), " / ".join(pct(x) for x in overrides["sim.k_rate_scale"]),
            f"{1e3 * tau:.1f}" if tau is not None and math.isfinite(tau) else "-",
            pct(overrides["sim.mass_scale"]), pct(overrides["sim.thrust_scale"]),
            f"{1e3 * overrides['sim.command_delay_s']:.1f}",
            vec(overrides["sim.gyro_bias"], "+.3f"), vec(overrides["sim.acc_bias"], "+.2f"),
            f"{1e3 * motors:.1f}" if (motors := overrides.get("sim.motor_tau_s")) is not None
            else "-"]
