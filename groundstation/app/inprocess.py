"""Fly the flight core against a virtual lab on its simulated clock.

Everything between the two is real except the transport: COMMAND and CONFIG
frames are encoded to bytes and written into the virtual X-3D, DATA frames come
back as bytes through the same stream decoder, and Vicon datagrams go through
the same pose filter as on the lab PC. Only the pty, the UDP socket and the wall
clock are left out, so a flight runs many times faster than real time and is
the same, bit for bit, for a given seed.

The lab is anything that satisfies :class:`groundstation.lab.Lab`; by default the
installed virtual lab builds one for the configuration the flight's parameters were
assembled from (:func:`groundstation.lab.virtual_lab`).
Used by the tests and the virtual lab's evaluation suite (``gs eval --fast``).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from groundstation.app.recorder import FlightRecorder
from groundstation.app.ticklog import TickLogger
from groundstation.asctec.decoder import StreamDecoder, encode_frame
from groundstation.asctec.messages import ConfigMsg, DataMsg
from groundstation.control.base import Controller
from groundstation.control.trajectory import Trajectory
from groundstation.flight.core import FlightCore, TickResult
from groundstation.flight.inputs import DataFrontEnd, with_vicon
from groundstation.flight.params import FlightParams
from groundstation.flight.supervisor import State, Transition
from groundstation.lab import Lab, virtual_lab
from groundstation.types import FloatArray, Pose
from groundstation.vicon.posefilter import PoseFilter

Event = Callable[["InProcessFlight"], None]
"""A scripted action at a simulated time: inject a fault in ``flight.lab``, move the
pilot's switch, or ``flight.stop_requests += 1`` to simulate SIGINT/SIGTERM."""

_COLUMNS = ("t", "true_t", "state", "true_pos", "est_pos", "ref_pos", "ref_vel", "true_vel",
            "est_vel", "sticks", "mask", "true_q", "est_q")


@dataclass
class FlightTrace:
    """Per-tick arrays of one in-process flight (rows are control ticks).

    t : (N,) tick time [s] (the DATA frame's delivery time); state : (N,) supervisor state;
    true_t : (N,) time of the truth columns [s]: the lab is advanced a whole DATA period
        before its frames are ticked, so the truth is up to one period newer than ``t``
        (interpolate ``lab.truth_log`` for truth at the tick time exactly);
    true_pos, est_pos, ref_pos : (N, 3) NED [m]; ref_vel, true_vel : (N, 3) NED [m/s];
    est_vel : (N, 3) NED [m/s] (estimate rotated to earth axes);
    sticks : (N, 4) sent [roll, pitch, yaw, thrust] (0 when not commanding);
    mask : (N,) ctrl mask of the last COMMAND; true_q, est_q : (N, 4) quaternions.
    """

    rows: dict[str, list[FloatArray | float]] = field(
        default_factory=lambda: {name: [] for name in _COLUMNS})

    def arrays(self) -> dict[str, FloatArray]:
        """The trace as numpy arrays."""
        return {name: np.asarray(values, dtype=float) for name, values in self.rows.items()}


@dataclass(frozen=True)
class FlightResult:
    """Outcome of an in-process flight."""

    final_state: State
    success: bool
    transitions: list[Transition]
    trace: dict[str, FloatArray]
    lab: Lab
    core: FlightCore

    def during(self, state: State) -> np.ndarray:
        """Boolean mask of the ticks spent in ``state``."""
        return np.asarray(self.trace["state"] == int(state))


def _rotate_to_earth(q: FloatArray, v: FloatArray) -> FloatArray:
    from groundstation.model.quaternion import rotate

    return rotate(q, v)


