"""Flight recorder: values round-trip, the file loads after every flush and after SIGKILL,
CSV export, metadata. Expected values are the inputs themselves (seeded random ticks),
compared field by field through independent readers (np.load, np.genfromtxt, json)."""

from __future__ import annotations

import contextlib
import datetime as dt
import errno
import io
import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from groundstation import __version__
from groundstation.app.recorder import (
    COLUMN_UNITS,
    FLAT_DTYPE,
    RECORD_DTYPE,
    FlightRecorder,
    read_flight,
)
from groundstation.asctec.messages import CommandMsg
from groundstation.errors import GroundStationError, RecorderError
from groundstation.export import CSV_PRECISION, export_csv
from groundstation.types import ImuSample, Pose, Reference, StateEstimate, Sticks

CONFIG = "serial:\n  port: /dev/ttyUSB0\n"
STATES = ["PREFLIGHT", "TAKEOFF", "TRACK"]


def make_tick(rng: np.random.Generator, k: int) -> dict[str, Any]:
    """Random append() arguments for tick k at 100 Hz; every third tick has no pose."""
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    return dict(
        t=100.0 + 0.01 * k,
        imu=ImuSample(100.0 + 0.01 * k - 0.003, rng.normal(size=3), rng.normal(size=3),
                      int(rng.integers(0, 65536))),
        gyro_counts=tuple(int(v) for v in rng.integers(0, 4096, 3)),
        acc_counts=tuple(int(v) for v in rng.integers(0, 4096, 3)),
        pose=None if k % 3 == 0 else Pose(99.99 + 0.01 * k, rng.normal(size=3), q, k),
        estimate=StateEstimate(100.0 + 0.01 * k, *(rng.normal(size=n) for n in (3, 4, 3, 3, 3, 3)),
                               rng.random(16)),
        reference=Reference(0.01 * k, rng.normal(size=3), rng.normal(size=3), yaw=rng.normal()),
        command=CommandMsg(*(int(v) for v in rng.integers(-2047, 2048, 3)),
                           int(rng.integers(0, 4097)), int(rng.integers(0, 16))),
        controller=None if k % 4 == 0 else Sticks(
            *(int(v) for v in rng.integers(-2048, 2048, 3)), int(rng.integers(0, 4097))),
        sent=bool(k % 2), state=k % 3,
        compute_time=rng.random() * 1e-3, jitter=rng.normal() * 1e-4, latency=rng.random() * 1e-2,
        battery_v=11.8 - 1e-3 * k, vehicle_flags=int(rng.integers(0, 8)),
        vehicle_mask=int(rng.integers(0, 16)), pilot_enabled=bool(k % 5),
        pilot=None if k % 6 == 0 else Sticks(
            *(int(v) for v in rng.integers(-2048, 2048, 3)), int(rng.integers(0, 4097))),
    )


def expected_row(a: dict[str, Any]) -> dict[str, Any]:
    """The record fields append() must store for the arguments ``a``."""
    pose, est, ref, cmd = a["pose"], a["estimate"], a["reference"], a["command"]
    ctrl = a["controller"] if a["controller"] is not None else Sticks(0, 0, 0, 0)
    pilot = a["pilot"] if a["pilot"] is not None else Sticks(0, 0, 0, 0)
    nan3, nan4 = np.full(3, np.nan), np.full(4, np.nan)
    return {
        "t": a["t"], "imu_t": a["imu"].t, "imu_counter": a["imu"].counter,
        "gyro_counts": a["gyro_counts"], "acc_counts": a["acc_counts"],
        "gyro": a["imu"].gyro, "acc": a["imu"].acc,
        "vicon_valid": pose is not None,
        "vicon_t": np.nan if pose is None else pose.t,
        "vicon_position": nan3 if pose is None else pose.position,
        "vicon_quaternion": nan4 if pose is None else pose.quaternion,
        "est_position": est.position, "est_quaternion": est.quaternion,
        "est_velocity_body": est.velocity_body, "est_omega": est.omega,
        "est_gyro_bias": est.gyro_bias, "est_acc_bias": est.acc_bias,
        "est_covariance_diag": est.covariance_diag,
        "ref_position": ref.position, "ref_velocity": ref.velocity, "ref_yaw": ref.yaw,
        "cmd_pitch": cmd.pitch, "cmd_roll": cmd.roll, "cmd_yaw": cmd.yaw,
        "cmd_thrust": cmd.thrust, "cmd_mask": cmd.ctrl, "cmd_sent": a["sent"],
        "ctrl_pitch": ctrl.pitch, "ctrl_roll": ctrl.roll, "ctrl_yaw": ctrl.yaw,
        "ctrl_thrust": ctrl.thrust,
        "state": a["state"], "compute_time": a["compute_time"], "jitter": a["jitter"],
        "latency": a["latency"], "battery_v": a["battery_v"],
        "vehicle_flags": a["vehicle_flags"], "vehicle_mask": a["vehicle_mask"],
        "pilot_enabled": a["pilot_enabled"], "pilot_pitch": pilot.pitch,
        "pilot_roll": pilot.roll, "pilot_yaw": pilot.yaw, "pilot_thrust": pilot.thrust,
    }


