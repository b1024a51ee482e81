"""`gs export --format csv|parquet`: tables with units, the CSV at its sensors' precision.

The CSV's header names every column with its unit and pandas reads it as written; every
float column comes back within half its declared precision of flight.npy's value (read
with np.load, the tolerance computed here from the declared digits), integers exactly,
and the file is far smaller than one with full float reprs. The Parquet file reads back
with pyarrow and pandas equal to flight.npy, units in its field metadata and meta.json in
its schema metadata. The columns of flight.npy, CSV and Parquet cannot drift apart.
"""

from __future__ import annotations

import csv
import io
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import numpy.typing as npt
import pandas as pd
import pyarrow.parquet as pq
import pytest
from lab_helpers import empty_log, fly_logged, sim_config

from groundstation.app.recorder import COLUMN_UNITS, FLAT_DTYPE, RECORD_DTYPE, read_flight
from groundstation.export import (
    CSV_PRECISION,
    FIELD_OF_COLUMN,
    csv_header,
    export_csv,
    export_parquet,
    tabular_columns,
)

REPO = Path(__file__).resolve().parents[1]
GS = [sys.executable, "-c", "import sys; from groundstation.cli import main; "
      "sys.argv[0] = 'gs'; main()"]


@pytest.fixture(scope="module")
def log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return fly_logged(sim_config(**{"trajectory.name": "square"}),
                      tmp_path_factory.mktemp("tabular"), 3.0)[0]


def _gs(*args: str, env: dict[str, str] | None = None) -> subprocess.CompletedProcess[str]:
    return subprocess.run([*GS, *args], capture_output=True, text=True, timeout=120, cwd=REPO,
                          env=env)


def test_every_column_is_in_the_csv_and_the_parquet_with_its_unit() -> None:
    flat = list(FLAT_DTYPE.names or ())
    columns = tabular_columns()
    assert [c for c in columns if c != "state_name"] == flat
    assert columns[columns.index("state") + 1] == "state_name"
    header = csv_header()
    assert [h.partition(" [")[0] for h in header] == columns
    for name, label in zip(columns, header, strict=True):
        unit = COLUMN_UNITS.get(name, "")
        if unit in ("", "1", "bool", "enum"):
            assert label == name  # dimensionless: no brackets
        else:
            assert label == f"{name} [{unit}]"
    assert header[:4] == ["t [s]", "imu_t [s]", "imu_counter", "gyro_counts_x [count]"]
    assert "vicon_position_x [m]" in header and "acc_z [m/s^2]" in header
    # every float field has a declared precision, and nothing else does
    floats = {n for n in RECORD_DTYPE.names or () if RECORD_DTYPE[n].base.kind == "f"}
    assert set(CSV_PRECISION) == floats
    assert set(FIELD_OF_COLUMN) == set(flat)
    assert set(FIELD_OF_COLUMN.values()) == set(RECORD_DTYPE.names or ())


def test_the_declared_precisions_follow_the_sensors() -> None:
    # STATUS carries the battery in mV: three decimals in V lose nothing
    assert CSV_PRECISION["battery_v"].digits == 3
    # Vicon noise std >= 0.057 mm: at least 0.01 mm; quaternion noise std >= 3.3e-5
    assert CSV_PRECISION["vicon_position"].digits >= 5
    assert CSV_PRECISION["vicon_quaternion"].digits >= 6
    # the smallest IMU count step is 0.0077 SI units: the count must stay recoverable
    assert 10.0 ** -CSV_PRECISION["gyro"].digits < 0.0077 / 100
    assert CSV_PRECISION["t"].digits == 6  # 1 us


def _half_step(value: npt.NDArray[np.float64], digits: int,
               significant: bool) -> npt.NDArray[np.float64]:
    """Half the last kept digit's step at ``value`` (what rounding may change)."""
    if not significant:
        return np.full_like(value, 0.5 * 10.0 ** -digits)
    magnitude = np.floor(np.log10(np.where(value == 0, 1.0, np.abs(value))))
    return 0.5 * 10.0 ** (magnitude - (digits - 1))


