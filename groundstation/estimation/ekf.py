"""IMU-driven Extended Kalman Filter (thesis Ch. 7.2-7.3).

The IMU drives the prediction (gyro and accelerometer as model inputs); Vicon
position and attitude are the measurements. Interface state (16,) =
``[P (NED, m), q (scalar first, eCb), v (body FRD, m/s), b_g (rad/s), b_a (m/s^2)]``
with ``true = measured - bias`` (see :mod:`.imu_model`).

Formulation (documented choice): a multiplicative error-state EKF. The
covariance is kept on the 15-dof error ``[dP, dtheta, dv, db_g, db_a]`` with a
body-frame attitude error ``q_true = q ⊗ exp(dtheta)``; the quaternion stays a
unit quaternion and its covariance is never singular. A Vicon quaternion enters
as the 3-dof residual ``log(q^-1 ⊗ q_vicon)`` (sign matched to the prediction:
``q`` and ``-q`` are the same attitude) with ``R = 4 var(q1..q3)`` of Table 6.1.
This replaces the thesis's additive 4x4 quaternion update, whose ``R`` (``var q0
= 1e-9``) and state covariance are both rank-deficient on the unit sphere.

Numerics: RK4 on the nominal model with inputs linear between samples;
``Phi = I + F T + F^2 T^2 / 2`` (second order, better than eq. 7.24's ``I + F T``);
Joseph-form update; Cholesky solves (LAPACK ``potrf``/``potrs``), never an inverse;
scratch arrays allocated once. The covariance reset after injecting an attitude
correction (``I - [dtheta/2 ×]``) is omitted: corrections are a few mrad. A
covariance that stops being finite or positive definite raises
:class:`~groundstation.errors.EstimatorError`; bad samples are counted and skipped.

Timing: the filter time is the last IMU sample. A pose is applied at its own
time stamp: a newer one waits until the IMU passes it; an older one (within
``max_vicon_delay``) restores the checkpoint before it and re-propagates the
stored IMU samples, re-applying the poses fused since.

Fault handling (Ch. 7.3): Algorithm 1 (a repeated IMU counter/values or a
repeated pose is not new information and is skipped - the thesis's ``R = 1e8``
has the same effect) and a chi-square innovation gate that rejects and counts
outliers. Algorithm 2 (the lab's lost-tracking encodings) belongs to the pose
filter (:mod:`groundstation.vicon.posefilter`), which knows the raw values: an
identity attitude is a level vehicle at heading 0 as far as the filter knows. A
pose outside the plausible volume is refused before any arithmetic.

The evidence outranks the estimate. After persistent gating the filter
re-anchors position and attitude on ``gate_reset_count`` consecutive gated poses
that agree with each other (never on one pose):

* at once (``gate_reset_after``) when the IMU prediction explains them within its
  covariance plus what the IMU may have missed (a touchdown that clipped the
  accelerometer): an ordinary correction;
* after ``evidence_after`` without a fused pose even when it does not: poses that
  keep agreeing with each other but not with the estimate mean the estimate is
  wrong (an accelerometer saturated by a thrust fault, a knock), and refusing the
  truth indefinitely flies the vehicle blind. Such a re-anchoring is counted
  (:attr:`Ekf.overruled`) and the supervisor treats it as a failsafe.

A repeated pose is one with identical values: a frame number alone says nothing
(another sender may reuse Tracker's). The skip holds in the air only: on the floor a sender
without noise (a simulator's) repeats the still vehicle's pose exactly, and skipping
every pose would leave the filter to dead-reckon on the IMU's biases until the
preflight refuses it (the caller says when the vehicle stands: ``update(still=)``).
"""

from __future__ import annotations

import math
import struct
from bisect import insort
from collections import deque
from collections.abc import Sequence

import numpy as np
from scipy.linalg import lapack

from groundstation.errors import EstimatorError
from groundstation.estimation.history import History
from groundstation.estimation.imu_model import N_ERR, error_jacobian, jacobian_flat_index, propagate
from groundstation.estimation.init import initial_state
from groundstation.estimation.records import EkfHealth, EkfParams, InitReport, UpdateResult
from groundstation.types import FloatArray, ImuSample, Pose, StateEstimate

__all__ = ["Ekf"]

_NAN = float("nan")
_NOT_INIT = UpdateResult(False, _NAN, "not_initialised")
_POSITION_SLACK = 0.02  # [m] jump always allowed between reset candidates (the pose filter's)
_ANGLE_SLACK = 0.05  # [rad] rotation always allowed between reset candidates (likewise)
FORCED_VELOCITY_VAR = 1.0
"""Velocity variance per axis after a re-anchoring the IMU did not explain [(m/s)^2]: the
IMU missed a motion (a saturated accelerometer), so the velocity is known to about 1 m/s
and the next poses correct it; large enough to accept them at 10 Hz, small enough that
the covariance stays below the divergence trace."""


