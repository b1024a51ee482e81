"""One name per meaning across the `gs` command set, read from the commands themselves:
`--config/-c` wherever a configuration is read, `--control` for the daemon's control
socket and `--telemetry` for its publisher, `--duration` for how long the vehicle's motion
lasts and `--seconds` for how long a command runs, `--out` always a file and `--out-dir`
always a directory, one `--timeout` default, `--wait-timeout` wherever `--wait` is; and the
former spellings still work as hidden aliases (a user's scripts may use them)."""

from __future__ import annotations

import threading
from collections.abc import Iterator
from typing import Any

import pytest
import typer
from typer.testing import CliRunner

from groundstation.cli import app
from groundstation.cli.options import REPLY_TIMEOUT_S, WAIT_TIMEOUT_S
from groundstation.telemetry.requests import RequestServer

runner = CliRunner()


def _commands() -> Iterator[tuple[str, Any]]:
    def walk(command: Any, words: list[str]) -> Iterator[tuple[str, Any]]:
        subcommands = getattr(command, "commands", None)
        if subcommands is None:
            yield " ".join(words), command
            return
        for name, sub in subcommands.items():
            yield from walk(sub, [*words, name])

    yield from walk(typer.main.get_command(app), [])


COMMANDS = dict(_commands())


def _shown(command: Any, option: str) -> Any | None:
    """The visible parameter spelled ``option`` on ``command``, or None."""
    return next((p for p in command.params if option in getattr(p, "opts", ())
                 and not getattr(p, "hidden", False)), None)


def _with(option: str) -> dict[str, Any]:
    """Every command showing ``option``: name -> its parameter."""
    found = {name: _shown(c, option) for name, c in COMMANDS.items()}
    return {name: p for name, p in found.items() if p is not None}


def test_every_configuration_is_read_with_config_or_c() -> None:
    reading = {name: [p for p in c.params if p.name == "config"] for name, c in COMMANDS.items()}
    reading = {name: params[0] for name, params in reading.items() if params}
    assert {"fly", "check-config", "trajectory", "motors", "replay", "calibrate imu",
            "calibrate vicon", "synth hinf", "sim-device", "eval"} <= set(reading)
    for name, param in reading.items():
        assert {"--config", "-c"} <= set(param.opts), name


def test_endpoints_have_one_name_per_socket() -> None:
    assert not _with("--endpoint"), "--endpoint is a hidden former spelling only"
    control = _with("--control")
    assert set(control) == {"goto", "hold", "land", "status", "channels"}
    assert all("control_endpoint" in p.help for p in control.values())
    telemetry = _with("--telemetry")
    assert {"monitor", "foxglove", "land"} <= set(telemetry)
    assert all("telemetry.endpoint" in p.help for p in telemetry.values())


def test_durations_and_run_times_have_their_own_names() -> None:
    # the vehicle's motion: gs fly on its trajectory, gs goto's move
    assert set(_with("--duration")) == {"fly", "goto"}
    # how long a command runs or measures
    assert {"monitor", "foxglove", "sim-device", "calibrate imu", "calibrate vicon"} <= \
        set(_with("--seconds"))


def test_out_is_always_a_file_and_out_dir_always_a_directory() -> None:
    files = _with("--out")
    assert set(files) == {"export", "synth hinf"}
    for name, param in files.items():
        assert "file" in param.help.lower() and "director" not in param.help.lower(), name
    directories = _with("--out-dir")
    assert {"report", "eval", "calibrate imu", "calibrate vicon", "identify rates",
            "identify scales", "identify thrust", "identify inflow",
            "verify-model"} <= set(directories)
    for name, param in directories.items():
        assert "director" in param.help.lower(), name


def test_one_reply_timeout_and_a_wait_timeout_wherever_wait_is() -> None:
    timeouts = _with("--timeout")
    assert {"goto", "hold", "land", "status", "channels"} <= set(timeouts)
    assert {p.default for p in timeouts.values()} == {REPLY_TIMEOUT_S}
    waiting = {name for name in COMMANDS if _shown(COMMANDS[name], "--wait") is not None}
    assert waiting == {"goto", "land", "fleet land"}
    assert {name: p.default for name, p in _with("--wait-timeout").items()} == \
        {name: WAIT_TIMEOUT_S for name in waiting}


def test_the_former_spellings_still_work_and_may_not_contradict() -> None:
    dead = "tcp://127.0.0.1:9"  # nothing publishes there: the monitor receives nothing
    new = runner.invoke(app, ["monitor", "--telemetry", dead, "--seconds", "0.3"])
    old = runner.invoke(app, ["monitor", "--endpoint", dead, "--duration", "0.3"])
    assert new.exit_code == old.exit_code == 0, (new.output, old.output)
    assert new.output.splitlines()[-1] == old.output.splitlines()[-1] == \
        "waiting for telemetry (0 messages)"
    both = runner.invoke(app, ["monitor", "--telemetry", dead, "--endpoint",
                               "tcp://127.0.0.1:8", "--seconds", "0.1"])
    assert both.exit_code == 2 and "--telemetry and --endpoint" in both.output


@pytest.mark.parametrize("option", ["--control", "--endpoint"])
def test_control_commands_reach_the_daemon_by_either_spelling(option: str) -> None:
    seen: list[dict[str, object]] = []

    def handler(request: dict[str, object]) -> dict[str, object]:
        seen.append(request)
        return {"ok": True, "auto": ["thrust"], "state": "TRACK"}

    with RequestServer("tcp://127.0.0.1:*") as server:
        assert server.endpoint is not None
        stop = threading.Event()
        thread = threading.Thread(target=lambda: [server.poll(handler)
                                                  for _ in iter(lambda: stop.wait(0.001), True)],
                                  daemon=True)
        thread.start()
        try:
            result = runner.invoke(app, ["channels", "thrust", option, server.endpoint])
        finally:
            stop.set()
            thread.join(5.0)
    assert result.exit_code == 0, result.output
    assert seen == [{"request": "channels", "auto": ["thrust"]}]


def test_the_readmes_command_table_names_only_what_the_commands_take() -> None:
    """Each row of README's command table: its commands exist and every option its first
    cell names is one the command shows (so the table follows a rename)."""
    import re
    from pathlib import Path

    readme = (Path(__file__).resolve().parents[1] / "README.md").read_text(encoding="utf-8")
    table = readme.split("## Commands", 1)[1].split("\n\n", 2)[1]
    rows = [line.split(" | ")[0] for line in table.splitlines() if line.startswith("| `gs ")]
    assert len(rows) > 15
    checked = 0
    for cell in rows:
        for usage in re.findall(r"`gs ([^`]+)`", cell):
            words = usage.split()
            name = " ".join(w for w in words[:2] if re.fullmatch(r"[a-z-]+", w))
            command = COMMANDS.get(name) or COMMANDS.get(words[0])
            if command is None:  # `gs calibrate imu|vicon`: each alternative
                names = [f"{words[0]} {alt}" for alt in words[1].split("\\|")]
                assert all(n in COMMANDS for n in names), usage
                commands = [COMMANDS[n] for n in names]
            else:
                commands = [command]
            for option in re.findall(r"(--[a-z][a-z-]*)", usage):
                for each in commands:
                    assert _shown(each, option) is not None, (usage, option)
                    checked += 1
    assert checked > 30
