"""``gs eval --perturb``: the plants drawn per seed, the virtual lab built from them, and a
short perturbed suite flown in-process.

The draws are checked against their stated ranges (perturb.py's constants) over many
seeds, and the lab's parameters (sim_device.params.LabParams.from_config) against the
products the overrides define (true gain = model gain x drawn scale, and so on). The
flown subset is two seeds of two short shaped flights; its report must hold every
seed's metrics, the plants, and worst-case figures equal to the worst per-seed ones.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import pytest
import yaml
from eval_flights import sharing_flights

from groundstation.config import apply_overrides, dump_config, load_config, validate_config
from groundstation.errors import ConfigError
from sim_device.evaluation import run_eval
from sim_device.evaluation.perturb import (
    ACC_BIAS_MAX,
    COMMAND_DELAY_RANGE_S,
    GYRO_BIAS_MAX,
    IMU_SCALE_ERROR,
    MASS_SPREAD,
    MOTOR_TAU_RANGE_S,
    PLANT_COLUMNS,
    RATE_GAIN_SPREAD,
    RATE_TAU_SPREAD,
    THRUST_SPREAD,
    parse_seeds,
    perturbation,
    plant_row,
)
from sim_device.evaluation.scenarios import select
from sim_device.evaluation.suite import plant_for
from sim_device.params import LabParams

REPO = Path(__file__).resolve().parents[1]
SEEDS = range(200)


def within(x: float, lo: float, hi: float) -> bool:
    return lo <= x <= hi


def test_the_same_seed_draws_the_same_plant_and_seeds_differ() -> None:
    assert perturbation(3) == perturbation(3)
    plants = [perturbation(s) for s in range(20)]
    assert len({json.dumps(p, sort_keys=True) for p in plants}) == 20
    assert [p["sim.seed"] for p in plants] == list(range(20))  # the seed also seeds the noise
    with pytest.raises(ConfigError, match="seed -1"):
        perturbation(-1)


def test_draws_stay_inside_the_stated_ranges_and_fill_them() -> None:
    tau0 = 0.05
    plants = [perturbation(s, tau0) for s in SEEDS]
    gains = [g for p in plants for g in p["sim.k_rate_scale"]]
    checks: list[tuple[list[float], float, float]] = [
        (gains, 1 - RATE_GAIN_SPREAD, 1 + RATE_GAIN_SPREAD),
        ([p["sim.rate_loop_tau_s"] / tau0 for p in plants], 1 - RATE_TAU_SPREAD,
         1 + RATE_TAU_SPREAD),
        ([p["sim.mass_scale"] for p in plants], 1 - MASS_SPREAD, 1 + MASS_SPREAD),
        ([p["sim.thrust_scale"] for p in plants], 1 - THRUST_SPREAD, 1 + THRUST_SPREAD),
        ([p["sim.command_delay_s"] for p in plants], *COMMAND_DELAY_RANGE_S),
        ([b for p in plants for b in p["sim.gyro_bias"]], -GYRO_BIAS_MAX, GYRO_BIAS_MAX),
        ([b for p in plants for b in p["sim.acc_bias"]], -ACC_BIAS_MAX, ACC_BIAS_MAX),
        ([p["sim.motor_tau_s"] for p in plants], *MOTOR_TAU_RANGE_S),
    ]
    for values, lo, hi in checks:
        assert all(within(v, lo, hi) for v in values), (lo, hi)
        # uniform: 200 draws (600 per axis set) reach the outer tenth of the range at both ends
        span = hi - lo
        assert min(values) < lo + 0.1 * span and max(values) > hi - 0.1 * span, (lo, hi)
    assert {p["sim.scale_error"] for p in plants} == {IMU_SCALE_ERROR}
    # the rate gains of one plant are drawn per axis, independently
    assert all(len(set(p["sim.k_rate_scale"])) == 3 for p in plants)


def test_the_lab_built_from_a_drawn_plant_differs_from_the_model() -> None:
    base = load_config(REPO / "config" / "sim.yaml")
    nominal = LabParams.from_config(base)
    veh = base.vehicle
    assert nominal.plant.k_rate == pytest.approx(veh.k_rate)  # the lab is the design model
    assert nominal.plant.mass == pytest.approx(veh.mass_kg)
    for seed in (1, 2, 3):
        drawn = perturbation(seed, veh.rate_loop_tau_s)
        lab = LabParams.from_config(apply_overrides(base, drawn))
        scale = drawn["sim.k_rate_scale"]
        assert lab.plant.k_rate == pytest.approx([k * s for k, s in zip(veh.k_rate, scale,
                                                                         strict=True)])
        assert lab.plant.mass == pytest.approx(veh.mass_kg * drawn["sim.mass_scale"])
        assert lab.plant.thrust_scale == drawn["sim.thrust_scale"]
        assert lab.plant.rate_tau == drawn["sim.rate_loop_tau_s"]
        assert lab.link.command_delay == drawn["sim.command_delay_s"]
        assert lab.plant.motor_tau_s == drawn["sim.motor_tau_s"]
        assert lab.imu.gyro_bias == pytest.approx(drawn["sim.gyro_bias"])
        assert lab.imu.acc_bias == pytest.approx(drawn["sim.acc_bias"])
        assert lab.imu.scale_error == IMU_SCALE_ERROR and lab.seed == seed
        assert max(abs(a / b - 1) for a, b in zip(lab.plant.k_rate, nominal.plant.k_rate,
                                                  strict=True)) > 0.01
        # real time: the child `gs sim-device` reads the configuration as YAML; the same lab
        cfg = apply_overrides(base, drawn)
        reread = validate_config(yaml.safe_load(dump_config(cfg)))
        assert LabParams.from_config(reread) == lab


def test_a_scenario_keeps_its_own_overrides_over_the_drawn_plant() -> None:
    drawn = perturbation(4)
    low = select(["hinf-rate-gains-low"])[0]  # rate gains exactly 30 % low, the rest drawn
    taken = plant_for(low, drawn)
    assert "sim.k_rate_scale" not in taken
    assert set(taken) == set(drawn) - {"sim.k_rate_scale"}
    square = select(["square-shaped-lqr-ff"])[0]
    assert plant_for(square, drawn) == drawn


@pytest.mark.parametrize(("values", "seeds"), [
    (["3"], [3]), (["1-5"], [1, 2, 3, 4, 5]), (["2", "1-3"], [2, 1, 3]), (["1,4", "4"], [1, 4]),
    ([" 7 - 8 "], [7, 8]), ([], []),
])
def test_seeds_from_the_command_line(values: list[str], seeds: list[int]) -> None:
    assert parse_seeds(values) == seeds


@pytest.mark.parametrize("bad", ["x", "-1", "5-3", "1-", "1.5", ""])
def test_bad_seeds_are_refused(bad: str) -> None:
    with pytest.raises(ConfigError, match="--perturb"):
        parse_seeds([bad])


def test_plant_row_gives_deviations_from_the_model() -> None:
    row = plant_row(2, {"sim.k_rate_scale": [0.75, 1.0, 1.25], "sim.rate_loop_tau_s": 0.07,
                        "sim.mass_scale": 1.1, "sim.thrust_scale": 0.9,
                        "sim.command_delay_s": 0.0125, "sim.gyro_bias": [0.01, 0.0, -0.02],
                        "sim.acc_bias": [0.1, 0.0, -0.1], "sim.motor_tau_s": 0.035})
    assert row[:6] == ["2", "-25.0 / +0.0 / +25.0", "70.0", "+10.0", "-10.0", "12.5"]
    assert row[-1] == "35.0" and len(row) == len(PLANT_COLUMNS)


@pytest.mark.slow
def test_a_short_perturbed_suite_reports_every_seed_and_the_worst(tmp_path: Path) -> None:
    names = ["takeoff-h135", "yaw-turn"]
    with sharing_flights():
        report = run_eval(load_config(REPO / "config" / "sim.yaml"), fast=True,
                          out_dir=tmp_path, scenarios=names, perturb=[1, 2])
    assert list(report.plants) == [1, 2] and report.plants[2] == perturbation(2)
    data: dict[str, Any] = json.loads(report.metrics_json.read_text(encoding="utf-8"))
    assert data["perturbation"]["seeds"] == [1, 2]
    assert data["perturbation"]["plants"]["1"]["sim.mass_scale"] == perturbation(1)[
        "sim.mass_scale"]
    for name in names:
        s = data["scenarios"][name]
        per_seed = {int(k): v["metrics"] for k, v in s["seeds"].items()}
        assert list(per_seed) == [1, 2] and s["failed_seeds"] == []
        assert per_seed[1]["rms_m"] != per_seed[2]["rms_m"]  # different plants, different flights
        for key in ("rms_m", "max_m", "heading_end_deg", "max_tilt_deg"):
            worst = max(m[key] for m in per_seed.values())
            assert s["metrics"][key] == worst
            assert per_seed[s["worst_seed"][key]][key] == worst
        assert s["record_seed"] in (1, 2) and s["transitions"]
        assert report.outcomes[name].record.meta["seed"] == s["record_seed"]
    assert {t["scenario"] for t in data["targets"]} == set(names)
    text = report.report_md.read_text(encoding="utf-8")
    assert "## Perturbed plants" in text and "## Targets" in text
    assert "| 1 | " in text and "| 2 | " in text  # the plant table's rows
    rms = report.metrics["yaw-turn"]["rms_m"]
    assert f"{100 * rms:.2f} (s{report.worst_seeds['yaw-turn']['rms_m']})" in text
    assert sorted(p.name for p in report.figures) == ["takeoff_h135.png", "yaw_turn.png"]
    for png in report.figures:
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and f"]({png.name})" in text
    assert not math.isnan(report.wall_s)


@pytest.mark.slow
def test_gs_eval_takes_perturb_seeds(tmp_path: Path) -> None:
    from typer.testing import CliRunner

    from groundstation.cli import app

    runner = CliRunner()
    config = str(REPO / "config" / "sim.yaml")
    bad = runner.invoke(app, ["eval", "--config", config, "--fast", "--perturb", "2-x"])
    assert bad.exit_code == 2 and "--perturb '2-x'" in bad.output
    out = tmp_path / "eval"
    with sharing_flights():
        res = runner.invoke(app, ["eval", "--config", config, "--fast", "--out", str(out),
                                  "--scenario", "hover-h90", "--perturb", "3"])
    assert res.exit_code == 0, res.output
    data = json.loads((out / "metrics.json").read_text(encoding="utf-8"))
    assert data["perturbation"]["seeds"] == [3]
    assert list(data["scenarios"]["hover-h90"]["seeds"]) == ["3"]