@pytest.mark.slow
def test_the_csv_reads_back_within_half_its_precision(log: Path, tmp_path: Path) -> None:
    out = tmp_path / "flight.csv"
    assert export_csv(log, out) == len(np.load(log / "flight.npy"))
    table = pd.read_csv(out)  # as the README says
    flat = np.load(log / "flight.npy")
    meta = json.loads((log / "meta.json").read_text())
    assert len(table) == len(flat) > 300
    assert list(table.columns) == csv_header()
    for name, label in zip(tabular_columns(), table.columns, strict=True):
        if name == "state_name":
            assert list(table[label]) == [meta["supervisor_states"][s] for s in flat["state"]]
            continue
        want, got = flat[name], table[label].to_numpy()
        if FLAT_DTYPE[name].kind != "f":
            assert got.dtype.kind in "iu", name  # integers stay integers
            np.testing.assert_array_equal(got, want.astype(np.int64), err_msg=name)
            continue
        precision = CSV_PRECISION[FIELD_OF_COLUMN[name]]
        np.testing.assert_array_equal(np.isnan(got), np.isnan(want), err_msg=name)
        ok = ~np.isnan(want)
        tolerance = _half_step(want[ok], precision.digits, precision.significant)
        error = np.abs(got[ok] - want[ok])
        assert np.all(error <= tolerance * (1 + 1e-9) + 4 * np.spacing(np.abs(want[ok]))), name
    assert set(table["state_name"]) >= {"TAKEOFF", "DONE"}


@pytest.mark.slow
def test_numpy_reads_the_csv_too(log: Path, tmp_path: Path) -> None:
    out = tmp_path / "flight.csv"
    export_csv(log, out)
    table = np.genfromtxt(out, delimiter=",", names=True, dtype=None, encoding="utf-8")
    assert len(table) == len(np.load(log / "flight.npy"))
    # genfromtxt drops brackets and slashes from the names: `acc_z [m/s^2]` -> `acc_z_ms2`
    assert {"t_s", "vicon_position_x_m", "acc_z_ms2", "state_name"} <= set(table.dtype.names)
    np.testing.assert_allclose(table["battery_v_V"], np.load(log / "flight.npy")["battery_v"],
                               atol=5e-4)


@pytest.mark.slow
def test_missing_values_are_empty_fields(log: Path) -> None:
    stream = io.StringIO()
    export_csv(log, stream)
    lines = list(csv.reader(io.StringIO(stream.getvalue())))
    column = lines[0].index("preview_position_x [m]")
    flat = np.load(log / "flight.npy")
    missing = np.isnan(flat["preview_position_x"])
    assert missing.any()
    assert all((row[column] == "") == m for row, m in zip(lines[1:], missing, strict=True))
    assert not any(field in ("nan", "-0") for row in lines[1:] for field in row)


@pytest.mark.slow
def test_the_csv_is_far_smaller_than_full_float_reprs(log: Path, tmp_path: Path) -> None:
    flat = np.load(log / "flight.npy")
    full = io.StringIO()  # what `gs export` wrote before: shortest round-trip reprs
    np.savetxt(full, flat, delimiter=",", header=",".join(FLAT_DTYPE.names or ()), comments="",
               fmt=["%s" if FLAT_DTYPE[n].kind == "f" else "%d" for n in FLAT_DTYPE.names or ()])
    out = tmp_path / "flight.csv"
    export_csv(log, out)
    assert out.stat().st_size < 0.6 * len(full.getvalue())


@pytest.mark.slow
def test_csv_goes_to_stdout_without_out(log: Path, tmp_path: Path) -> None:
    done = _gs("export", str(log))
    assert done.returncode == 0, done.stderr
    out = tmp_path / "flight.csv"
    export_csv(log, out)
    assert done.stdout == out.read_text()


