"""sd_notify against a real AF_UNIX datagram socket (path and abstract namespace), and the
deployment files (systemd unit, Dockerfile) checked against sd_notify(3), systemd.service(5)
and the shipped lab configuration."""

from __future__ import annotations

import json
import os
import re
import shutil
import socket
import subprocess
import uuid
from collections.abc import Iterator
from pathlib import Path

import pytest

from groundstation.app.sdnotify import SdNotifier
from groundstation.config import load_config


@pytest.fixture
def listener(tmp_path: Path) -> Iterator[tuple[socket.socket, str]]:
    """A bound datagram socket in tmp_path playing systemd: (socket, $NOTIFY_SOCKET value)."""
    path = tmp_path / "notify.sock"
    with socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM) as sock:
        sock.bind(str(path))
        sock.settimeout(2.0)
        yield sock, str(path)


def received(sock: socket.socket) -> str:
    return sock.recv(4096).decode()


def test_messages_follow_sd_notify(listener: tuple[socket.socket, str]) -> None:
    sock, address = listener
    notifier = SdNotifier.from_env({"NOTIFY_SOCKET": address})
    assert notifier.enabled
    assert notifier.ready()
    assert received(sock) == "READY=1"
    assert notifier.watchdog()
    assert received(sock) == "WATCHDOG=1"
    assert notifier.status("tracking square\nlap 2")  # a newline would start a new key
    assert received(sock) == "STATUS=tracking square lap 2"
    assert notifier.ready("preflight passed")
    assert received(sock) == "READY=1\nSTATUS=preflight passed"
    assert notifier.stopping("landing")
    assert received(sock) == "STOPPING=1\nSTATUS=landing"
    assert notifier.sent == 5 and notifier.errors == 0


def test_abstract_namespace_address() -> None:
    name = f"groundstation-test-{uuid.uuid4().hex}"
    with socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM) as sock:
        sock.bind("\0" + name)  # what "@name" in $NOTIFY_SOCKET denotes
        sock.settimeout(2.0)
        assert SdNotifier.from_env({"NOTIFY_SOCKET": "@" + name}).watchdog()
        assert received(sock) == "WATCHDOG=1"


def test_no_op_outside_systemd() -> None:
    for env in ({}, {"NOTIFY_SOCKET": ""}, {"NOTIFY_SOCKET": "relative/path"}):
        notifier = SdNotifier.from_env(env)
        assert not notifier.enabled
        assert not notifier.ready() and not notifier.watchdog()
        assert notifier.errors == 0 and notifier.watchdog_interval() is None


def test_send_failure_is_counted_not_raised(tmp_path: Path) -> None:
    notifier = SdNotifier(str(tmp_path / "nobody-listens.sock"))
    assert not notifier.watchdog()
    assert notifier.errors == 1 and notifier.sent == 0


def test_watchdog_interval_from_environment() -> None:
    pid = 4242
    env = {"NOTIFY_SOCKET": "/run/x", "WATCHDOG_USEC": "2000000"}
    assert SdNotifier.from_env(env, pid=pid).watchdog_interval() == 2.0  # 2e6 us
    assert SdNotifier.from_env({**env, "WATCHDOG_PID": "4242"}, pid=pid).watchdog_interval() == 2.0
    # inherited from a parent: the watchdog is not ours (sd_watchdog_enabled(3))
    assert SdNotifier.from_env({**env, "WATCHDOG_PID": "1"}, pid=pid).watchdog_interval() is None
    for bad in ("", "0", "-5", "two"):
        assert SdNotifier.from_env({**env, "WATCHDOG_USEC": bad}).watchdog_interval() is None
    # the real process id is the default
    own = {**env, "WATCHDOG_PID": str(os.getpid())}
    assert SdNotifier.from_env(own).watchdog_interval() == 2.0


# ----------------------------------------------------------------------------- deployment
def unit_settings(path: Path) -> dict[str, dict[str, list[str]]]:
    """systemd unit file -> {section: {key: [values, in order]}} (keys may repeat)."""
    sections: dict[str, dict[str, list[str]]] = {}
    current: dict[str, list[str]] = {}
    for raw in path.read_text().splitlines():
        line = raw.strip()
        if not line or line[0] in "#;":
            continue
        if line.startswith("[") and line.endswith("]"):
            current = sections.setdefault(line[1:-1], {})
            continue
        key, sep, value = line.partition("=")
        assert sep, f"not a key=value line: {raw!r}"
        current.setdefault(key.strip(), []).append(value.strip())
    return sections