def assert_rows(data: np.ndarray, ticks: list[dict[str, Any]]) -> None:
    assert data.dtype == RECORD_DTYPE
    assert len(data) == len(ticks)
    for row, args in zip(data, ticks, strict=True):
        for name, value in expected_row(args).items():
            np.testing.assert_array_equal(row[name], value, err_msg=name)  # NaN == NaN here


@pytest.mark.slow
def test_round_trip_every_field(tmp_path: Path) -> None:
    rng = np.random.default_rng(1)
    ticks = [make_tick(rng, k) for k in range(250)]
    # capacity 64 < 100 rows per flush interval: exercises flush-when-full and by-time
    with FlightRecorder.create(tmp_path, CONFIG, capacity=64) as rec:
        for args in ticks:
            rec.append(**args)
        assert rec.rows == 250
    data, meta, config = read_flight(rec.directory)
    assert_rows(data, ticks)
    assert config == CONFIG
    assert meta["rows"] == 250 and meta["bad_rows"] == 0 and meta["rows_dropped"] == 0


def test_missing_estimate_and_reference_are_nan(tmp_path: Path) -> None:
    args = make_tick(np.random.default_rng(2), 0)  # k = 0: no pose either
    args.update(estimate=None, reference=None)
    with FlightRecorder.create(tmp_path, CONFIG) as rec:
        rec.append(**args)
    row = read_flight(rec.directory)[0][0]
    assert not row["vicon_valid"]
    for name in ("vicon_position", "est_position", "est_covariance_diag", "ref_velocity",
                 "ref_yaw", "vicon_t"):
        assert np.all(np.isnan(row[name])), name


def test_without_a_status_block_the_battery_is_nan(tmp_path: Path) -> None:
    args = make_tick(np.random.default_rng(3), 1)
    for name in ("battery_v", "vehicle_flags", "vehicle_mask", "pilot_enabled", "pilot"):
        del args[name]
    with FlightRecorder.create(tmp_path, CONFIG) as rec:
        rec.append(**args)
    data, meta, _ = read_flight(rec.directory)
    row = data[0]
    assert np.isnan(row["battery_v"]) and row["vehicle_flags"] == row["vehicle_mask"] == 0
    assert row["pilot_enabled"]
    assert row["pilot_thrust"] == row["pilot_yaw"] == 0  # no RC block: no pilot sticks
    assert meta["schema_version"] == 5
    assert meta["units"]["battery_v"] == "V" and meta["units"]["vehicle_mask"] == "bits"


def test_np_load_works_after_every_flush(tmp_path: Path) -> None:
    rng = np.random.default_rng(3)
    ticks = [make_tick(rng, k) for k in range(40)]
    with FlightRecorder.create(tmp_path, CONFIG, flush_interval_s=1e9) as rec:
        assert np.load(rec.path).shape == (0,)  # loadable before the first row
        rec.append(**ticks[0])  # the first row is flushed at once
        for k, args in enumerate(ticks[1:], start=2):
            rec.append(**args)
            if k % 7 == 0:
                rec.flush()
                on_disk = np.load(rec.path)
                assert on_disk.dtype == FLAT_DTYPE  # one scalar column each (pandas-ready)
                assert_rows(on_disk.view(RECORD_DTYPE), ticks[:k])
        assert len(np.load(rec.path)) == 35  # 5 rows appended since the last flush...
    assert len(np.load(rec.path)) == 40  # ...written by close()