class _Fused:
    """A pose fused into the estimate, kept for re-propagation."""

    __slots__ = ("mode", "pose", "t")

    def __init__(self, pose: Pose, mode: str) -> None:
        self.t = float(pose.t)
        self.pose = pose
        self.mode = mode  # "ok", "reset" or "forced" (a re-anchoring the IMU did not explain)

    def __lt__(self, other: _Fused) -> bool:
        return self.t < other.t


class Ekf:
    """IMU-driven EKF. Call :meth:`initialise`, then :meth:`predict` for every IMU
    sample and :meth:`update` for every Vicon pose, in any interleaving."""

    def __init__(self, params: EkfParams | None = None) -> None:
        p = params if params is not None else EkfParams()
        self.params = p
        self._g = p.g
        s = p.process_noise_scale * p.imu_period
        self._sg = [v * s for v in p.gyro_var]  # gyro noise density [(rad/s)^2 s]
        self._sa = [v * s for v in p.acc_var]  # accelerometer noise density [(m/s^2)^2 s]
        self._qbias = np.array([p.gyro_bias_walk] * 3 + [p.acc_bias_walk] * 3)
        self._r = p.measurement_variance()  # R is diagonal (6,)
        self._R = np.diag(self._r)
        # the chi-square quantile of 6 degrees of freedom, as scipy.stats.chi2.ppf gives it,
        # from scipy.special: scipy.stats takes a second or more to import, paid by every
        # daemon, and the CLI's commands that never build a filter should not wait at all
        from scipy.special import chdtri

        self._gate = float(chdtri(6, 1.0 - p.gate_probability))
        self._r_reset = self._r + np.r_[[p.reset_position_sigma**2] * 3,
                                        [p.reset_attitude_sigma**2] * 3]
        self._volume = p.plausible_volume
        self._fidx, fconst = jacobian_flat_index()
        self._F = fconst
        self._I = np.eye(N_ERR)
        self._Phi = np.empty((N_ERR, N_ERR))
        self._FF = np.empty((N_ERR, N_ERR))
        self._T = np.empty((N_ERR, N_ERR))
        self._rhs = np.empty((6, N_ERR + 1))
        self._y = np.empty(6)
        self._x = np.zeros(16)
        self._P = np.zeros((N_ERR, N_ERR))  # updated in place only: the views below stay valid
        self._P36 = self._P[3:9, 3:9]
        self._Q6 = np.zeros((6, 6))
        self._Q6flat = self._Q6.reshape(-1)
        self._Pbias_diag = self._P.reshape(-1)[9 * (N_ERR + 1) :: N_ERR + 1]
        self._gyro = np.zeros(3)
        self._acc = np.zeros(3)
        self._t = _NAN
        self._hist = History(math.ceil(p.max_vicon_delay / p.imu_period) + 8)
        self._fused: deque[_Fused] = deque()
        self._pending: list[_Fused] = []
        self._initialised = False
        self._last_pose: Pose | None = None
        self._last_imu: tuple[int, list[float], list[float]] | None = None
        self._ahead: tuple[bytes, FloatArray] | None = None
        """The last :meth:`estimate_ahead`'s one step: its inputs (state, inputs at both
        ends, step, as bytes) and the state it reached. The next prediction usually takes
        the same step from the same state (no pose between), and then reuses the result
        instead of integrating the same numbers again."""
        self._reset_counters()

    # ------------------------------------------------------------------ public API
    def initialise(self, pose: Pose, imu_samples: Sequence[ImuSample] = ()) -> InitReport:
        """Start (or restart) from a Vicon fix and optional IMU samples at rest.

        Position and attitude come from ``pose``, velocity is zero, biases come
        from the IMU samples when they are stationary and agree with gravity
        (see :class:`InitReport`); the covariance is ``params.initial_variance``.
        The filter time is the last IMU sample's time (or ``pose.t``).
        """
        x0, report = initial_state(pose, imu_samples, self.params)
        self._reset_counters()
        self._hist.clear()
        self._fused.clear()
        self._pending.clear()
        self._x[:] = x0
        self._P[:] = np.diag(self.params.initial_error_variance())
        self._t = report.t
        if imu_samples:
            last = imu_samples[-1]
            self._gyro[:] = last.gyro
            self._acc[:] = last.acc
            self._last_imu = (last.counter, last.gyro.tolist(), last.acc.tolist())
        else:
            self._first_imu = True
        self._t_fix = float(pose.t)
        self._last_pose = pose
        self._initialised = True
        self._hist.push(self._t, self._x, self._P, self._gyro, self._acc)
        return report

    def predict(self, imu: ImuSample) -> None:
        """Propagate to ``imu.t`` with this sample (and apply queued poses on the way).

        Skips (and counts) samples before :meth:`initialise`, non-finite ones,
        repeats (Algorithm 1) and ones not newer than the filter time.
        """
        if not self._initialised:
            return
        g_list, a_list = imu.gyro.tolist(), imu.acc.tolist()
        if not all(map(math.isfinite, g_list + a_list)):
            self.invalid_imu += 1
            return
        last = self._last_imu
        if last is not None and (
            imu.counter == last[0]
            or (self.params.imu_repeat_on_identical and g_list == last[1] and a_list == last[2])
        ):
            self.repeated_imu += 1
            return
        if self._first_imu:  # no input known at the filter time yet: this sample defines it
            self._gyro[:] = imu.gyro
            self._acc[:] = imu.acc
            self._first_imu = False
            if imu.t <= self._t:
                self._last_imu = (imu.counter, g_list, a_list)
                self._hist.overwrite_input_last(self._gyro, self._acc)
                return
        if not imu.t > self._t:
            self.stale_imu += 1
            return
        self._last_imu = (imu.counter, g_list, a_list)
        due: list[_Fused] = []
        while self._pending and self._pending[0].t <= imu.t:
            due.append(self._pending.pop(0))
        self._advance(float(imu.t), imu.gyro, imu.acc, due, None)
        self._hist.push(self._t, self._x, self._P, self._gyro, self._acc)
        self._check_finite()

    def update(self, pose: Pose, *, still: bool = False) -> UpdateResult:
        """Fuse one Vicon pose at its own time stamp ``pose.t``; see :class:`UpdateResult`.

        ``still``: the vehicle stands on the floor (the caller knows: the flight core's
        :meth:`~groundstation.flight.core.FlightCore.standing`). A pose that repeats the
        previous one exactly is then fused: it is a still vehicle seen by a sender without
        noise (a simulator's), and a held sample of a still vehicle is true as well.
        Otherwise it is skipped as a held sample (see the module docstring)."""
        if not self._initialised:
            return _NOT_INIT
        bad = self._screen(pose, still)
        if bad is not None:
            return bad
        t = float(pose.t)
        if t > self._t:
            if t - self._t > self.params.max_vicon_delay:
                self.future += 1
                return UpdateResult(False, _NAN, "future")
            insort(self._pending, _Fused(pose, "ok"))
            return UpdateResult(True, _NAN, "deferred")
        if t == self._t:
            result = self._fuse(pose, gate=True)
            self._hist.overwrite_last(self._x, self._P)
            return result
        if t < self._hist.oldest_time() or self._t - t > self.params.max_vicon_delay:
            self.too_old += 1
            return UpdateResult(False, _NAN, "too_old")
        return self._replay(pose)

    def estimate(self) -> StateEstimate:
        """The current estimate at the filter time (new arrays; safe to keep)."""
        return self._estimate_of(self._t, self._x, self._gyro)

    def estimate_ahead(self, imu: ImuSample) -> StateEstimate:
        """The estimate at ``imu.t``, predicted from the filter state with the nominal
        model only; the filter itself does not move (call :meth:`predict` for that).

        This is the output side of a filter that runs one IMU sample behind (the
        flight core's arrangement, as PX4's ekf2 runs on a delayed horizon): Vicon
        poses, which arrive stamped a few ms in the past, then land after the filter
        time and are fused in order inside the next :meth:`predict` instead of
        restoring a checkpoint and re-propagating. Poses queued for times up to
        ``imu.t`` are not applied here (they are at the next :meth:`predict`), and the
        covariance is the filter's, at the filter time (its attitude block mapped to
        the predicted quaternion). A sample that
        :meth:`predict` would skip (not newer, non-finite, a repeated counter) gives
        :meth:`estimate`.
        """
        dt = float(imu.t) - self._t
        if not self._initialised or not dt > 0.0 or self._first_imu \
                or (self._last_imu is not None and imu.counter == self._last_imu[0]) \
                or not bool(np.isfinite(imu.gyro).all() and np.isfinite(imu.acc).all()):
            return self.estimate()
        x = self._x.copy()
        g0, a0 = self._gyro, self._acc
        steps = self._substeps(dt, imu.gyro, imu.acc)
        key = _step_key(x, g0, a0, imu.gyro, imu.acc, dt) if len(steps) == 1 else None
        for h, g1, a1 in steps:  # as the filter steps
            propagate(x, g0, a0, g1, a1, h, self._g, x)
            g0, a0 = g1, a1
        self._ahead = None if key is None else (key, x.copy())
        return self._estimate_of(float(imu.t), x, imu.gyro, imu.acc)

    def _estimate_of(self, t: float, x: FloatArray, gyro: FloatArray,
                     acc: FloatArray | None = None) -> StateEstimate:
        """A StateEstimate of state ``x`` at ``t`` with the measured ``gyro`` and ``acc``
        there (default: the filter's last input) and the filter's covariance (the
        quaternion block mapped from the attitude error)."""
        P = self._P
        q0, q1, q2, q3 = x[3:7].tolist()
        Xi = np.array([[-q1, -q2, -q3], [q0, -q3, q2], [q3, q0, -q1], [-q2, q1, q0]])
        qvar = 0.25 * np.einsum("ij,jk,ik->i", Xi, P[3:6, 3:6], Xi)
        d = np.diagonal(P)
        cov = np.concatenate((d[0:3], qvar, d[6:15]))
        return StateEstimate(
            t=t,
            position=x[0:3].copy(),
            quaternion=x[3:7].copy(),
            velocity_body=x[7:10].copy(),
            omega=gyro - x[10:13],
            gyro_bias=x[10:13].copy(),
            acc_bias=x[13:16].copy(),
            covariance_diag=cov,
            specific_force=(self._acc if acc is None else acc) - x[13:16],
        )

    def health(self) -> EkfHealth:
        """Counters and consistency figures (see :class:`EkfHealth`)."""
        trace = self._trace16() if self._initialised else _NAN
        return EkfHealth(
            t=self._t,
            initialised=self._initialised,
            time_since_fix=self._t - self._t_fix if self._initialised else math.inf,
            covariance_trace=trace,
            diverged=bool(trace > self.params.divergence_trace),
            last_nis=self.last_nis,
            updates=self.updates,
            gated=self.gated,
            repeated_poses=self.repeated_poses,
            forced_resets=self.forced_resets,
            too_old=self.too_old + self.future,
            invalid_poses=self.invalid_poses,
            resets=self.resets,
            late_poses=self.late_poses,
            repeated_imu=self.repeated_imu,
            invalid_imu=self.invalid_imu,
            stale_imu=self.stale_imu,
            implausible_poses=self.implausible_poses,
            refused_resets=self.refused_resets,
        )

    @property
    def verdicts(self) -> tuple[int, int, float]:
        """Poses judged (fused or gated), poses refused for any reason, and the last NIS:
        see :attr:`groundstation.estimation.base.Estimator.verdicts`."""
        refused = (self.gated + self.repeated_poses + self.too_old + self.future
                   + self.invalid_poses + self.implausible_poses)
        return self.updates + self.gated, refused, self.last_nis

    @property
    def overruled(self) -> tuple[int, str]:
        """How often the evidence overruled the estimate (consistent poses it could not
        explain re-anchored it after ``evidence_after``), and a line on the last time."""
        return self.forced_resets, self._overruled_reason

    @property
    def time_since_fix(self) -> float:
        """Filter time minus the newest fused pose's time [s] (inf before
        :meth:`initialise`): how long the estimate has gone without Vicon, whether
        Vicon was silent or its poses were refused (the cheap subset of :meth:`health`)."""
        return self._t - self._t_fix if self._initialised else math.inf

    @property
    def diverged(self) -> bool:
        """True if the covariance trace exceeds ``divergence_trace`` or is not finite
        (the per-tick subset of :meth:`health`; False before :meth:`initialise`)."""
        if not self._initialised:
            return False
        trace = self._trace16()
        return not trace <= self.params.divergence_trace

    def _trace16(self) -> float:
        """Trace of the covariance in the 16-state layout, without building it: the
        quaternion block is ``Xi P_tt Xi^T / 4`` and ``Xi^T Xi = |q|^2 I = I``, so its trace
        is ``trace(P_tt) / 4``."""
        P = self._P
        return float(P.trace()) - 0.75 * float(P[3, 3] + P[4, 4] + P[5, 5])

    @property
    def state(self) -> FloatArray:
        """Copy of the 16-state ``[P, q, v, b_g, b_a]``."""
        return self._x.copy()

    @property
    def error_covariance(self) -> FloatArray:
        """Copy of the 15x15 error-state covariance ``[dP, dtheta, dv, db_g, db_a]``."""
        return self._P.copy()

    # ------------------------------------------------------------------ internals
    def _reset_counters(self) -> None:
        self.updates = self.gated = self.repeated_poses = self.forced_resets = 0
        self.too_old = self.future = self.invalid_poses = self.resets = self.late_poses = 0
        self.repeated_imu = self.invalid_imu = self.stale_imu = 0
        self.implausible_poses = self.refused_resets = 0
        self.consecutive_gated = 0
        self._candidates: list[tuple[Pose, bool]] = []  # consistent gated poses, explained
        self._overruled_reason = ""
        self.last_nis = _NAN
        self._first_imu = False
        self._t_fix = _NAN
        self._last_pose = None
        self._last_imu = None

    def _screen(self, pose: Pose, still: bool) -> UpdateResult | None:
        """Algorithm 1/2 and validity checks; None if the pose is usable (``still``: see
        :meth:`update`)."""
        p, q = pose.position.tolist(), pose.quaternion.tolist()
        n2 = sum(c * c for c in q)
        if len(p) != 3 or len(q) != 4 or not all(map(math.isfinite, p + q)) or abs(n2 - 1) > 0.1:
            self.invalid_poses += 1
            return UpdateResult(False, _NAN, "invalid")
        box = self._volume
        if box is not None and not all(lo <= v <= hi for v, (lo, hi) in zip(p, box, strict=True)):
            self.implausible_poses += 1
            return UpdateResult(False, _NAN, "implausible")
        last = self._last_pose
        self._last_pose = pose
        if (not still and last is not None and p == last.position.tolist()
                and q == last.quaternion.tolist()):
            self.repeated_poses += 1
            return UpdateResult(False, _NAN, "repeated")
        return None

    def _advance(
        self, t1: float, gyro1: FloatArray, acc1: FloatArray,
        poses: list[_Fused], new: _Fused | None,
    ) -> UpdateResult | None:  # fmt: skip
        """Propagate to ``t1`` (input ``gyro1, acc1`` there), fusing ``poses`` (sorted,
        times in ``(t, t1]``) at their time stamps. Returns the result for ``new``."""
        result = None
        if not poses:
            self._propagate_to(t1, gyro1, acc1)
            return None
        t0, g0, a0 = self._t, self._gyro.copy(), self._acc.copy()
        span = t1 - t0
        for item in poses:
            f = (item.t - t0) / span
            self._propagate_to(item.t, g0 + f * (gyro1 - g0), a0 + f * (acc1 - a0))
            r = self._refuse(item, new)
            result = r if r is not None else result
        self._propagate_to(t1, gyro1, acc1)
        return result

    def _refuse(self, item: _Fused, new: _Fused | None) -> UpdateResult | None:
        """Fuse a live/new pose with the gate, or re-apply an already fused one."""
        if new is None or item is new:
            return self._fuse(item.pose, gate=True)
        self._correct(item.pose, gate=False, reset=item.mode != "ok",
                      forced=item.mode == "forced")
        return None

    def _propagate_to(self, t: float, gyro: FloatArray, acc: FloatArray) -> None:
        """Integrate state and covariance from the filter time to ``t`` (input linear)."""
        dt_total = t - self._t
        if dt_total > 0.0:
            for h, g1, a1 in self._substeps(dt_total, gyro, acc):
                self._step(h, g1, a1)
        self._t = t
        self._gyro[:] = gyro
        self._acc[:] = acc

    def _substeps(self, dt: float, gyro: FloatArray, acc: FloatArray
                  ) -> list[tuple[float, FloatArray, FloatArray]]:
        """``(h, gyro_end, acc_end)`` per integration step over ``dt`` > 0 [s] from the
        stored input to ``(gyro, acc)``: one step, or for a gap longer than ``max_step``
        equal sub-steps with the input linear in time."""
        if dt <= self.params.max_step:
            return [(dt, gyro, acc)]
        n = math.ceil(dt / self.params.max_step)
        g0, a0 = self._gyro.copy(), self._acc.copy()
        return [(dt / n, g0 + (i / n) * (gyro - g0), a0 + (i / n) * (acc - a0))
                for i in range(1, n + 1)]

    def _step(self, dt: float, gyro1: FloatArray, acc1: FloatArray) -> None:
        """One prediction step of length ``dt`` from the stored input to ``(gyro1, acc1)``."""
        x, P, F, Phi, T = self._x, self._P, self._F, self._Phi, self._T
        g0 = self._gyro
        a0x, a0y, a0z = g0.tolist()
        a1x, a1y, a1z = gyro1.tolist()
        bx, by, bz = x[10:13].tolist()
        w = (0.5 * (a0x + a1x) - bx, 0.5 * (a0y + a1y) - by, 0.5 * (a0z + a1z) - bz)
        error_jacobian(x, w, self._g, F, self._fidx)
        np.matmul(F, F, out=self._FF)
        np.multiply(F, dt, out=Phi)
        Phi += self._I
        self._FF *= 0.5 * dt * dt
        Phi += self._FF
        np.matmul(Phi, P, out=T)
        np.matmul(T, Phi.T, out=P)
        self._add_process_noise(dt)
        ahead = self._ahead
        if ahead is not None and ahead[0] == _step_key(x, g0, self._acc, gyro1, acc1, dt):
            x[:] = ahead[1]  # the same step from the same numbers: the same result
        else:
            propagate(x, g0, self._acc, gyro1, acc1, dt, self._g, x)
        self._ahead = None
        self._gyro[:] = gyro1
        self._acc[:] = acc1

    def _add_process_noise(self, dt: float) -> None:
        """``P += G Qc G^T dt``: IMU noise into ``[dtheta, dv]`` (with the ``-[v×] n_g``
        coupling of gyro noise into dv) and the bias random walks."""
        v1, v2, v3 = self._x[7:10].tolist()
        s1, s2, s3 = (s * dt for s in self._sg)
        a1, a2, a3 = (s * dt for s in self._sa)
        # [[S, S [v×]^T], [[v×] S, [v×] S [v×]^T + S_a]] with S = diag(s), noise [n_g, n_a]
        self._Q6flat[:] = (
            s1, 0.0, 0.0, 0.0, s1 * v3, -s1 * v2,
            0.0, s2, 0.0, -s2 * v3, 0.0, s2 * v1,
            0.0, 0.0, s3, s3 * v2, -s3 * v1, 0.0,
            0.0, -s2 * v3, s3 * v2, a1 + s2 * v3 * v3 + s3 * v2 * v2, -s3 * v1 * v2,
            -s2 * v1 * v3,
            s1 * v3, 0.0, -s3 * v1, -s3 * v1 * v2, a2 + s1 * v3 * v3 + s3 * v1 * v1,
            -s1 * v2 * v3,
            -s1 * v2, s2 * v1, 0.0, -s2 * v1 * v3, -s1 * v2 * v3,
            a3 + s1 * v2 * v2 + s2 * v1 * v1,
        )  # fmt: skip
        self._P36 += self._Q6
        self._Pbias_diag += self._qbias * dt

    def _fuse(self, pose: Pose, gate: bool) -> UpdateResult:
        """Gate and apply a new pose at the filter time, or re-anchor on it if it completes
        a run of reset candidates; counts and records it."""
        mode = "ok"
        nis, applied = self._correct(pose, gate=gate, reset=False)
        if not applied:
            reset = self._completes_reset(pose)
            if reset is not None:
                mode = reset
                if reset == "forced":
                    self._note_overruled(pose)
                nis, applied = self._correct(pose, gate=False, reset=True,
                                             forced=reset == "forced")
        self.last_nis = nis
        if not applied:
            self.gated += 1
            self.consecutive_gated += 1
            return UpdateResult(False, nis, "gated")
        self.consecutive_gated = 0
        self._candidates.clear()
        self.updates += 1
        self.resets += mode != "ok"
        self.forced_resets += mode == "forced"
        self._t_fix = max(self._t_fix, float(pose.t))
        self._fused.append(_Fused(pose, mode))
        while self._fused and self._fused[0].t < self._hist.oldest_time():
            self._fused.popleft()
        return UpdateResult(True, nis, "ok" if mode == "ok" else "reset")

    def _completes_reset(self, pose: Pose) -> str | None:
        """Count the gated ``pose`` as a reset candidate (see :class:`EkfParams`): ``"reset"``
        if it completes a run of ``gate_reset_count`` consistent candidates the IMU explains,
        ``gate_reset_after`` without a fix; ``"forced"`` if it completes a run of consistent
        ones ``evidence_after`` without a fix, explained or not; else None."""
        p, run = self.params, self._candidates
        if run and not self._consistent(run[-1][0], pose):
            self.refused_resets += 1
            run.clear()
        explained = self._explained(pose)
        run.append((pose, explained))
        del run[:-p.gate_reset_count]
        since = self._t - self._t_fix
        if len(run) >= p.gate_reset_count:
            if since >= p.gate_reset_after and all(e for _, e in run):
                run.clear()
                return "reset"
            if since >= p.evidence_after:
                run.clear()
                return "forced"
        if not explained:
            self.refused_resets += 1
        return None

    def _note_overruled(self, pose: Pose) -> None:
        """Describe a forced re-anchoring on ``pose`` (before the estimate moves)."""
        jump = float(np.linalg.norm(pose.position - self._x[0:3]))
        self._overruled_reason = (
            f"{self.params.gate_reset_count} consistent Vicon poses disagreed with the "
            f"estimate for {self._t - self._t_fix:.2f} s (by {100.0 * jump:.0f} cm, more than "
            "the IMU can explain): re-anchored on Vicon")

    def _explained(self, pose: Pose) -> bool:
        """The innovation of ``pose`` passes the gate with ``R`` grown by what the IMU may
        have missed: the reset bound (the prediction's own covariance has grown with the
        time since the last fix)."""
        x, P = self._x, self._P
        y = np.empty(6)
        y[0:3] = pose.position - x[0:3]
        y[3:6] = _attitude_residual(x[3:7].tolist(), pose.quaternion.tolist())
        S = P[0:6, 0:6] + np.diag(self._r_reset)
        c, info = lapack.dpotrf(S, lower=0, clean=0, overwrite_a=1)
        if info != 0:
            return False
        sol, _ = lapack.dpotrs(c, y, lower=0)
        return bool(float(y @ sol) <= self._gate)

    def _consistent(self, a: Pose, b: Pose) -> bool:
        """``b`` agrees with ``a``: jump and rotation within the speed / rotation-rate gate
        for their spacing (as the pose filter's)."""
        p = self.params
        dt = abs(float(b.t) - float(a.t))
        ax, ay, az = a.position.tolist()
        bx, by, bz = b.position.tolist()
        jump = math.sqrt((bx - ax) ** 2 + (by - ay) ** 2 + (bz - az) ** 2)
        p0, p1, p2, p3 = a.quaternion.tolist()
        q0, q1, q2, q3 = b.quaternion.tolist()
        n = math.sqrt((p0 * p0 + p1 * p1 + p2 * p2 + p3 * p3) * (q0 * q0 + q1 * q1 + q2 * q2
                                                                  + q3 * q3))
        angle = 2.0 * math.acos(min(abs(p0 * q0 + p1 * q1 + p2 * q2 + p3 * q3) / n, 1.0))
        return (jump <= p.max_speed * dt + _POSITION_SLACK
                and angle <= p.max_rotation_rate * dt + _ANGLE_SLACK)

    def _correct(self, pose: Pose, gate: bool, reset: bool,
                 forced: bool = False) -> tuple[float, bool]:
        """Measurement update at the filter time (``reset``: re-anchored on ``pose`` first,
        ``forced``: one the IMU did not explain). Returns ``(nis, applied)``."""
        x, P, y = self._x, self._P, self._y
        if reset:
            self._reset_pose(pose, forced)
        y[0:3] = pose.position - x[0:3]
        y[3:6] = _attitude_residual(x[3:7].tolist(), pose.quaternion.tolist())
        S = P[0:6, 0:6] + self._R
        c, info = lapack.dpotrf(S, lower=0, clean=0, overwrite_a=1)
        if info != 0:
            raise EstimatorError(f"innovation covariance not positive definite (potrf info {info})")
        rhs = self._rhs
        rhs[:, 0] = y
        rhs[:, 1:] = P[0:6, :]
        sol, info = lapack.dpotrs(c, rhs, lower=0, overwrite_b=0)
        nis = float(y @ sol[:, 0])
        if gate and not nis <= self._gate:  # also rejects NaN
            return nis, False
        K = sol[:, 1:].T  # (15, 6) = P H^T S^-1
        dx = K @ y
        # Joseph form (I - K H) P (I - K H)^T + K R K^T, using H = [I_6 0]:
        # T = (I - K H) P = P - K P[0:6, :];  T (I - K H)^T = T - T[:, 0:6] K^T
        T = self._T
        np.matmul(K, P[0:6, :], out=self._Phi)
        np.subtract(P, self._Phi, out=T)
        np.matmul(T[:, 0:6], sol[:, 1:], out=self._Phi)
        np.subtract(T, self._Phi, out=P)
        P += K @ (self._r[:, None] * sol[:, 1:])  # K R K^T with R diagonal
        np.add(P, P.T, out=T)
        np.multiply(T, 0.5, out=P)
        x[0:3] += dx[0:3]
        x[3:7] = _quat_mul_exp(x[3:7].tolist(), dx[3:6].tolist())
        x[7:16] += dx[6:15]
        return nis, True

    def _reset_pose(self, pose: Pose, forced: bool = False) -> None:
        """Re-initialise position and attitude from ``pose``, and forget the velocity's
        certainty: all three get the initial variance and lose their correlations.

        Persistent gating means the prediction, not Vicon, is wrong; that is almost
        always a velocity error the IMU did not see (a touchdown or a knock that
        saturated the accelerometer). Resetting the velocity variance lets the next
        poses correct it within a few updates instead of gating them again.
        """
        x, P = self._x, self._P
        x[0:3] = pose.position
        q = pose.quaternion / np.linalg.norm(pose.quaternion)
        x[3:7] = q if float(np.dot(q, x[3:7])) >= 0.0 else -q
        P[0:9, :] = 0.0
        P[:, 0:9] = 0.0
        P.flat[: 9 * (N_ERR + 1) : N_ERR + 1] = self.params.initial_error_variance()[0:9]
        if forced:  # the IMU missed the motion: its velocity is a guess
            P.flat[6 * (N_ERR + 1) : 9 * (N_ERR + 1) : N_ERR + 1] = FORCED_VELOCITY_VAR

    def _replay(self, pose: Pose) -> UpdateResult:
        """Apply a pose older than the filter time: restore the checkpoint at or before
        it, then re-propagate every stored IMU sample and re-fuse later poses."""
        self.late_poses += 1
        new = _Fused(pose, "ok")
        k = self._hist.restore_before(new.t, self._x, self._P, self._gyro, self._acc)
        self._t = self._hist.time(k)
        later = sorted([f for f in self._fused if f.t > self._t], key=lambda f: f.t)
        result: UpdateResult | None = None
        if new.t == self._t:
            result = self._fuse(pose, gate=True)
        else:
            insort(later, new)
        for j in self._hist.indices_after(k):
            tj = self._hist.time(j)
            due = [f for f in later if f.t <= tj]
            later = later[len(due):]
            r = self._advance(tj, self._hist.gyro(j), self._hist.acc(j), due, new)
            result = r if r is not None else result
            self._hist.overwrite(j, self._x, self._P)
        self._check_finite()
        return result if result is not None else UpdateResult(False, _NAN, "too_old")

    def _check_finite(self) -> None:
        tr = float(self._P.trace())  # the method: np.trace's dispatch costs more than the sum
        if not math.isfinite(tr) or not math.isfinite(float(self._x.sum())):
            raise EstimatorError("EKF state or covariance is not finite")