def test_unit_file_settings(repo: Path) -> None:
    service = unit_settings(repo / "config" / "groundstation.service")["Service"]
    one = {key: values[-1] for key, values in service.items()}
    assert one["Type"] == "notify" and one["NotifyAccess"] == "main"
    assert one["Restart"] == "no"  # never re-arm a vehicle in the air
    assert one["ExecStart"].split() == [
        "/opt/groundstation/.venv/bin/gs", "fly", "--config", "/etc/groundstation/lab.yaml"]
    assert "dialout" in one["SupplementaryGroups"].split()
    assert one["ProtectSystem"] == "strict" and one.get("PrivateDevices", "no") == "no"
    lab = load_config(repo / "config" / "lab.yaml")
    # flight logs land in the StateDirectory, the only writable path under ProtectSystem=strict
    state_dir = Path("/var/lib") / one["StateDirectory"]
    assert state_dir in lab.logging.flight_log_dir.parents
    # the watchdog must tolerate a ping every second (half the interval, sd_watchdog_enabled(3))
    assert float(one["WatchdogSec"]) == 2.0
    # stopping must leave time to land from the ceiling of the volume at the landing speed
    safety = lab.safety
    land_s = (safety.volume_z[1] - safety.volume_z[0]) / safety.land_speed_m_s
    assert float(one["TimeoutStopSec"]) > 2 * land_s
    assert float(one["TimeoutStartSec"]) > safety.preflight_timeout_s + lab.estimator.settle_time_s


@pytest.mark.skipif(shutil.which("systemd-analyze") is None, reason="systemd-analyze missing")
def test_unit_file_passes_systemd_analyze_verify(repo: Path, tmp_path: Path) -> None:
    text = (repo / "config" / "groundstation.service").read_text()
    # verify insists the program exists: point ExecStart at one that does
    unit = tmp_path / "groundstation.service"
    unit.write_text(text.replace("/opt/groundstation/.venv/bin/gs", shutil.which("true") or ""))
    result = subprocess.run(["systemd-analyze", "verify", str(unit)], capture_output=True,
                            text=True, timeout=60, check=False)
    assert result.returncode == 0, result.stderr
    assert result.stderr.strip() == "", result.stderr  # unknown keys are only warned about


def dockerfile_instructions(path: Path) -> list[tuple[str, str]]:
    """(INSTRUCTION, arguments) per instruction, continuation lines joined."""
    text = re.sub(r"\\\n", " ", path.read_text())
    out = []
    for line in text.splitlines():
        line = line.strip()
        if line and not line.startswith("#"):
            word, _, rest = line.partition(" ")
            out.append((word.upper(), rest.strip()))
    return out


def test_dockerfile(repo: Path) -> None:
    instructions = dockerfile_instructions(repo / "Dockerfile")
    words = [word for word, _ in instructions]
    args = {word: rest for word, rest in instructions}  # the last of each
    assert all(rest.startswith("python:3.11-slim") for w, rest in instructions if w == "FROM")
    assert args["USER"] not in ("root", "0") and words.index("USER") < words.index("ENTRYPOINT")
    assert "dialout" in next(rest for w, rest in instructions if w == "RUN" and "useradd" in rest)
    assert json.loads(args["ENTRYPOINT"]) == ["gs"]
    assert json.loads(args["CMD"]) == ["fly", "--config", "/etc/groundstation/lab.yaml"]
    assert not any("[dev]" in rest for w, rest in instructions if w == "RUN")
    lab = load_config(repo / "config" / "lab.yaml")
    exposed = args["EXPOSE"].split()
    assert f"{lab.vicon.port}/udp" in exposed
    assert f"{lab.telemetry.endpoint.rsplit(':', 1)[1]}/tcp" in exposed
    # every COPY source from the build context exists and is allowed by .dockerignore
    allowed = {line.lstrip("!").rstrip("/") for line in
               (repo / ".dockerignore").read_text().splitlines() if line.startswith("!")}
    for word, rest in instructions:
        if word == "COPY" and not rest.startswith("--from"):
            for source in rest.split()[:-1]:
                assert (repo / source).exists(), source
                assert source in allowed, source