@pytest.mark.slow
def test_automatic_flush_keeps_at_most_one_second_in_memory(tmp_path: Path) -> None:
    rng = np.random.default_rng(4)
    with FlightRecorder.create(tmp_path, CONFIG, flush_interval_s=1.0) as rec:
        for k in range(350):
            rec.append(**make_tick(rng, k))  # t advances 10 ms per tick
            on_disk = len(np.load(rec.path))
            # at 100 Hz, 1 s is 100 rows: never more than 100 rows only in memory
            assert k + 1 - 100 <= on_disk <= k + 1
        assert len(np.load(rec.path)) == 301  # flushes at ticks 0, 100, 200, 300


_KILLED_WRITER = textwrap.dedent("""
    import sys
    import numpy as np
    from groundstation.app.recorder import FlightRecorder
    sys.path.insert(0, sys.argv[2])
    from test_recorder import CONFIG, make_tick
    rng = np.random.default_rng(5)
    rec = FlightRecorder.create(sys.argv[1], CONFIG, flush_interval_s=1e9)
    for k in range(120):
        rec.append(**make_tick(rng, k))
        if k == 99:
            rec.flush()
    print(rec.directory, flush=True)
    sys.stdin.read()  # wait to be killed
""")


@pytest.mark.slow
def test_sigkill_leaves_a_loadable_file_with_the_flushed_rows(tmp_path: Path) -> None:
    proc = subprocess.Popen(
        [sys.executable, "-c", _KILLED_WRITER, str(tmp_path), str(Path(__file__).parent)],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
    )
    try:
        assert proc.stdout is not None
        directory = Path(proc.stdout.readline().strip())
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.communicate(timeout=10)
    assert proc.returncode == -signal.SIGKILL
    rng = np.random.default_rng(5)
    ticks = [make_tick(rng, k) for k in range(120)]
    data, meta, config = read_flight(directory)
    assert_rows(data, ticks[:100])  # rows 100..119 were never flushed
    assert config == CONFIG and "end_time" not in meta  # never closed


def test_csv_export_reads_back_with_genfromtxt(tmp_path: Path) -> None:
    rng = np.random.default_rng(6)
    ticks = [make_tick(rng, k) for k in range(30)]
    with FlightRecorder.create(tmp_path, CONFIG, {"supervisor_states": STATES}) as rec:
        for args in ticks:
            rec.append(**args)
    out = tmp_path / "flight.csv"
    assert export_csv(rec.directory, out) == 30
    stream = io.StringIO()
    assert export_csv(rec.directory / "flight.npy", stream) == 30  # e.g. sys.stdout
    assert stream.getvalue() == out.read_text()
    header = out.read_text().splitlines()[0].split(",")
    assert header[:4] == ["t [s]", "imu_t [s]", "imu_counter", "gyro_counts_x [count]"]
    names = [h.partition(" [")[0] for h in header]
    assert [n for n in names if n != "state_name"] == list(FLAT_DTYPE.names or ())
    numbers = [i for i, n in enumerate(names) if n != "state_name"]
    csv = np.genfromtxt(out, delimiter=",", skip_header=1, usecols=numbers)  # empty -> nan
    column = {n: csv[:, k] for k, n in enumerate(n for n in names if n != "state_name")}
    flat = np.load(rec.path)
    for name in FLAT_DTYPE.names or ():
        if FLAT_DTYPE[name].kind != "f":
            np.testing.assert_array_equal(column[name], flat[name].astype(float), err_msg=name)
    # floats at their precision: compare against the inputs themselves
    position = np.column_stack([column[f"est_position_{c}"] for c in "xyz"])
    assert CSV_PRECISION["est_position"].digits == 5
    np.testing.assert_allclose(position, [a["estimate"].position for a in ticks], rtol=0,
                               atol=5e-6 + 1e-12)
    assert CSV_PRECISION["est_covariance_diag"] == (4, True)  # 4 significant digits
    np.testing.assert_allclose(column["est_covariance_diag_baz"],
                               [a["estimate"].covariance_diag[15] for a in ticks], rtol=5e-4)
    np.testing.assert_array_equal(column["battery_v"], [round(a["battery_v"], 3) for a in ticks])
    no_pose = [a["pose"] is None for a in ticks]
    np.testing.assert_array_equal(np.isnan(column["vicon_position_x"]), no_pose)
    state_names = [line.split(",")[names.index("state_name")]
                   for line in out.read_text().splitlines()[1:]]
    assert state_names == [STATES[a["state"]] for a in ticks]


