"""``gs replay LOG``: re-run the estimator and the controller on a recorded flight.

The estimator is fed the logged IMU samples and Vicon poses tick by tick through
the flight core's own estimator step (initialisation included), and its
estimate is compared with the logged one. The controller is fed the *logged*
estimate, reference and look-ahead reference, on the ticks a COMMAND went out
(it steps once per COMMAND), and is told what the COMMAND carried, so its
differences are its own, not the estimator's; its sticks are compared with the
logged controller sticks (before the channel handover). The supervisor and
mission are not re-run: the logged references and states drive the replay.

With the configuration the flight used, the differences measure how exactly a
flight can be reproduced (the log keeps one Vicon pose per tick, so a tick that
fused two poses replays slightly differently); with a changed configuration
(``--config``) they show what the change would have done on that flight.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import yaml

from groundstation.app.recorder import read_flight
from groundstation.config import GroundStationConfig, validate_config
from groundstation.control.sticks import StickParams, to_sticks
from groundstation.flight.assembly import assemble
from groundstation.flight.core import FlightCore
from groundstation.flight.supervisor import State
from groundstation.model import inputs_from_sticks
from groundstation.model.quaternion import conjugate, multiply
from groundstation.types import ControlOutput, ImuSample, Pose, Reference, StateEstimate, Sticks

_CONTROLLED = frozenset({State.TAKEOFF, State.TRACK, State.HOLD, State.LAND})


@dataclass(frozen=True)
class ReplayReport:
    """Differences between a replay and the recorded flight.

    rows : ticks in the log; estimator_ticks : ticks where both estimates exist
    position_rms_m, position_max_m : replayed minus logged estimate position [m]
    attitude_max_rad : largest rotation between replayed and logged attitude [rad]
    controller_ticks : ticks the controller was replayed on
    stick_max : largest |replayed - logged| controller stick per channel
        (roll, pitch, yaw, thrust) [RC units]
    """

    rows: int
    estimator_ticks: int
    position_rms_m: float
    position_max_m: float
    attitude_max_rad: float
    controller_ticks: int
    stick_max: tuple[int, int, int, int]

    def lines(self) -> list[str]:
        """Human-readable summary."""
        return [
            f"replayed {self.rows} ticks",
            f"  estimator ({self.estimator_ticks} ticks): position difference RMS "
            f"{1e3 * self.position_rms_m:.3f} mm, max {1e3 * self.position_max_m:.3f} mm; "
            f"attitude max {1e3 * self.attitude_max_rad:.3f} mrad",
            f"  controller ({self.controller_ticks} ticks): largest stick difference "
            f"roll {self.stick_max[0]}, pitch {self.stick_max[1]}, yaw {self.stick_max[2]}, "
            f"thrust {self.stick_max[3]}",
        ]


def _logged_estimate(row: np.void) -> StateEstimate:
    return StateEstimate(
        t=float(row["t"]), position=np.array(row["est_position"], dtype=float),
        quaternion=np.array(row["est_quaternion"], dtype=float),
        velocity_body=np.array(row["est_velocity_body"], dtype=float),
        omega=np.array(row["est_omega"], dtype=float),
        gyro_bias=np.array(row["est_gyro_bias"], dtype=float),
        acc_bias=np.array(row["est_acc_bias"], dtype=float),
        covariance_diag=np.array(row["est_covariance_diag"], dtype=float),
        # the newest sample, bias-corrected, as the estimator hands it on
        specific_force=np.array(row["acc"], dtype=float) - np.array(row["est_acc_bias"],
                                                                   dtype=float),
    )


def _logged_reference(row: np.void, prefix: str) -> Reference:
    """The reference (``ref``) or look-ahead reference (``preview``) of a log row."""
    return Reference(
        float(row["t"]), np.array(row[f"{prefix}_position"], dtype=float),
        np.array(row[f"{prefix}_velocity"], dtype=float),
        acceleration=np.array(row[f"{prefix}_acceleration"], dtype=float),
        yaw=float(row[f"{prefix}_yaw"]), jerk=np.array(row[f"{prefix}_jerk"], dtype=float),
        yaw_rate=float(row[f"{prefix}_yaw_rate"]),
    )


def _angle(q_a: np.ndarray, q_b: np.ndarray) -> float:
    d = multiply(conjugate(q_a), q_b)
    return 2.0 * math.atan2(float(np.linalg.norm(d[1:])), abs(float(d[0])))


def replay_flight(log: str, config: GroundStationConfig | None = None) -> ReplayReport:
    """Replay the flight log in ``log`` (a flight directory) with ``config`` (default: the
    configuration the flight used). Raises RecorderError for an unreadable log."""
    rows, _meta, logged_config = read_flight(log)
    cfg = config if config is not None else validate_config(yaml.safe_load(logged_config), log)
    params = assemble(cfg)
    core = FlightCore(params)
    quad = params.vehicle
    sticks_params = StickParams.from_quadrotor(quad)
    pos_sq, pos_max, att_max, n_est = 0.0, 0.0, 0.0, 0
    stick_max = np.zeros(4, dtype=int)
    n_ctrl = 0
    last_counter: int | None = None
    previous_state = State.PREFLIGHT
    for row in rows:
        counter = int(row["imu_counter"])
        imu = None
        if counter != last_counter:
            imu = ImuSample(float(row["imu_t"]), np.array(row["gyro"], dtype=float),
                            np.array(row["acc"], dtype=float), counter)
            last_counter = counter
        poses = [Pose(float(row["vicon_t"]), np.array(row["vicon_position"], dtype=float),
                      np.array(row["vicon_quaternion"], dtype=float))] \
            if row["vicon_valid"] else []
        est = core.estimate_step(imu, poses, still=core.standing(previous_state, poses))
        logged_ok = bool(np.all(np.isfinite(row["est_position"])))
        if est is not None and logged_ok:
            err = float(np.linalg.norm(est.position - row["est_position"]))
            pos_sq += err * err
            pos_max = max(pos_max, err)
            att_max = max(att_max, _angle(est.quaternion, np.asarray(row["est_quaternion"])))
            n_est += 1
        state = State(int(row["state"]))
        if state is State.TAKEOFF and previous_state is State.PREFLIGHT:
            core.controller.reset()
        previous_state = state
        if state in _CONTROLLED and logged_ok and bool(row["cmd_sent"]):
            ref = _logged_reference(row, "ref")
            preview = _logged_reference(row, "preview")
            out = core.controller.step(float(row["t"]), _logged_estimate(row), ref,
                                       preview if math.isfinite(preview.yaw) else None)
            sent = Sticks(roll=int(row["cmd_roll"]), pitch=int(row["cmd_pitch"]),
                          yaw=int(row["cmd_yaw"]), thrust=int(row["cmd_thrust"]))
            u = inputs_from_sticks(sent, quad)
            core.controller.sent(ControlOutput(omega=u[0:3], f_z=float(u[3])),
                                 bool(row["cmd_automatic"]))
            sticks, _ = to_sticks(out, sticks_params)
            logged = (row["ctrl_roll"], row["ctrl_pitch"], row["ctrl_yaw"], row["ctrl_thrust"])
            replayed = (sticks.roll, sticks.pitch, sticks.yaw, sticks.thrust)
            diff = np.abs(np.array(replayed, dtype=int) - np.array(logged, dtype=int))
            stick_max = np.maximum(stick_max, diff)
            n_ctrl += 1
    return ReplayReport(
        rows=len(rows), estimator_ticks=n_est,
        position_rms_m=math.sqrt(pos_sq / n_est) if n_est else math.nan,
        position_max_m=pos_max if n_est else math.nan, attitude_max_rad=att_max,
        controller_ticks=n_ctrl,
        stick_max=(int(stick_max[0]), int(stick_max[1]), int(stick_max[2]),
                   int(stick_max[3])),
    )
