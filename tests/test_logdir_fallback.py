"""A flight log whose configured directory cannot be written falls back to the user's
directories, says so in one line, and fails only when no directory at all can take it.

The unwritable directory is made unwritable by the kernel, not by a mock: a directory
without write permission for an ordinary user, and, for root (whom permissions do not
stop), a path under sysfs, where nobody may make a directory."""

from __future__ import annotations

import json
import os
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from structlog.testing import capture_logs

from groundstation.app.logdir import create_flight_log, fallback_log_dirs
from groundstation.app.recorder import read_flight
from groundstation.errors import RecorderError


@pytest.fixture
def unwritable(tmp_path: Path) -> Iterator[Path]:
    """A flight-log directory the process cannot create (its parent refuses entries)."""
    parent = tmp_path / "locked"
    parent.mkdir()
    parent.chmod(0o500)
    target = parent / "flightlogs"
    try:
        target.mkdir()
    except PermissionError:
        yield target
    else:  # root: permissions do not stop it; sysfs refuses everyone
        target.rmdir()
        yield Path("/sys/groundstation-test-no-such-dir/flightlogs")
    parent.chmod(0o700)


def test_user_directories_in_xdg_order(tmp_path: Path) -> None:
    env = {"XDG_STATE_HOME": "/srv/state", "HOME": "/home/pilot"}
    assert fallback_log_dirs(env, tmp_path) == [
        Path("/srv/state/groundstation/flightlogs"), tmp_path / "flightlogs"]
    # a relative XDG_STATE_HOME is invalid (XDG Base Directory spec): the default is used
    env = {"XDG_STATE_HOME": "state", "HOME": "/home/pilot"}
    assert fallback_log_dirs(env, tmp_path)[0] == Path(
        "/home/pilot/.local/state/groundstation/flightlogs")
    assert fallback_log_dirs({}, tmp_path) == [tmp_path / "flightlogs"]


def test_an_unwritable_directory_falls_back_and_says_so_once(unwritable: Path,
                                                             tmp_path: Path) -> None:
    user = tmp_path / "state" / "groundstation" / "flightlogs"
    with capture_logs() as logs:
        recorder = create_flight_log(unwritable, "serial: {}\n", {"supervisor_states": ["A"]},
                                     fallbacks=[user, tmp_path / "flightlogs"])
    with recorder:
        directory = recorder.directory
    assert directory.parent == user
    warnings = [e for e in logs if e["log_level"] == "warning"]
    assert len(warnings) == 1
    line = warnings[0]["event"]
    assert "\n" not in line and str(unwritable) in line and str(user) in line
    meta = json.loads((directory / "meta.json").read_text(encoding="utf-8"))
    assert meta["flight_log_dir"]["configured"] == str(unwritable)
    assert meta["flight_log_dir"]["used"] == str(user)
    assert meta["supervisor_states"] == ["A"]
    rows, _, config_text = read_flight(directory)
    assert len(rows) == 0 and config_text == "serial: {}\n"


def test_a_writable_directory_is_used_without_a_word(tmp_path: Path) -> None:
    with capture_logs() as logs:
        recorder = create_flight_log(tmp_path / "logs", "{}\n",
                                     fallbacks=[tmp_path / "elsewhere"])
    with recorder:
        assert recorder.directory.parent == tmp_path / "logs"
    assert not [e for e in logs if e["log_level"] == "warning"]
    assert "flight_log_dir" not in json.loads(
        (recorder.directory / "meta.json").read_text(encoding="utf-8"))


def test_no_directory_at_all_is_an_error_naming_each(unwritable: Path, tmp_path: Path) -> None:
    also = Path("/sys/groundstation-test-no-such-dir/other")
    with pytest.raises(RecorderError) as info:
        create_flight_log(unwritable, "{}\n", fallbacks=[also, unwritable])
    message = str(info.value)
    assert str(unwritable) in message and str(also) in message
    assert message.count(str(unwritable)) == 1  # tried once, not twice


def test_the_fallback_log_records_rows(unwritable: Path, tmp_path: Path) -> None:
    """The recorder in the fallback directory is a whole flight log (rows read back)."""
    from groundstation.asctec.messages import CommandMsg
    from groundstation.types import ImuSample

    with create_flight_log(unwritable, "{}\n", fallbacks=[tmp_path / "user"]) as rec:
        for k in range(5):
            imu = ImuSample(t=0.01 * k, gyro=np.zeros(3), acc=np.array([0.0, 0.0, -9.82]))
            rec.append(t=0.01 * k, imu=imu, gyro_counts=(2048, 2048, 2048),
                       acc_counts=(2048, 2048, 1163), pose=None, estimate=None,
                       reference=None, command=CommandMsg.release(), controller=None,
                       sent=False, state=0, compute_time=0.0, jitter=0.0, latency=0.0)
        directory = rec.directory
    rows, _, _ = read_flight(directory)
    assert len(rows) == 5 and directory.parent == tmp_path / "user"
    assert os.access(directory / "flight.npy", os.R_OK)
