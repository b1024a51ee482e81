"""What the virtual lab throws at the vehicle: a payload, wind and drag, ground effect.

Expected values are closed forms written here from the physics, not the plant's code:
Newton's law for the payload (a = g (1 - 1 / 1.2) with the lift unchanged), RotorPy's drag
(rotor drag k_r v_air + parasitic c_D |v_air| v_air) for the first acceleration in a wind and
for where a level vehicle drifting in it ends (the airspeed goes to zero), the 1-cosine
gust, Cheeseman and Bennett's ground effect 1 / (1 - (R / 4 h)^2) and the hover it allows;
the accelerometer against a finite difference of the plant's own velocity.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from sim_device.params import GroundEffectParams, PlantParams, WindParams
from sim_device.plant import Plant

MASS, G = 0.60, 9.82
DT = 0.002


def hovering(params: PlantParams, z: float = -1.0, lift_scale: float = 1.0) -> Plant:
    """A plant level at height ``z`` with the lift that holds its weight (times
    ``lift_scale``) already reached, no battery droop."""
    plant = Plant(replace(params, battery_droop=0.0, initial_position=(0.0, 0.0, z)), DT)
    lift = -params.mass * params.g * lift_scale
    plant.set_inputs(0.0, 0.0, 0.0, lift)
    plant.lift = lift
    plant.on_ground = False
    return plant


def velocity_ned(plant: Plant) -> np.ndarray:
    return np.array(plant.velocity_ned())


def test_a_payload_step_makes_the_same_lift_accelerate_a_heavier_vehicle_down() -> None:
    plant = hovering(PlantParams(payload_steps=((0.5, 1.2),), inflow=0.0))
    plant.run(round(0.5 / DT))
    assert abs(plant.vz) < 1e-9 and plant.mass == pytest.approx(MASS)
    plant.run(round(0.2 / DT))
    assert plant.mass == pytest.approx(1.2 * MASS)
    a = G * (1.0 - 1.0 / 1.2)  # lift m g now holds only 1/1.2 of the weight
    assert plant.vz == pytest.approx(a * 0.2, rel=1e-3)
    assert plant.specific_force()[2] == pytest.approx(-G / 1.2, rel=1e-9)


def test_two_payload_steps_multiply() -> None:
    plant = Plant(PlantParams(payload_steps=((2.0, 1.5), (1.0, 1.2))), DT)
    assert plant.mass_at(0.5) == MASS
    assert plant.mass_at(1.5) == pytest.approx(1.2 * MASS)
    assert plant.mass_at(3.0) == pytest.approx(1.8 * MASS)


def test_the_first_acceleration_in_a_wind_is_the_drag_on_the_airspeed() -> None:
    k_r, c = 0.217, (0.005, 0.007, 0.01)
    wind = WindParams(velocity=(3.0, -1.0, 0.0), rotor_drag=k_r, body_drag=c)
    plant = hovering(PlantParams(wind=wind))
    air = np.array([-3.0, 1.0, 0.0])  # the vehicle at rest, level at heading 0
    speed = float(np.linalg.norm(air))
    expected = -(k_r * air[:2] + np.array(c[:2]) * speed * air[:2]) / MASS
    assert plant.specific_force()[:2] == pytest.approx(tuple(expected), rel=1e-12)
    plant.step()
    assert velocity_ned(plant)[:2] == pytest.approx(tuple(expected * DT), rel=1e-3)


def test_a_level_vehicle_drifting_in_the_wind_ends_at_the_wind_speed() -> None:
    wind = WindParams(velocity=(2.0, 1.0, 0.0))
    plant = hovering(PlantParams(wind=wind))
    plant.run(round(30.0 / DT))  # drag time constant m / k_r = 2.8 s: 10 of them
    assert velocity_ned(plant)[:2] == pytest.approx((2.0, 1.0), abs=1e-3)
    assert plant.specific_force()[:2] == pytest.approx((0.0, 0.0), abs=1e-3)


def test_rotor_drag_grows_with_the_rotor_speed() -> None:
    """RotorPy's rotor drag is linear in each rotor's speed, and the speed goes as the
    square root of the lift: at twice the lift, sqrt(2) times the rotor drag."""
    wind = WindParams(velocity=(1.0, 0.0, 0.0), body_drag=(0.0, 0.0, 0.0))
    one = hovering(PlantParams(wind=wind)).specific_force()[0]
    two = hovering(PlantParams(wind=wind), lift_scale=2.0).specific_force()[0]
    assert two / one == pytest.approx(math.sqrt(2.0), rel=1e-12)


def test_still_air_without_drag_is_the_thesis_plant() -> None:
    """A wind section that moves no air and has no drag flies as the plant without one
    (eq. 3.19-3.22): the drag terms reduce to the thesis's model."""
    no_drag = WindParams(rotor_drag=0.0, body_drag=(0.0, 0.0, 0.0))
    a = hovering(PlantParams(), lift_scale=1.1)
    b = hovering(PlantParams(wind=no_drag), lift_scale=1.1)
    for plant in (a, b):
        plant.set_inputs(0.3, -0.2, 0.1, plant.lift_sp)
        plant.run(500)
    state = [(p.px, p.py, p.pz, p.q0, p.q1, p.q2, p.q3, p.vx, p.vy, p.vz) for p in (a, b)]
    assert state[1] == pytest.approx(state[0], abs=1e-12)


