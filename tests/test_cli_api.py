"""`gs keys`, and the run-time API commands' errors without a daemon.

Flights driven through these commands are in tests/test_api_flight.py.
"""

from __future__ import annotations

import stat
import threading
import time
from pathlib import Path

import pytest
from typer.testing import CliRunner

from groundstation.cli import app
from groundstation.telemetry.curve import load_client_keys, load_server_keys
from groundstation.telemetry.requests import RequestServer, send_request

RUNNER = CliRunner()


def test_gs_keys_makes_pairs_the_daemon_and_a_client_authenticate_with(tmp_path: Path) -> None:
    keys = tmp_path / "keys"
    for name in ("server", "alice"):
        result = RUNNER.invoke(app, ["keys", str(keys), "--name", name])
        assert result.exit_code == 0, result.output
    secret = keys / "server.key_secret"
    assert stat.S_IMODE(secret.stat().st_mode) == 0o600
    clients = tmp_path / "clients"
    clients.mkdir()
    (clients / "alice.key").write_bytes((keys / "alice.key").read_bytes())
    # the daemon's side and the client's side of a real CURVE handshake
    with RequestServer("tcp://127.0.0.1:*", curve=load_server_keys(secret, clients)) as server:
        assert server.endpoint is not None
        curve = load_client_keys(keys / "alice.key_secret", keys / "server.key")
        done = threading.Event()
        serving = threading.Thread(target=server.serve, args=(lambda r: {"ok": True}, done))
        serving.start()
        try:
            assert send_request(server.endpoint, {"request": "status"}, 5.0,
                                curve=curve) == {"ok": True}
        finally:
            done.set()
            serving.join(5.0)


def test_gs_keys_never_overwrites_a_key(tmp_path: Path) -> None:
    assert RUNNER.invoke(app, ["keys", str(tmp_path), "--name", "server"]).exit_code == 0
    before = (tmp_path / "server.key_secret").read_bytes()
    again = RUNNER.invoke(app, ["keys", str(tmp_path), "--name", "server"])
    assert again.exit_code == 2 and "never overwritten" in again.output
    assert (tmp_path / "server.key_secret").read_bytes() == before
    bad = RUNNER.invoke(app, ["keys", str(tmp_path), "--name", "../elsewhere"])
    assert bad.exit_code == 2 and "plain file name" in bad.output


@pytest.mark.parametrize("args", [
    ["goto", "0.5", "0", "-1"],  # a negative coordinate is an argument, not an option
    ["status"], ["hold"], ["land"],
])
def test_api_commands_say_when_no_daemon_answers(args: list[str]) -> None:
    """Within the timeout asked for, motions too (they wait longer for a plan only once a
    daemon has answered)."""
    began = time.monotonic()
    result = RUNNER.invoke(app, [*args, "--endpoint", "tcp://127.0.0.1:9", "--timeout", "0.3"])
    assert result.exit_code == 1, result.output
    assert "no reply from tcp://127.0.0.1:9" in result.output
    assert time.monotonic() - began < 5.0  # 0.3 s asked; the motion's plan wait is 20 s


def test_api_commands_refuse_bad_usage() -> None:
    assert RUNNER.invoke(app, ["goto", "0.5", "0"]).exit_code == 2  # z is missing
    bad = RUNNER.invoke(app, ["status", "--timeout", "-1"])
    assert bad.exit_code == 2 and "positive number of seconds" in bad.output


@pytest.mark.parametrize(("args", "words"), [
    (["goto", "0", "0", "-1", "--yaw", "1e15"], "--yaw 1e+15: a heading within one turn"),
    (["goto", "0", "0", "-1", "--yaw", "nan"], "--yaw nan: must be a finite number"),
    (["goto", "inf", "0", "-1"], "X inf: must be a finite number"),
    (["goto", "0", "0", "-1", "--duration", "0"], "--duration 0: a positive number"),
])
def test_goto_refuses_numbers_no_daemon_would_take_as_usage_errors(args: list[str],
                                                                   words: str) -> None:
    """Checked before anything is sent (no daemon runs at the endpoint: it is never asked)."""
    result = RUNNER.invoke(app, [*args, "--endpoint", "tcp://127.0.0.1:9", "--timeout", "0.3"])
    assert result.exit_code == 2, result.output
    assert words in result.output and "no reply" not in result.output
