"""The virtual X-3D's airframe against closed forms, the thesis and the ground-station model.

Expected values come from: the eq. 3.7 polynomial's root (numpy.roots, not the
project's ThrustMap), free fall z = z0 + g t^2 / 2, the induced-inflow equilibrium
of eq. 3.9 (v' = (F + m g + I_i v)/m), the first-order lag 1 - exp(-t/tau), Fig. 3.8's
0.14 s rise time, and groundstation.model.quadrotor (an independent implementation
of eq. 3.19-3.22).
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from groundstation.asctec.messages import CommandMsg
from groundstation.model.quadrotor import QuadrotorModel, QuadrotorParams
from groundstation.types import Sticks
from sim_device import LabParams, PlantParams, VirtualLab
from sim_device.plant import Plant

EQ37 = (2.073e-10, -1.143e-6, -1.054e-3, -0.903)
MASS, G, I_I = 0.60, 9.82, -0.423


def poly(u: float) -> float:
    """Eq. 3.7 evaluated with numpy (independent of the project's ThrustMap)."""
    return float(np.polyval(EQ37, u))


def hover_root(mass: float = MASS) -> float:
    """The stick where eq. 3.7 lift equals the weight: real root of F(u) + m g in (0, 4090)."""
    roots = np.roots([EQ37[0], EQ37[1], EQ37[2], EQ37[3] + mass * G])
    real = [r.real for r in roots if abs(r.imag) < 1e-9 and 0 < r.real < 4090]
    assert len(real) == 1
    return float(real[0])


def lab_with(seed: int = 1, **plant: Any) -> VirtualLab:
    """A lab without battery droop (unless asked) and the given plant overrides."""
    base = PlantParams(battery_droop=0.0)
    return VirtualLab(LabParams(plant=replace(base, **plant), truth_period=0.002), seed=seed)


def test_hover_at_the_polynomial_root() -> None:
    u_hover = hover_root()
    assert 1900 < u_hover < 2100  # DESIGN.md: the mass makes eq. 3.7 hover near mid-stick
    heights = {}
    for offset in (-30, 0, 30):
        lab = lab_with()
        lab.set_pilot(Sticks(thrust=round(u_hover) + offset))
        lab.place((0.0, 0.0, -1.0))
        lab.advance(2.0)
        heights[offset] = lab.truth.position[2] + 1.0
    # Rounding the stick leaves |F + m g| <= |dF/du|/2 = 2 mN: a few mm in 2 s.
    assert abs(heights[0]) < 0.005
    assert heights[30] < -0.05  # more stick climbs (z decreases)
    assert heights[-30] > 0.05


@pytest.mark.parametrize("thrust_scale", [1.0, 0.9])
def test_climb_reaches_the_induced_inflow_equilibrium(thrust_scale: float) -> None:
    u = 2600
    lab = lab_with(motor_tau_s=0.0, thrust_scale=thrust_scale)
    lab.set_pilot(Sticks(thrust=u))
    lab.place((0.0, 0.0, -1.0))
    lab.advance(3.0)
    # v' = (F + m g + I_i v)/m from rest: v(t) = v_inf (1 - exp(I_i t / m)), v_inf = -(F+mg)/I_i
    f_net = thrust_scale * poly(u) + MASS * G
    v_inf = -f_net / I_I
    expected = v_inf * (1.0 - math.exp(I_I * 3.0 / MASS))
    assert lab.truth.velocity[2] == pytest.approx(expected, rel=1e-6)
    assert expected < -0.5  # it does climb


def test_free_fall_then_rest_on_the_floor() -> None:
    lab = lab_with()  # pilot thrust 0: motors off
    lab.place((0.3, -0.2, -2.0))
    lab.advance(0.5)
    truth = lab.truth
    assert truth.position[2] == pytest.approx(-2.0 + 0.5 * G * 0.5**2, abs=1e-9)
    assert truth.velocity[2] == pytest.approx(G * 0.5, abs=1e-9)
    assert truth.specific_force == pytest.approx([0.0, 0.0, 0.0], abs=1e-12)
    lab.advance(1.0)  # reaches the floor after sqrt(2 * 2 / g) = 0.64 s
    truth = lab.truth
    assert truth.on_ground
    assert truth.position == pytest.approx([0.3, -0.2, 0.0], abs=1e-12)
    assert truth.velocity == pytest.approx([0.0, 0.0, 0.0], abs=1e-12)
    assert truth.specific_force == pytest.approx([0.0, 0.0, -G], abs=1e-12)


def test_floor_holds_until_lift_exceeds_weight() -> None:
    lab = lab_with()
    lab.set_pilot(Sticks(thrust=1800, roll=500))  # below hover; a roll stick on the floor
    lab.advance(1.0)
    truth = lab.truth
    assert truth.on_ground and truth.position[2] == 0.0
    assert truth.omega == pytest.approx([0.0, 0.0, 0.0], abs=0.0)
    assert truth.quaternion == pytest.approx([1.0, 0.0, 0.0, 0.0], abs=0.0)
    lab.set_pilot(Sticks(thrust=2300))
    lab.advance(1.0)
    assert not lab.truth.on_ground
    assert lab.truth.position[2] < -0.1


def test_landing_tilted_sits_level_keeping_heading() -> None:
    lab = lab_with()
    q = Rotation.from_euler("ZYX", [40.0, 0.0, 10.0], degrees=True).as_quat(scalar_first=True)
    lab.place((0.0, 0.0, -0.05), quaternion=q, velocity_body=(0.0, 0.0, 1.0))
    lab.advance(0.5)
    truth = lab.truth
    yaw = math.radians(40.0)
    assert truth.on_ground
    assert truth.quaternion == pytest.approx([math.cos(yaw / 2), 0, 0, math.sin(yaw / 2)],
                                             abs=1e-12)
    assert truth.velocity_body == pytest.approx([0.0, 0.0, 0.0], abs=0.0)


def test_rate_step_follows_the_first_order_lag() -> None:
    tau = 0.064
    lab = lab_with(rate_tau=tau)
    u = round(hover_root())
    lab.set_pilot(Sticks(thrust=u))
    lab.place((0.0, 0.0, -1.0))
    lab.advance(0.5)
    lab.set_pilot(Sticks(roll=1000, thrust=u))  # pilot sticks: no link delay
    t0 = lab.truth.t
    lab.advance(tau)
    setpoint = 1.1e-3 * 1000
    assert lab.truth.t == pytest.approx(t0 + tau)
    assert lab.truth.omega[0] / setpoint == pytest.approx(1.0 - math.exp(-1.0), rel=1e-9)
    # 10-90 % rise time from the log, against Fig. 3.8's 0.14 s (eq. 3.2)
    lab.advance(0.5)
    log = lab.truth_log.arrays()
    after = log["t"] >= t0 - 1e-9
    t, w = log["t"][after] - t0, log["omega"][after, 0] / setpoint
    rise = np.interp(0.9, w, t) - np.interp(0.1, w, t)
    assert rise == pytest.approx(0.14, rel=0.02)


def test_command_takes_effect_after_transmission_and_transport_delay() -> None:
    lab = lab_with(rate_tau=0.0)
    lab.advance(0.5)
    lab.send(CommandMsg(roll=1000, thrust=2300, ctrl=0x0F))
    # 23 bytes at 57600 baud (10 bits each) + 20 ms command delay, on the 2 ms grid
    arrival = 0.5 + 23 * 10 / 57600 + 0.020
    first_step = math.ceil(arrival / 0.002 - 1e-9) * 0.002
    lab.advance_to(first_step - 0.002)
    assert lab.truth.sticks == Sticks()
    lab.advance_to(first_step + 1e-6)
    assert lab.truth.sticks == Sticks(roll=1000, thrust=2300)


def test_battery_droop_scales_lift_linearly() -> None:
    lab = lab_with(battery_droop=0.03, battery_droop_time=10.0, motor_tau_s=0.0)
    lab.set_pilot(Sticks(thrust=2000))
    lab.place((0.0, 0.0, -1.0))
    lab.advance(5.0)
    assert lab.truth.lift == pytest.approx((1.0 - 0.03 * 5.0 / 10.0) * poly(2000), rel=1e-9)


def test_plant_step_matches_the_ground_station_model() -> None:
    """One plant step equals groundstation.model's RK4 step (eq. 3.19-3.22) without lags."""
    rng = np.random.default_rng(7)
    params = PlantParams(rate_tau=0.0, motor_tau_s=0.0, battery_droop=0.0)
    model = QuadrotorModel(QuadrotorParams(mass=MASS, g=G, inflow=I_I))
    for _ in range(20):
        plant = Plant(params, 0.002)
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        pos, v, w = rng.normal(size=3) - [0, 0, 5], rng.normal(size=3), rng.normal(size=3)
        lift = -rng.uniform(2.0, 9.0)
        plant.set_inputs(w[0], w[1], w[2], lift)
        plant.on_ground = False
        plant.px, plant.py, plant.pz = pos
        plant.q0, plant.q1, plant.q2, plant.q3 = q
        plant.vx, plant.vy, plant.vz = v
        plant.wx, plant.wy, plant.wz = w
        plant.lift = lift
        plant.step()
        x = model.step(np.concatenate([pos, q, v]), np.append(w, lift + MASS * G), 0.002)
        got = [plant.px, plant.py, plant.pz, plant.q0, plant.q1, plant.q2, plant.q3,
               plant.vx, plant.vy, plant.vz]
        np.testing.assert_allclose(got, x, rtol=0, atol=1e-12)


def test_touchdown_is_felt_by_the_accelerometer() -> None:
    """The deceleration the IMU feels at touchdown integrates to the velocity lost
    (independent answer: the free-fall speed at the floor, sqrt(2 g h))."""
    params = PlantParams(initial_position=(0.0, 0.0, -0.2), impact_time=0.05)
    plant = Plant(params, 0.002)
    while not plant.on_ground:
        plant.step()
    felt = 0.0  # integral of (specific force z + g): the non-gravity deceleration
    for _ in range(100):
        felt += (plant.specific_force()[2] + G) * plant.dt
        plant.step()
    v_floor = math.sqrt(2.0 * G * 0.2)
    assert felt == pytest.approx(-v_floor, rel=0.03)  # one 2 ms step of slack
    assert plant.specific_force() == pytest.approx((0.0, 0.0, -G), abs=1e-12)  # then at rest


def test_a_touchdown_that_lifts_off_again_is_felt_all_the_same() -> None:
    """The floor stops the vehicle even when its lift (2 % over the weight here) takes it
    off again at once: the accelerometer's non-gravity reading integrates to the velocity
    the plant actually changed by, impact included (the reading alone, before, knew
    nothing of the floor once the vehicle was airborne)."""
    params = PlantParams(initial_position=(0.0, 0.0, -0.01), impact_time=0.05)
    plant = Plant(params, 0.002)
    plant.lift = plant.lift_sp = -1.02 * plant.mass * G  # up, a little over the weight
    plant.vz = 0.3  # descending [m/s]
    felt, v_start = 0.0, plant.vz
    touched = lifted = False
    for _ in range(100):  # 0.2 s: the touchdown and 0.15 s of flight after it
        felt += (plant.specific_force()[2] + G) * plant.dt
        plant.step()
        touched = touched or plant.on_ground
        lifted = lifted or (touched and not plant.on_ground)
    assert touched and lifted
    assert felt == pytest.approx(plant.vz - v_start, abs=0.3 * 0.03)  # one step of slack
