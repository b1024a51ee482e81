"""The identification flight (``trajectory.name: sysid``) and what it feeds.

The trajectory is checked against closed forms of a doublet (a body rate ``A`` for ``T``,
``-A`` for ``2T``, ``A`` for ``T``: peak tilt ``A T``, excursion ``2 g A T^3``, back at rest)
and against scipy's integration of its own jerk (the segments join continuously). The
flight is flown in-process on the simulated clock on a virtual vehicle whose rate gains
are 30 % off the configured ones (``sim.k_rate_scale``, both ways); the gains
``gs identify rates`` fits from its log are compared with the virtual vehicle's own
parameters, never with the identification's earlier output. Every ``gs identify`` the
refusals recommend the flight for must then accept its log.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from lab_helpers import fly_logged, sim_config

from groundstation.app.inprocess import FlightResult
from groundstation.control.excitation import (
    LIMIT_SHARE,
    identification_flight,
    plan_excitation,
)
from groundstation.control.feasibility import FlightLimits, Volume
from groundstation.errors import IdentificationError, TrajectoryError
from groundstation.flight.assembly import assemble
from groundstation.flight.prepare import prepare_trajectory
from groundstation.identification import identify_rates, identify_scales
from groundstation.identification.lift import identify_inflow_log, identify_thrust_log
from sim_device.lab import VirtualLab

G = 9.82
LAB = Volume((-1.5, 1.5), (-1.5, 1.5), (-2.0, 0.05), margin_m=0.1)
LIMITS = FlightLimits(gravity=G, max_tilt_rad=math.radians(20.0), max_rate_rad_s=2.25,
                      max_yaw_rate_rad_s=math.radians(90.0), max_speed_m_s=1.5)
TRUE_OVER_MODEL = [1.3, 0.7, 1.3]  # the virtual vehicle's rate gains / the configured ones


@pytest.mark.slow
def test_doublets_match_their_closed_forms() -> None:
    heading = math.radians(30.0)
    traj = identification_flight([0.2, -0.1, -1.0], heading, LIMITS, LAB, 0.064)
    plan = plan_excitation(np.array([0.2, -0.1, -1.0]), LIMITS, LAB, 0.064)
    t = np.linspace(0.0, traj.duration, 400_001)
    s = traj.sample_many(t)
    # at rest where it starts and ends, back at the centre and heading
    np.testing.assert_allclose(s.position[[0, -1]], [[0.2, -0.1, -1.0]] * 2, atol=1e-9)
    np.testing.assert_allclose(s.velocity[[0, -1]], 0.0, atol=1e-9)
    np.testing.assert_allclose(s.yaw[[0, -1]], heading, atol=1e-12)
    # each derivative is the finite difference of the one below it (away from the jerk's
    # steps, where the difference straddles), and nothing jumps at a segment boundary
    h = t[1] - t[0]
    for low, high in ((s.position, s.velocity), (s.velocity, s.acceleration),
                      (s.acceleration, s.jerk)):
        diff = np.gradient(low, h, axis=0)
        smooth = np.all(np.abs(np.diff(s.jerk, axis=0)) < 1e-9, axis=1)
        inner = smooth[1:] & smooth[:-1]
        np.testing.assert_allclose(diff[1:-1][inner], high[1:-1][inner], atol=1e-6)
    eps = 1e-9
    for b in traj.breaks[1:-1]:
        before, after = traj.sample(b - eps), traj.sample(b + eps)
        np.testing.assert_allclose(before.position, after.position, atol=1e-8)
        np.testing.assert_allclose(before.velocity, after.velocity, atol=1e-7)
        np.testing.assert_allclose(before.acceleration, after.acceleration, atol=1e-6)
        assert before.yaw == pytest.approx(after.yaw, abs=1e-8)
    # body rates the hover model reads from the jerk: roll right = j_right / g, pitch =
    # -j_forward / g, in the heading's axes
    fwd = np.array([math.cos(heading), math.sin(heading), 0.0])
    right = np.array([-math.sin(heading), math.cos(heading), 0.0])
    roll, pitch = s.jerk @ right / G, -(s.jerk @ fwd) / G
    assert np.max(np.abs(roll)) == pytest.approx(max(plan.rate), rel=1e-9)
    assert np.max(np.abs(pitch)) == pytest.approx(max(plan.rate), rel=1e-9)
    assert np.max(np.abs(s.yaw_rate)) == pytest.approx(max(plan.yaw_rate), rel=1e-9)
    # one axis at a time: while roll is excited, pitch and yaw hold
    assert not np.any((np.abs(roll) > 1e-9) & (np.abs(pitch) > 1e-9))
    assert not np.any((np.abs(roll) > 1e-9) & (np.abs(s.yaw_rate) > 1e-9))
    # per pulse width: peak tilt A T (small angles: |a_h| / g) and excursion 2 g A T^3
    for width, rate in zip(plan.widths, plan.rate, strict=True):
        assert rate * width <= LIMIT_SHARE * LIMITS.max_tilt_rad + 1e-12
        assert rate <= LIMIT_SHARE * LIMITS.max_rate_rad_s + 1e-12
    # (the samples, 91 us apart, miss the peaks by at most half of that: rel 1e-4)
    tilt = np.max(np.hypot(s.acceleration[:, 0], s.acceleration[:, 1])) / G
    assert tilt == pytest.approx(max(r * w for r, w in zip(plan.rate, plan.widths,
                                                              strict=True)), rel=1e-4)
    reach = np.max(np.abs((s.position - s.position[0]) @ right))
    assert reach == pytest.approx(max(2 * G * r * w ** 3 for r, w in zip(
        plan.rate, plan.widths, strict=True)), rel=1e-4)


def test_amplitudes_shrink_with_the_room_and_a_centre_outside_is_refused() -> None:
    small = Volume((-0.5, 0.5), (-0.5, 0.5), (-1.5, 0.05), margin_m=0.1)
    traj = identification_flight([0.0, 0.0, -1.0], 0.0, LIMITS, small, 0.064)
    s = traj.sample_many(np.linspace(0.0, traj.duration, 100_001))
    lo, hi = small.allowed()
    assert np.all(s.position >= lo - 1e-9) and np.all(s.position <= hi + 1e-9)
    # half the room: 0.2 m each way horizontally, 0.2 m up (0.4 m to the ceiling's margin)
    assert np.max(np.abs(s.position[:, :2])) <= 0.2 + 1e-9
    assert np.min(s.position[:, 2]) >= -1.2 - 1e-9
    with pytest.raises(TrajectoryError, match="not inside"):
        identification_flight([1.45, 0.0, -1.0], 0.0, LIMITS, LAB, 0.064)


def test_the_configured_flight_passes_the_check_gs_fly_runs() -> None:
    cfg = sim_config(**{"trajectory.name": "sysid", "trajectory.yaw_deg": 45.0})
    prepared = prepare_trajectory(assemble(cfg))
    assert prepared.report.feasible, prepared.report.problems
    assert "identification flight" in prepared.description
    limits = assemble(cfg).limits
    assert prepared.report.max_tilt_rad <= LIMIT_SHARE * limits.max_tilt_rad * 1.001
    assert prepared.report.max_yaw_rate_rad_s <= LIMIT_SHARE * limits.max_yaw_rate_rad_s * 1.001
    assert prepared.trajectory.sample(0.0).yaw == pytest.approx(math.radians(45.0))


@pytest.fixture(scope="module")
def flown(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, FlightResult]:
    """The identification flight on a vehicle whose gains are 30 % off (about 15 s)."""
    cfg = sim_config(**{"trajectory.name": "sysid", "sim.k_rate_scale": TRUE_OVER_MODEL})
    return fly_logged(cfg, tmp_path_factory.mktemp("sysid"),
                      prepare_trajectory(assemble(cfg)).duration_s)


@pytest.mark.slow
def test_the_gains_are_found_within_5_percent_of_the_truth(
        flown: tuple[Path, FlightResult]) -> None:
    log, result = flown
    lab = result.lab
    assert isinstance(lab, VirtualLab)
    truth = np.array(lab.params.plant.k_rate)
    configured = np.array(result.core.params.vehicle.k_rate)
    np.testing.assert_allclose(truth / configured, TRUE_OVER_MODEL, rtol=1e-9)
    fit = identify_rates(log)  # as `gs identify rates LOG`: the configured gyro scale
    gains = np.array(fit.k_rate)
    assert np.all(np.abs(gains / truth - 1.0) < 0.05), (gains, truth)
    for axis in fit.axes():
        lo, hi = axis.k_rate_ci
        assert lo < axis.k_rate < hi and (hi - lo) / 2 < 0.05 * axis.k_rate
    scales = identify_scales(log, axes=("gyro_x", "gyro_y", "gyro_z"))
    rescaled = np.array(identify_rates(log, gyro_scale=scales.gyro_scale).k_rate)
    assert np.all(np.abs(rescaled / truth - 1.0) < 0.05), (rescaled, truth)
    # the truth's own record: the flight kept inside its limits
    arrays = lab.truth_log.arrays()
    q = arrays["quaternion"]
    tilt = np.degrees(np.arccos(np.clip(1.0 - 2.0 * (q[:, 1] ** 2 + q[:, 2] ** 2), -1, 1)))
    assert np.max(tilt) < math.degrees(result.core.params.supervisor.max_tilt_rad)
    lo, hi = LAB.allowed()
    assert np.all(arrays["position"] >= lo - 0.1) and np.all(arrays["position"] <= hi + 0.1)


@pytest.mark.slow
def test_every_identification_it_is_recommended_for_accepts_its_log(
        flown: tuple[Path, FlightResult]) -> None:
    log, _ = flown
    # gs identify scales' default axes: the gyro and acc_z (acc_x and acc_y read about zero
    # in flight: their refusal recommends the bench, not this flight)
    scales = identify_scales(log, axes=("gyro_x", "gyro_y", "gyro_z", "acc_z"))
    assert len(scales.fits) == 4
    thrust = identify_thrust_log(log)
    assert thrust.scale_ci[0] < thrust.scale < thrust.scale_ci[1]
    inflow = identify_inflow_log(log)
    assert inflow.inflow < 0.0


@pytest.mark.slow
def test_a_hover_is_refused_with_the_flight_that_is_not(tmp_path: Path) -> None:
    log, _ = fly_logged(sim_config(**{"trajectory.name": "hover"}), tmp_path, 6.0)
    # (the inflow and the thrust map are found even in a hover's take-off and landing)
    for identify in (identify_rates,
                     lambda d: identify_scales(d, axes=("gyro_x", "gyro_y", "gyro_z"))):
        with pytest.raises(IdentificationError) as err:
            identify(log)
        message = str(err.value)
        assert "--trajectory sysid" in message, message
        assert "square" not in message and "figure-eight" not in message
