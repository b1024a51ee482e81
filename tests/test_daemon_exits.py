"""Every way out of `gs fly` ends the flight as documented: a terminal that went away (a
closed window, a dropped ssh session) and a disk that filled in the air.

Real-time flights: `gs fly` in a process of its own against `gs sim-device` in another
(a pty and UDP), so the vehicle sees the ground station as a real X-3D would and its
ground truth (`sim.truth_file`) and wire record say what the vehicle did, independent
of what the ground station reports about itself. Run them under the shared lock
(`flock /tmp/realtime.lock`).
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import os
import re
import select
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from lab_helpers import REPO, realtime_sim_config

from groundstation.app.daemon import FlightDaemon
from groundstation.app.fly import EXIT_CODES, summary_lines
from groundstation.app.recorder import LogLoss, read_flight
from groundstation.config import apply_overrides, dump_config, validate_config
from groundstation.endpoints import free_udp_port
from groundstation.flight.assembly import assemble
from groundstation.flight.supervisor import Outcome, State
from sim_device.realtime import SimDeviceProcess

GS = str(Path(sys.executable).parent / "gs")

IN_A_SESSION_OF_ITS_OWN = """
import fcntl, os, sys, termios
os.setsid()  # a new session, and the pty on stdin its controlling terminal
fcntl.ioctl(0, termios.TIOCSCTTY, 0)
os.execv(sys.argv[1], sys.argv[1:])
"""
"""Run argv[1:] as the leader of a new session whose controlling terminal is stdin (a
login shell on a terminal is such a leader; the kernel sends it SIGHUP on hangup)."""


@contextlib.contextmanager
def vehicle(tmp_path: Path) -> Iterator[tuple[SimDeviceProcess, Path]]:
    """The virtual lab in a process of its own, and a `gs fly` configuration file for it
    (a hover; the flight log under ``tmp_path/logs``)."""
    cfg = apply_overrides(realtime_sim_config(), {
        "trajectory.name": "hover", "vicon.port": free_udp_port(),
        "telemetry.endpoint": "tcp://127.0.0.1:*", "telemetry.control_endpoint": None,
        "logging.flight_log_dir": str(tmp_path / "logs"),
        "sim.truth_file": str(tmp_path / "truth.npz")})
    lab_file = tmp_path / "lab.yaml"
    lab_file.write_text(dump_config(cfg), encoding="utf-8")
    with SimDeviceProcess(lab_file, tmp_path / "truth.npz",
                          stderr=tmp_path / "lab.stderr") as lab:
        fly_file = tmp_path / "fly.yaml"
        fly_file.write_text(dump_config(apply_overrides(cfg, {"serial.port": lab.pty_path})),
                            encoding="utf-8")
        yield lab, fly_file


def read_pty_until(master: int, marker: str, timeout: float) -> str:
    """What the terminal shows up to the first line that starts with ``marker`` (the
    progress lines start with the supervisor state)."""
    text = ""
    deadline = time.monotonic() + timeout
    while not any(line.lstrip("\r").startswith(marker) for line in text.split("\n")):
        left = deadline - time.monotonic()
        assert left > 0, f"no {marker!r} line in:\n{text}"
        if select.select([master], [], [], min(left, 0.5))[0]:
            try:
                text += os.read(master, 65536).decode("utf-8", "replace")
            except OSError:  # EIO: the child closed its side
                raise AssertionError(f"the terminal closed before {marker!r}:\n{text}") from None
    return text


def the_flight(log_root: Path) -> Path:
    flights = [p for p in log_root.iterdir() if p.is_dir()]
    assert len(flights) == 1, flights
    return flights[0]


class Truth:
    """The lab's ground truth: height above the floor [m], the ctrl mask it applied and
    whether it rested on the floor, on the monotonic clock [s]."""

    def __init__(self, path: Path) -> None:
        with np.load(path) as npz:
            self.t = float(npz["start_monotonic"]) + np.asarray(npz["t"], dtype=float)
            self.height = -np.asarray(npz["position"], dtype=float)[:, 2]
            self.mask = np.asarray(npz["ctrl_mask"], dtype=int)
            self.on_ground = np.asarray(npz["on_ground"], dtype=bool)

    def at(self, t: float) -> int:
        return int(np.searchsorted(self.t, t))

    def first_handback_after(self, t: float) -> int:
        """Index of the first row after ``t`` where the pilot had every channel."""
        k = self.at(t)
        return k + int(np.argmax(self.mask[k:] == 0))


@pytest.mark.realtime
@pytest.mark.slow
def test_a_closed_terminal_lands_hands_back_and_logs_the_flight(tmp_path: Path) -> None:
    """A hostile tester's finding: SIGHUP in the air killed the daemon at once (no
    landing, no summary, no final flight-log row, no outcome, no final mask-0 COMMAND;
    the vehicle's watchdog handed back 100 ms later, in the air).

    `gs fly` runs as a session leader on a pty, as under a login shell; once it tracks,
    the terminal's master side is closed: the kernel sends SIGHUP and every later write
    to the terminal (progress lines, log lines, the summary) fails with EIO. A second
    SIGHUP a second later, as a shell forwarding the hangup sends, must not hand back."""
    with vehicle(tmp_path) as (lab, fly_file):
        master, slave = os.openpty()
        child = subprocess.Popen(
            [sys.executable, "-c", IN_A_SESSION_OF_ITS_OWN, GS, "fly", "--config",
             str(fly_file), "--duration", "60"],
            stdin=slave, stdout=slave, stderr=slave)
        os.close(slave)
        try:
            shown = read_pty_until(master, "TRACK", 90.0)
            t_hangup = time.monotonic()
            os.close(master)
            master = -1
            time.sleep(1.0)
            os.kill(child.pid, signal.SIGHUP)  # the same hangup, once more
            code = child.wait(90.0)
        finally:
            if master >= 0:
                os.close(master)
            if child.poll() is None:
                child.kill()
                child.wait()
    assert code == 4, f"exit code {code}; the terminal showed:\n{shown}"
    # what the vehicle did (its own records)
    truth = Truth(tmp_path / "truth.npz")
    assert truth.height[truth.at(t_hangup)] > 0.5  # tracking the 1 m hover when it hung up
    k = truth.first_handback_after(t_hangup)
    assert truth.mask[k] == 0 and truth.on_ground[k], (
        f"handed back at {truth.height[k]:.2f} m (on the ground: {truth.on_ground[k]})")
    assert truth.height[-1] < 0.10
    assert lab.wire is not None and lab.wire.command_mask[-1] == 0  # the last COMMAND
    # what the ground station recorded
    flight = the_flight(tmp_path / "logs")
    meta = json.loads((flight / "meta.json").read_text(encoding="utf-8"))
    assert meta["outcome"]["exit_code"] == 4 and meta["outcome"]["outcome"] == "STOPPED"
    assert meta["outcome"]["final_state"] == "DONE" and meta["outcome"]["log"]["complete"]
    rows, _, _ = read_flight(flight)
    states = rows["state"]
    assert states[-1] == int(State.DONE) and rows["cmd_mask"][-1] == 0
    assert int(State.LAND) in states and int(State.HANDBACK) not in states
    assert not list(flight.glob("*.tmp")) and not list(flight.glob("*.reserve"))


def private_mount_namespace() -> list[str]:
    """The command prefix that runs a command in a mount namespace of its own (where it
    may mount a tmpfs), or skip the test with the reason."""
    tried = []
    # as root, no user namespace: the flight keeps its real-time priority
    prefixes = [["unshare", "-m"], ["unshare", "-rm"]] if os.geteuid() == 0 else \
        [["unshare", "-rm"]]
    for prefix in prefixes:
        if shutil.which(prefix[0]) is None:
            pytest.skip("needs util-linux unshare for a private tmpfs")
        probe = subprocess.run([*prefix, "sh", "-c", "mount -t tmpfs -o size=64k tmpfs /mnt"],
                               capture_output=True, text=True, timeout=30)
        if probe.returncode == 0:
            return prefix
        tried.append(f"{' '.join(prefix)}: {probe.stderr.strip()}")
    pytest.skip("cannot mount a tmpfs in a private mount namespace (" + "; ".join(tried) + ")")


ON_A_TINY_DISK = """
set -u
size=$1 disk=$2 copy=$3
shift 3
mount -t tmpfs -o "size=$size" tmpfs "$disk" || exit 97
"$@" --log-dir "$disk/logs"
code=$?
cp -a "$disk/logs" "$copy"
exit $code
"""
"""Mount a tmpfs of ``size`` on ``disk`` (in this mount namespace only), run the command
with its flight log there, and copy the log out before the namespace (and the tmpfs)
goes."""


@pytest.mark.realtime
@pytest.mark.slow
def test_a_disk_that_fills_in_the_air_is_an_incomplete_log_not_a_success(
        tmp_path: Path) -> None:
    """A hostile tester's finding: with the log on a 2 MB tmpfs, 570 of 3,414 rows were
    lost, and the flight printed `flight ended in DONE ... exit code 0`, meta.json had no
    outcome, an empty meta.json.tmp was left, the log ended in TRACK.

    640 kB: after the reserves (meta.json 64 kB, 256 rows for the last flush) about 530
    rows fit, 5.3 s of a flight of about 7.3 (a 1 s hover; a row per DATA sample, 100 a
    second however loaded the machine): the disk fills in the air, take-off from about
    1.5 s, landing until about 6.5 s."""
    prefix = private_mount_namespace()
    disk, copy = tmp_path / "disk", tmp_path / "copy"
    disk.mkdir()
    with vehicle(tmp_path) as (lab, fly_file):
        child = subprocess.run(
            [*prefix, "sh", "-c", ON_A_TINY_DISK, "sh", "640k", str(disk), str(copy),
             GS, "fly", "--config", str(fly_file), "--duration", "1"],
            capture_output=True, text=True, timeout=110)
    out = child.stdout
    assert child.returncode == 5, f"exit {child.returncode}\n{out}\n{child.stderr[-3000:]}"
    first = next(line for line in out.splitlines() if line.startswith("flight ended in"))
    found = re.search(r"flight log incomplete: (\d+) of (\d+) rows lost \(No space left on "
                      r"device\), exit code 5\)$", first)
    assert found is not None and first.startswith("flight ended in DONE:"), first
    lost, total = int(found[1]), int(found[2])
    # the vehicle landed and was handed back on the ground (its own truth)
    truth = Truth(tmp_path / "truth.npz")
    k = truth.first_handback_after(truth.t[int(np.argmax(truth.mask != 0))])
    assert truth.on_ground[k] and truth.height[-1] < 0.10
    assert lab.wire is not None and lab.wire.command_mask[-1] == 0
    # the log: meta.json whole and saying so, nothing left behind
    flight = the_flight(copy)
    assert sorted(p.name for p in flight.iterdir()) == ["config.yaml", "flight.npy",
                                                        "meta.json"]
    meta = json.loads((flight / "meta.json").read_text(encoding="utf-8"))
    outcome = meta["outcome"]
    assert outcome["exit_code"] == 5 and outcome["outcome"] == "COMPLETED"
    assert outcome["log"] == {"complete": False, "rows": total - lost, "rows_lost": lost,
                              "reasons": {"No space left on device": lost}}
    # the counters against the rows in the file (numpy's own reader)
    flat = np.load(flight / "flight.npy")
    assert len(flat) == meta["rows"] == total - lost and meta["rows_dropped"] == lost
    # the lost rows are gaps in the DATA sample counter (one row per DATA sample; a tick
    # without one, on a loaded machine, repeats the counter and is a row too), all in the
    # air; the rows after the last are the flight's end, from the last flush's reserve
    step = np.diff(flat["imu_counter"].astype(np.int64)) % 65536
    gaps = np.flatnonzero(step > 1)
    missing = int(np.sum(step[gaps] - 1))
    print(f"{first}\n  DATA samples missing in the log: {missing}, in {len(gaps)} gaps")
    assert abs(missing - lost) <= max(5, lost // 50), (missing, lost)
    states = flat["state"]
    assert set(states[gaps]) <= {int(State.TAKEOFF), int(State.TRACK), int(State.LAND)}, \
        states[gaps]
    assert states[-1] == int(State.DONE) and flat["cmd_mask"][-1] == 0  # the final row


@pytest.mark.slow
@pytest.mark.parametrize(("outcome", "complete", "code"), [
    (Outcome.COMPLETED, True, 0), (Outcome.COMPLETED, False, 5),
    (Outcome.STOPPED, True, 4), (Outcome.STOPPED, False, 5),
    (Outcome.FAILSAFE, True, 1), (Outcome.FAILSAFE, False, 1)])
def test_an_incomplete_log_exits_5_unless_a_failsafe_acted(
        outcome: Outcome, complete: bool, code: int) -> None:
    """The precedence README and `gs fly --help` document: 1 > 5 > 4 > 0. The summary's
    first line says the log is incomplete whatever the code."""
    loss = LogLoss() if complete else LogLoss(
        rows=2844, lost=570, reasons={"No space left on device": 570})
    summary = dataclasses.replace(FlightDaemon(assemble(validate_config({})))._summary(),
                                  outcome=outcome, log=loss, reason="landed")
    assert summary.exit_code == code
    first = summary_lines(summary)[0]
    assert first.endswith(f"exit code {code})")
    assert ("flight log incomplete: 570 of 3414 rows lost (No space left on device)"
            in first) == (not complete)


def test_every_exit_code_is_in_the_readme() -> None:
    row = next(line for line in (REPO / "README.md").read_text(encoding="utf-8").splitlines()
               if line.startswith("| `gs fly --config FILE`"))
    for code, meaning in EXIT_CODES.items():
        first_word = meaning.split()[0].rstrip(":,")
        assert f"**{code}** {first_word}" in row, (code, first_word)
