"""Time per controller step (and per stick conversion) at the loop's inputs.

Inputs: 20,000 state estimates and references recorded from a closed-loop
flight of the min-jerk square at the 50 Hz command rate
(``groundstation.control.simulate``, so the controllers see realistic, varying
states), with the reference ``lead_s`` ahead for the controllers that ask for a
preview, built before timing. Each controller's ``step()`` (and its ``sent()``,
which the loop calls after every COMMAND) is timed one call at a time with
``time.perf_counter_ns`` after a warm-up; the script prints median, p99 and max in
microseconds. Targets: p99 <= 100 us for the feed-forward LQR (as it flies, with
the accelerometer's external-force estimate, and without it), <= 50 us for the others;
it exits with status 1 if a controller misses its target.

Run: ``.venv/bin/python benchmarks/bench_controller.py``
"""

from __future__ import annotations

import gc
import statistics
import sys
import time
from collections.abc import Callable

import numpy as np

from groundstation.control import (
    Controller,
    LqrController,
    PidController,
    StickParams,
    to_sticks,
)
from groundstation.control.external_force import ExternalForceObserver
from groundstation.control.hinf import HinfController, default_gain_path, load_hinf_gain
from groundstation.control.lqr_ff import FeedforwardLqr
from groundstation.control.shaping import min_jerk_path
from groundstation.control.simulate import simulate
from groundstation.control.trajectories import square
from groundstation.model import QuadrotorParams
from groundstation.model.quaternion import dcm_from_quat
from groundstation.model.sensors import ACC_VARIANCE_TABLE_6_3
from groundstation.types import ControlOutput, Reference, StateEstimate

N = 20_000
WARMUP = 500
TARGET_P99_US = {"lqr-ff": 100.0, "lqr-ff-no-force": 100.0}
"""Per-controller p99 targets [us]; the others: :data:`DEFAULT_TARGET_US`."""
DEFAULT_TARGET_US = 50.0


def recorded_inputs() -> list[tuple[float, StateEstimate, Reference]]:
    """(t, estimate, reference) along two laps of the square, repeated to N samples; the
    specific force is the flight's acceleration less gravity in body axes, with Table
    6.3's noise (so the external-force estimate learns, and its detector fires now and
    then, as in flight)."""
    sq = min_jerk_path(square())
    run = simulate(FeedforwardLqr(), sq, 40.0)
    g = QuadrotorParams().g
    accel = np.gradient(run.velocity, run.t, axis=0) - np.array([0.0, 0.0, g])
    rng = np.random.default_rng(1)
    noise = rng.standard_normal((len(run.t), 3)) * np.sqrt(ACC_VARIANCE_TABLE_6_3)
    out = []
    for k in range(N):
        i = k % len(run.t)
        t = float(run.t[i])
        q = run.quaternion[i]
        force = dcm_from_quat(q).T @ accel[i] + noise[i]
        est = StateEstimate(t=t, position=run.position[i].copy(), quaternion=q.copy(),
                            velocity_body=run.velocity[i].copy(), omega=run.omega_cmd[i].copy(),
                            gyro_bias=np.zeros(3), acc_bias=np.zeros(3),
                            covariance_diag=np.zeros(16), specific_force=force)
        out.append((t, est, sq.sample(t)))
    return out


def with_external_force() -> FeedforwardLqr:
    """``lqr-ff`` as it flies by default: with the accelerometer's external-force estimate,
    which has seen the vehicle on the floor (it learns only above it)."""
    params = QuadrotorParams()
    observer = ExternalForceObserver(params, 0.02)
    floor = StateEstimate(t=0.0, position=np.zeros(3), quaternion=np.array([1.0, 0, 0, 0]),
                          velocity_body=np.zeros(3), omega=np.zeros(3), gyro_bias=np.zeros(3),
                          acc_bias=np.zeros(3), covariance_diag=np.zeros(16),
                          specific_force=np.array([0.0, 0.0, -params.g]))
    observer.update(floor)
    return FeedforwardLqr(params=params, external_force=observer)


def stepper(ctrl: Controller, inputs: list[tuple[float, StateEstimate, Reference]],
            previews: list[Reference]) -> Callable[[int], object]:
    """One loop step of ``ctrl`` on input k: step (with the preview if it asks), sent."""
    def fn(k: int) -> object:
        t, est, ref = inputs[k]
        out = ctrl.step(t, est, ref, previews[k] if ctrl.lead_s > 0.0 else None)
        ctrl.sent(out, True)
        return out
    return fn


def time_calls(fn: Callable[[int], object]) -> list[float]:
    """Per-call durations [us] of fn(k) for k in range(N), after a warm-up, GC paused."""
    for k in range(WARMUP):
        fn(k)
    gc.disable()
    try:
        out = []
        for k in range(N):
            t0 = time.perf_counter_ns()
            fn(k)
            out.append((time.perf_counter_ns() - t0) / 1000.0)
    finally:
        gc.enable()
    return out


def main() -> int:
    inputs = recorded_inputs()
    sq = min_jerk_path(square())
    controllers: dict[str, Controller] = {
        "lqr-ff": with_external_force(),
        "lqr-ff-no-force": FeedforwardLqr(),
        "lqr-cv": LqrController(reference_model="velocity"),
        "lqr-cp": LqrController(reference_model="position"),
        "lqr-cv-thesis-model": LqrController(design_model="thesis"),
        "pid": PidController(),
        "hinf-rate-loop": HinfController(load_hinf_gain(default_gain_path(True))),
    }
    failed = False
    print(f"{'step() + sent()':<22}{'median us':>10}{'p99 us':>10}{'max us':>10}"
          f"{'target':>10}")
    for name, ctrl in controllers.items():
        previews = [sq.sample(t + ctrl.lead_s) for t, _, _ in inputs]
        durations = time_calls(stepper(ctrl, inputs, previews))
        p99 = float(np.percentile(durations, 99))
        target = TARGET_P99_US.get(name, DEFAULT_TARGET_US)
        failed |= p99 > target
        print(f"{name:<22}{statistics.median(durations):>10.1f}{p99:>10.1f}"
              f"{max(durations):>10.1f}{target:>10.0f}")
    params = StickParams.from_quadrotor(QuadrotorParams())
    outputs = [ControlOutput(omega=np.array([0.1, -0.2, 0.0]) * (k % 7 - 3), f_z=0.3 * (k % 5 - 2))
               for k in range(N)]
    durations = time_calls(lambda k: to_sticks(outputs[k], params))
    print(f"{'to_sticks()':<22}{statistics.median(durations):>10.1f}"
          f"{float(np.percentile(durations, 99)):>10.1f}{max(durations):>10.1f}")
    print(f"targets: {'FAIL' if failed else 'ok'}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
