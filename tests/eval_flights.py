"""The evaluation suite's in-process flights, each flown once per test process and handed to
every test that asks for it. Test-only (not part of the package), imported like
``lab_helpers``.

An in-process flight on the simulated clock is a function of its scenario and its
configuration (the plant's draws are seeded), so a flight flown once serves every test
that needs the same one: the targets' worst case over the seeds, the short perturbed
suite's report, ``gs eval``'s output, the Ch. 11 regression figures and their report.
:func:`sharing_flights` puts the memo under :func:`sim_device.evaluation.run_eval` too,
so a test that runs the whole ``gs eval`` flies only the flights no earlier test flew.

Across the xdist workers of one session the flights are shared on disk: the session's
controller names a directory (:data:`MEMO_ENV`, set by ``tests/conftest.py``) and the first
worker to need a flight flies it under a file lock while any other that needs it waits,
then reads the pickled record. So tests that share flights need not share a worker.
"""

from __future__ import annotations

import fcntl
import hashlib
import os
import pickle
import tempfile
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path

import pytest

from groundstation.config import GroundStationConfig, dump_config, load_config
from groundstation.evaluation.record import FlightRecord
from sim_device.evaluation import suite as suite_module
from sim_device.evaluation.perturb import perturbation
from sim_device.evaluation.runner import run_in_process
from sim_device.evaluation.scenarios import Scenario, select
from sim_device.evaluation.suite import ScenarioOutcome, fly_perturbed, fly_scenario

REPO = Path(__file__).resolve().parents[1]
PERTURBED_SEEDS = (1, 2, 3, 4, 5)
"""The plants the targets are judged on (``gs eval --fast --perturb 1-5``)."""

MEMO_ENV = "GS_TEST_FLIGHTS"
"""The environment variable naming the session's directory of flown records (unset: each
process keeps its own)."""

_records: dict[tuple[str, str], FlightRecord] = {}


def share_on_disk() -> Path | None:
    """Name a fresh directory for this session's flights in :data:`MEMO_ENV` (inherited by
    the xdist workers started after it) and return it; None if one is named already."""
    if os.environ.get(MEMO_ENV):
        return None
    root = Path(tempfile.mkdtemp(prefix="gs-test-flights-"))
    os.environ[MEMO_ENV] = str(root)
    return root


def base_config() -> GroundStationConfig:
    """``config/sim.yaml``, the evaluation's base configuration."""
    return load_config(REPO / "config" / "sim.yaml")


def flown(scenario: Scenario, config: GroundStationConfig) -> FlightRecord:
    """:func:`sim_device.evaluation.runner.run_in_process`, flown once per (scenario,
    configuration) in this process."""
    key = (repr(scenario), dump_config(config))
    if key not in _records:
        _records[key] = _shared(key, scenario, config)
    return _records[key]


def _shared(key: tuple[str, str], scenario: Scenario,
            config: GroundStationConfig) -> FlightRecord:
    """The flight from the session's directory, flown and written there by whichever
    worker asked first (the others wait on its lock), or flown here if there is none."""
    root = os.environ.get(MEMO_ENV)
    if not root:
        return run_in_process(scenario, config)
    name = hashlib.sha256("\0".join(key).encode()).hexdigest()[:40]
    path = Path(root) / f"{name}.pickle"
    with open(Path(root) / f"{name}.lock", "w", encoding="utf-8") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if path.exists():
            record: FlightRecord = pickle.loads(path.read_bytes())
            return record
        record = run_in_process(scenario, config)
        partial = path.with_suffix(".partial")
        partial.write_bytes(pickle.dumps(record, protocol=pickle.HIGHEST_PROTOCOL))
        partial.replace(path)
        return record


@contextmanager
def sharing_flights() -> Iterator[None]:
    """Within the block, the evaluation suite flies in-process through :func:`flown`."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(suite_module, "run_in_process", flown)
        yield


def nominal(name: str, workdir: Path) -> ScenarioOutcome:
    """Scenario ``name`` flown and scored on the nominal plant (``gs eval --fast``)."""
    with sharing_flights():
        return fly_scenario(select([name])[0], base_config(), fast=True, workdir=workdir)


def perturbed(name: str, workdir: Path,
              seeds: Sequence[int] = PERTURBED_SEEDS) -> ScenarioOutcome:
    """Scenario ``name`` flown on every seed's plant, reduced to the worst case as
    ``gs eval --fast --perturb`` does (:func:`sim_device.evaluation.suite.fly_perturbed`)."""
    cfg = base_config()
    plants = {seed: perturbation(seed, cfg.vehicle.rate_loop_tau_s) for seed in seeds}
    with sharing_flights():
        return fly_perturbed(select([name])[0], cfg, plants, fast=True, workdir=workdir)