def test_meta_and_config_files(tmp_path: Path) -> None:
    before = time.monotonic()
    with FlightRecorder.create(tmp_path / "logs", CONFIG, {"supervisor_states": STATES}) as rec:
        meta_open = json.loads((rec.directory / "meta.json").read_text())
        assert (rec.directory / "config.yaml").read_text() == CONFIG
    assert rec.directory.parent == tmp_path / "logs"
    start = dt.datetime.fromisoformat(meta_open["start_time"])
    assert start.utcoffset() == dt.timedelta(0)
    assert rec.directory.name == start.strftime("%Y%m%dT%H%M%SZ")
    assert before <= meta_open["start_monotonic"] <= time.monotonic()
    assert meta_open["version"] == __version__
    assert meta_open["supervisor_states"] == STATES
    assert set(meta_open["units"]) == set(FLAT_DTYPE.names or ())
    assert meta_open["units"]["est_covariance_diag_px"] == "m^2"
    assert meta_open["units"]["est_covariance_diag_bgz"] == "(rad/s)^2"
    assert meta_open["units"]["gyro_x"] == "rad/s"
    meta = read_flight(rec.directory)[1]
    assert meta["rows"] == 0 and meta["end_monotonic"] >= meta["start_monotonic"]
    assert COLUMN_UNITS["latency"] == "s"


def test_two_flights_in_one_second_get_their_own_directories(tmp_path: Path) -> None:
    with FlightRecorder.create(tmp_path, CONFIG) as a, FlightRecorder.create(tmp_path, CONFIG) as b:
        assert a.directory != b.directory
    assert len(list(tmp_path.iterdir())) == 2


def test_bad_values_skip_the_row_and_close_is_idempotent(tmp_path: Path) -> None:
    rng = np.random.default_rng(7)
    good = make_tick(rng, 1)
    rec = FlightRecorder.create(tmp_path, CONFIG)
    rec.append(**{**good, "gyro_counts": (1, 2)})  # wrong shape
    rec.append(**{**good, "controller": Sticks(thrust=70000)})  # beyond int16
    rec.append(**good)
    assert rec.bad_rows == 2 and rec.rows == 1
    rec.close()
    rec.close()
    assert rec.closed
    rec.append(**good)  # after close: counted, not written, no exception
    assert rec.bad_rows == 3
    assert_rows(read_flight(rec.directory)[0], [good])


def test_write_failure_is_counted_not_raised(tmp_path: Path) -> None:
    rng = np.random.default_rng(8)
    rec = FlightRecorder.create(tmp_path, CONFIG, flush_interval_s=1e9)
    rec.append(**make_tick(rng, 0))  # flushed at once
    full = os.open("/dev/full", os.O_WRONLY)  # a real device whose writes fail with ENOSPC
    try:
        os.dup2(full, rec._fd)  # the recorder's own descriptor now points at a full disk
    finally:
        os.close(full)
    rec.append(**make_tick(rng, 1))
    rec.flush()
    assert rec.write_errors == 1 and rec.rows_dropped == 1
    rec.close()  # fsync on /dev/full fails too: logged, not raised
    assert rec.closed


def test_read_flight_rejects_what_is_not_a_flight_log(tmp_path: Path) -> None:
    with pytest.raises(GroundStationError, match="not a readable flight log"):
        read_flight(tmp_path)
    np.save(tmp_path / "flight.npy", np.zeros(3))
    (tmp_path / "meta.json").write_text("{}")
    (tmp_path / "config.yaml").write_text("")
    with pytest.raises(GroundStationError, match="schema"):
        read_flight(tmp_path / "flight.npy")