class InProcessFlight:
    """One flight of :class:`FlightCore` against a :class:`~groundstation.lab.Lab`, stepped
    by hand, with the flight's parameters (``lab`` None: the installed virtual lab for
    the configuration they were assembled from).

    :meth:`run` flies to a terminal state; :meth:`step` advances one DATA period
    for tests that interleave their own checks.
    """

    def __init__(self, params: FlightParams, *, lab: Lab | None = None,
                 controller: Controller | None = None, trajectory: Trajectory | None = None,
                 duration_s: float | None = None,
                 recorder: FlightRecorder | None = None) -> None:
        self.params = params
        self.lab: Lab = lab if lab is not None else virtual_lab().in_process(params.source)
        self.core = FlightCore(params, controller=controller, trajectory=trajectory,
                               duration_s=duration_s)
        self._profile = params.link.crc_profile
        self._decoder = StreamDecoder(self._profile)
        self._front = DataFrontEnd(params.imu)
        self._poses = PoseFilter.from_params(params.vicon.filter)
        self._period = params.link.data_period_ms / 1000.0
        self.stop_requests = 0
        self.trace = FlightTrace()
        self.compute_times: list[float] = []
        """Wall time of each FlightCore.tick [s]: the code's back-to-back cost."""
        self._last: TickResult | None = None
        self._ticklog = TickLogger(recorder) if recorder is not None else None
        """With a recorder the flight writes the same log as the daemon (times are the
        lab's simulated seconds; timing columns hold the core's compute time)."""
        self.lab.write(encode_frame(ConfigMsg(params.link.sensor_mask,
                                              params.link.data_period_ms), self._profile))

    @property
    def pose_filter(self) -> PoseFilter:
        """The pose filter every Vicon datagram goes through (read its :meth:`health`)."""
        return self._poses

    def _vicon(self) -> list[Pose]:
        out = []
        for datagram in self.lab.vicon_datagrams():
            pose = self._poses.process(datagram.data, datagram.t)
            if pose is not None:
                out.append(pose)
        return out

    def step(self) -> None:
        """Advance the lab by one DATA period and tick the core once per DATA frame."""
        received: list[tuple[float, DataMsg]] = []
        for t_rx, data in self.lab.advance(self._period):
            received.extend((t_rx, m) for m in self._decoder.feed(data) if isinstance(m, DataMsg))
        poses = self._vicon()
        if not received:  # stalled stream: the deadline still ticks the supervisor
            self._tick(self.lab.t, None, poses)
            return
        for i, (t_rx, msg) in enumerate(received):
            self._tick(t_rx, msg, poses if i == 0 else [])

    def _tick(self, t: float, msg: DataMsg | None, poses: Sequence[Pose]) -> None:
        imu = self._front.receive(t, msg) if msg is not None else None
        rate = self._poses.rate
        health = with_vicon(self._front.health(t, rate.time_since_pose(t), rate.rate(t)),
                            self._poses.evidence(t), self._poses.diagnosis)
        start = time.perf_counter()
        result = self.core.tick(t, imu, poses, self._front.status, health, self.stop_requests)
        compute = time.perf_counter() - start
        self.compute_times.append(compute)
        if result.due:
            self.lab.write(encode_frame(result.command, self._profile))
        self._last = result
        self._record(t, result)
        if self._ticklog is not None:
            self._ticklog.record(t, msg, imu, list(poses), result, compute=compute, jitter=0.0,
                                 latency=compute)

    def _record(self, t: float, r: TickResult) -> None:
        truth = self.lab.truth
        est = r.estimate
        rows = self.trace.rows
        rows["t"].append(t)
        rows["true_t"].append(truth.t)
        rows["state"].append(float(r.state))
        rows["true_pos"].append(truth.position.copy())
        rows["true_vel"].append(truth.velocity.copy())
        rows["true_q"].append(truth.quaternion.copy())
        nan3 = np.full(3, math.nan)
        rows["est_pos"].append(est.position.copy() if est is not None else nan3)
        rows["est_vel"].append(_rotate_to_earth(est.quaternion, est.velocity_body)
                               if est is not None else nan3)
        rows["est_q"].append(est.quaternion.copy() if est is not None else np.full(4, math.nan))
        rows["ref_pos"].append(r.reference.position.copy())
        rows["ref_vel"].append(r.reference.velocity.copy())
        s = r.sticks
        rows["sticks"].append(np.array([s.roll, s.pitch, s.yaw, s.thrust], dtype=float)
                              if s is not None else np.zeros(4))
        rows["mask"].append(float(r.command.ctrl))

    def run(self, max_time_s: float = 300.0,
            events: Sequence[tuple[float, Event]] = ()) -> FlightResult:
        """Fly until the supervisor reaches a terminal state (or ``max_time_s``).

        events : (simulated time [s], action) pairs run once when the time is reached.
        """
        pending = sorted(events, key=lambda e: e[0])
        while not self.core.supervisor.terminal and self.lab.t < max_time_s:
            while pending and self.lab.t >= pending[0][0]:
                pending.pop(0)[1](self)
            self.step()
        # The final COMMAND (ctrl mask 0) the daemon sends when it stops.
        from groundstation.asctec.messages import CommandMsg

        self.lab.write(encode_frame(CommandMsg.release(), self._profile))
        self.lab.advance(0.05)
        sup = self.core.supervisor
        return FlightResult(sup.state, sup.success, list(sup.transitions), self.trace.arrays(),
                            self.lab, self.core)


def fly_in_process(params: FlightParams, *, lab: Lab | None = None,
                   controller: Controller | None = None, trajectory: Trajectory | None = None,
                   duration_s: float | None = None, max_time_s: float = 300.0,
                   events: Sequence[tuple[float, Event]] = (),
                   recorder: FlightRecorder | None = None) -> FlightResult:
    """Fly one whole flight in-process; see :class:`InProcessFlight`."""
    flight = InProcessFlight(params, lab=lab, controller=controller, trajectory=trajectory,
                             duration_s=duration_s, recorder=recorder)
    return flight.run(max_time_s=max_time_s, events=events)