@pytest.mark.slow
def test_the_parquet_reads_back_equal_with_units_and_meta(log: Path, tmp_path: Path) -> None:
    out = tmp_path / "flight.parquet"
    done = _gs("export", str(log), "--format", "parquet", "--out", str(out))
    assert done.returncode == 0, done.stderr
    flat = np.load(log / "flight.npy")
    meta = json.loads((log / "meta.json").read_text())
    table = pq.read_table(out)
    assert table.column_names == tabular_columns()
    assert table.num_rows == len(flat) > 300
    for name in FLAT_DTYPE.names or ():
        column = table.column(name).to_numpy()
        assert column.dtype == flat.dtype[name], name  # native dtype, full precision
        np.testing.assert_array_equal(column, flat[name], err_msg=name)
        field = table.schema.field(name)
        assert field.metadata[b"unit"].decode() == meta["units"][name] == COLUMN_UNITS[name]
    names = meta["supervisor_states"]
    assert table.column("state_name").to_pylist() == [names[s] for s in flat["state"]]
    document = json.loads(table.schema.metadata[b"groundstation"])
    assert document["meta"]["start_time"] == meta["start_time"]
    assert document["meta"]["start_monotonic"] == meta["start_monotonic"]
    assert document["meta"]["supervisor_states"] == names
    assert document["meta"]["units"] == meta["units"]
    assert document["config"] == (log / "config.yaml").read_text()
    assert document["meta"]["version"] == meta["version"]
    frame = pd.read_parquet(out)  # as the README says
    assert isinstance(frame["state_name"].dtype, pd.CategoricalDtype)
    np.testing.assert_array_equal(frame["vicon_position_x"].to_numpy(),
                                  flat["vicon_position_x"])
    assert frame["cmd_thrust"].dtype == np.int16 and frame["vicon_valid"].dtype == bool
    assert list(frame["state_name"].astype(str)) == [names[s] for s in flat["state"]]


def test_an_empty_log_exports_a_header_and_no_rows(tmp_path: Path) -> None:
    log = empty_log(tmp_path / "logs")
    out = tmp_path / "flight.csv"
    assert export_csv(log, out) == 0
    assert out.read_text() == ",".join(csv_header()) + "\n"
    assert export_parquet(log, tmp_path / "flight.parquet") == 0
    assert pq.read_table(tmp_path / "flight.parquet").column_names == tabular_columns()


@pytest.mark.slow
def test_parquet_needs_an_output_file(log: Path) -> None:
    done = _gs("export", str(log), "--format", "parquet")
    assert done.returncode == 2 and "--out" in done.stderr


@pytest.mark.slow
def test_parquet_without_pyarrow_names_the_extra(log: Path, tmp_path: Path) -> None:
    fake = tmp_path / "site" / "pyarrow"
    fake.mkdir(parents=True)
    (fake / "__init__.py").write_text(
        "raise ModuleNotFoundError(\"No module named 'pyarrow'\", name='pyarrow')\n")
    env = {**os.environ, "PYTHONPATH": str(tmp_path / "site")}
    done = _gs("export", str(log), "--format", "parquet", "--out", str(tmp_path / "f.parquet"),
               env=env)
    assert done.returncode == 1, done.stderr
    assert done.stderr.strip() == ("error: Parquet export needs the pyarrow package: "
                                   "pip install 'groundstation[analysis]'")
    assert not (tmp_path / "f.parquet").exists()


def test_read_flight_agrees_with_the_parquet(log: Path, tmp_path: Path) -> None:
    """The vector fields read_flight gives are the Parquet's components in order."""
    out = tmp_path / "flight.parquet"
    export_parquet(log, out)
    rows = read_flight(log)[0]
    frame = pd.read_parquet(out)
    np.testing.assert_array_equal(
        frame[["est_quaternion_q0", "est_quaternion_q1", "est_quaternion_q2",
               "est_quaternion_q3"]].to_numpy(), rows["est_quaternion"])