def _step_key(x: FloatArray, g0: FloatArray, a0: FloatArray, g1: FloatArray, a1: FloatArray,
              dt: float) -> bytes:
    """The exact inputs of one :func:`propagate` step, as bytes (equal bytes: an equal
    result, since the step is a function of them alone)."""
    return b"".join((x.tobytes(), g0.tobytes(), a0.tobytes(), g1.tobytes(), a1.tobytes(),
                     struct.pack("d", dt)))


def _attitude_residual(q: list[float], m: list[float]) -> tuple[float, float, float]:
    """``log(q^-1 ⊗ m)`` [rad]; the sign of ``m`` is matched to ``q`` (``m`` ~ ``-m``)."""
    a0, a1, a2, a3 = q[0], -q[1], -q[2], -q[3]
    b0, b1, b2, b3 = m
    w = a0 * b0 - a1 * b1 - a2 * b2 - a3 * b3
    x = a0 * b1 + a1 * b0 + a2 * b3 - a3 * b2
    y = a0 * b2 - a1 * b3 + a2 * b0 + a3 * b1
    z = a0 * b3 + a1 * b2 - a2 * b1 + a3 * b0
    if w < 0.0:  # choose the measured sign that matches the prediction
        w, x, y, z = -w, -x, -y, -z
    n = math.sqrt(x * x + y * y + z * z)
    k = 2.0 * math.atan2(n, w) / n if n > 1e-12 else 2.0 / w
    return k * x, k * y, k * z


def _quat_mul_exp(q: list[float], d: list[float]) -> tuple[float, float, float, float]:
    """``q ⊗ exp(d)`` for a rotation vector ``d`` [rad], renormalised."""
    a2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2]
    if a2 < 1e-12:
        e0, s = 1.0 - a2 / 8.0, 0.5 - a2 / 48.0
    else:
        a = math.sqrt(a2)
        e0, s = math.cos(0.5 * a), math.sin(0.5 * a) / a
    e1, e2, e3 = s * d[0], s * d[1], s * d[2]
    q0, q1, q2, q3 = q
    r0 = q0 * e0 - q1 * e1 - q2 * e2 - q3 * e3
    r1 = q0 * e1 + q1 * e0 + q2 * e3 - q3 * e2
    r2 = q0 * e2 - q1 * e3 + q2 * e0 + q3 * e1
    r3 = q0 * e3 + q1 * e2 - q2 * e1 + q3 * e0
    n = 1.0 / math.sqrt(r0 * r0 + r1 * r1 + r2 * r2 + r3 * r3)
    return r0 * n, r1 * n, r2 * n, r3 * n