def test_a_gust_is_a_one_minus_cosine_on_top_of_the_wind() -> None:
    wind = WindParams(velocity=(3.0, 0.0, 0.0), gusts=((10.0, 1.0, (4.0, 0.0, -1.0)),))
    for t in (9.0, 10.0, 10.25, 10.5, 10.75, 11.0, 12.0):
        k = 0.5 * (1.0 - math.cos(2.0 * math.pi * (t - 10.0))) if 10.0 <= t <= 11.0 else 0.0
        assert wind.at(t) == pytest.approx((3.0 + 4.0 * k, 0.0, -k), abs=1e-12)
    assert wind.at(10.5) == pytest.approx((7.0, 0.0, -1.0))


def test_the_accelerometer_feels_the_drag() -> None:
    """The specific force is the acceleration less gravity: a finite difference of the
    plant's own velocity (level, no rotation) over one step."""
    wind = WindParams(velocity=(0.0, 3.0, 1.0))
    plant = hovering(PlantParams(wind=wind))
    v0 = velocity_ned(plant)
    f0 = np.array(plant.specific_force())
    plant.step()
    f1 = np.array(plant.specific_force())
    accel = (velocity_ned(plant) - v0) / DT
    assert accel - np.array([0.0, 0.0, G]) == pytest.approx(0.5 * (f0 + f1), abs=1e-4)


@pytest.mark.parametrize("height", [0.0, 0.02, 0.1, 0.5])
def test_ground_effect_holds_the_vehicle_with_less_lift(height: float) -> None:
    radius, rotors = 0.1, 0.08
    ge = GroundEffectParams(rotor_radius=radius, rotor_height=rotors)
    h = max(rotors + height, radius / 2.0)
    factor = 1.0 / (1.0 - (radius / (4.0 * h)) ** 2)  # Cheeseman and Bennett
    assert ge.factor(-height) == pytest.approx(factor, rel=1e-12)
    plant = hovering(PlantParams(ground_effect=ge, inflow=0.0), z=-height - 1e-9,
                     lift_scale=1.0 / factor)
    plant.step()
    assert abs(plant.vz) < 1e-6  # m g / factor is exactly what hovers there


def test_ground_effect_fades_with_height() -> None:
    ge = GroundEffectParams()
    factors = [ge.factor(-h) for h in (0.0, 0.05, 0.2, 1.0)]
    assert factors == sorted(factors, reverse=True)
    assert factors[0] < 4.0 / 3.0 + 1e-12 and factors[-1] - 1.0 < 2e-3