def test_create_reports_an_unwritable_log_dir(tmp_path: Path) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("")
    with pytest.raises(GroundStationError, match="cannot start a flight log"):
        FlightRecorder.create(blocker / "logs", CONFIG)


def test_a_schema_3_log_is_read_with_the_new_columns_filled(tmp_path: Path) -> None:
    """Logs recorded before the pilot's sticks were logged (schema 3: no pilot columns,
    uint16 counts, no estimator verdicts) stay readable: every old column intact, the new
    ones zero (NaN for the NIS)."""
    rng = np.random.default_rng(5)
    ticks = [make_tick(rng, k) for k in range(20)]
    with FlightRecorder.create(tmp_path, CONFIG) as rec:
        for args in ticks:
            rec.append(**args)
    current = np.load(rec.path)
    old_fields = [(name, "<u2" if name.endswith("_counts_x") or name.endswith("_counts_y")
                   or name.endswith("_counts_z") else current.dtype[name].str)
                  for name in current.dtype.names or () if (not name.startswith("pilot_")
                  or name == "pilot_enabled") and name not in ("vicon_nis", "vicon_refused")]
    old = np.zeros(len(current), dtype=old_fields)
    for name, _ in old_fields:
        old[name] = current[name]
    np.save(rec.path, old)
    meta = json.loads((rec.directory / "meta.json").read_text())
    meta["schema_version"] = 3
    (rec.directory / "meta.json").write_text(json.dumps(meta))
    data, meta_back, _ = read_flight(rec.directory)
    assert meta_back["migrated_from_schema"] == 3
    for row, args in zip(data, ticks, strict=True):
        np.testing.assert_array_equal(row["gyro_counts"], args["gyro_counts"])
        assert row["cmd_thrust"] == args["command"].thrust
        assert row["pilot_thrust"] == 0
        assert np.isnan(row["vicon_nis"]) and row["vicon_refused"] == 0  # schema 5's columns
    np.save(rec.path, np.zeros(3, dtype=[("unknown", "<f8")]))
    with pytest.raises(RecorderError, match="cannot be read"):
        read_flight(rec.directory)


@pytest.fixture
def tiny_disk(tmp_path: Path) -> Iterator[Callable[[str], Path]]:
    """``mount(size)``: a tmpfs of ``size`` (``"400k"``) mounted in tmp_path, unmounted
    after the test. A real full disk: writes fail with ENOSPC in the kernel, as they do
    on the lab machine's disk."""
    if os.geteuid() != 0:
        pytest.skip("mounting a tmpfs in the test's own process needs root (the "
                    "full-disk flight in test_daemon_exits.py uses unshare -rm instead)")
    mounted: list[Path] = []

    def mount(size: str) -> Path:
        where = tmp_path / f"disk{len(mounted)}"
        where.mkdir()
        subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(where)],
                       check=True, capture_output=True)
        mounted.append(where)
        return where

    yield mount
    for where in mounted:
        subprocess.run(["umount", "-l", str(where)], check=False, capture_output=True)


def free_bytes(path: Path) -> int:
    st = os.statvfs(path)
    return st.f_bavail * st.f_frsize


def fill(disk: Path, leave: int = 0) -> None:
    """Write a ballast file until the disk has ``leave`` bytes free (0: full)."""
    fd = os.open(disk / "ballast", os.O_WRONLY | os.O_CREAT | os.O_EXCL)
    try:
        with contextlib.suppress(OSError):  # ENOSPC: full
            while (room := free_bytes(disk) - leave) > 0:
                os.write(fd, bytes(min(room, 1 << 16)))
    finally:
        os.close(fd)
    assert free_bytes(disk) <= leave


def test_a_disk_that_fills_loses_rows_counts_them_and_keeps_the_end(
        tiny_disk: Callable[[str], Path]) -> None:
    """400 kB: after the reserves (meta.json 64 kB, 256 rows) about 200 rows fit. 600
    ticks at 100 Hz: the disk fills after the second flush; every later flush is lost
    until the last, which writes the flight's last second into the reserve."""
    disk = tiny_disk("400k")
    rng = np.random.default_rng(9)
    ticks = [make_tick(rng, k) for k in range(600)]
    rec = FlightRecorder.create(disk, CONFIG, {"supervisor_states": STATES})
    for args in ticks:
        rec.append(**args)
    assert free_bytes(disk) < 100 * RECORD_DTYPE.itemsize  # really full
    rec.meta["outcome"] = {"exit_code": 5}
    rec.close()
    enospc = os.strerror(errno.ENOSPC)
    assert rec.rows_dropped > 0 and rec.lost_by_reason == {enospc: rec.rows_dropped}
    data, meta, _ = read_flight(rec.directory)
    index = np.rint((data["t"] - 100.0) / 0.01).astype(int)  # which tick each row is
    assert_rows(data, [ticks[k] for k in index])
    assert index[-1] == 599 and np.all(np.diff(index) >= 1)  # the end is there, in order
    written_then_lost = np.flatnonzero(np.diff(index) > 1)
    assert len(written_then_lost) == 1  # one gap: from the full disk to the last flush
    assert len(data) + rec.rows_dropped == 600
    assert meta["rows"] == len(data) and meta["rows_dropped"] == rec.rows_dropped
    assert meta["lost_rows_by_reason"] == {enospc: rec.rows_dropped}
    assert meta["outcome"] == {"exit_code": 5}
    loss = rec.loss()
    assert not loss.complete and loss.describe() == (
        f"flight log incomplete: {rec.rows_dropped} of 600 rows lost ({enospc})")
    assert sorted(p.name for p in rec.directory.iterdir()) == ["config.yaml", "flight.npy",
                                                               "meta.json"]
    # the unused reserve went back to the disk: the file holds its header and rows only
    with rec.path.open("rb") as f:
        assert np.lib.format.read_magic(f) == (1, 0)
        np.lib.format.read_array_header_1_0(f)  # numpy's reader: where the rows start
        header = f.tell()
    assert os.path.getsize(rec.path) == header + len(data) * RECORD_DTYPE.itemsize
    assert free_bytes(disk) > 100 * RECORD_DTYPE.itemsize


def test_the_outcome_reaches_meta_json_on_a_full_disk(
        tiny_disk: Callable[[str], Path]) -> None:
    """The finding: meta.json had no outcome and an empty meta.json.tmp was left. The
    final meta.json is written into space allocated at the start."""
    disk = tiny_disk("256k")
    rng = np.random.default_rng(10)
    rec = FlightRecorder.create(disk, CONFIG, {"supervisor_states": STATES},
                                reserve_rows=16)
    rec.append(**make_tick(rng, 0))  # written at once
    fill(disk)
    with pytest.raises(OSError) as full:
        (disk / "probe").write_bytes(b"x")
    assert full.value.errno == errno.ENOSPC
    ticks = [make_tick(rng, k) for k in range(1, 11)]
    for args in ticks:
        rec.append(**args)  # buffered: the flush interval has not passed
    rec.meta["outcome"] = {"outcome": "COMPLETED", "exit_code": 0, "reason": "x" * 2000}
    rec.close()
    assert rec.meta_error == "" and rec.rows_dropped == 0
    data, meta, _ = read_flight(rec.directory)  # json.loads: valid JSON
    assert meta["outcome"]["reason"] == "x" * 2000 and meta["rows"] == 11
    assert_rows(data[1:], ticks)  # the last flush went into the reserve
    assert not list(disk.rglob("*.tmp")) and not list(disk.rglob("*.reserve"))


def test_a_disk_too_full_to_start_refuses_and_leaves_no_temporary(
        tiny_disk: Callable[[str], Path]) -> None:
    """Room for config.yaml only: meta.json cannot be written, and the flight does not
    start (`gs fly` exits 3) rather than fly without a log that can say how it ended."""
    disk = tiny_disk("256k")
    fill(disk, leave=4096)  # one page: config.yaml
    with pytest.raises(RecorderError, match="cannot start a flight log"):
        FlightRecorder.create(disk / "logs", CONFIG, {"supervisor_states": STATES})
    assert [p.name for p in disk.rglob("*") if p.is_file()] == ["ballast", "config.yaml"]
