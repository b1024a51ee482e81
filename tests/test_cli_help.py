"""Every `gs` command's `--help`, rendered at 80 columns, keeps what its source says.

Rich markup used to eat bracketed text (`[hinf]`, `North [m]`, `zeros [counts]`), reST's
double backquotes showed literally, and `gs fly --help` cut its trajectory list at 80
columns. Here each command's help is rendered as a user's terminal gets it (80 columns)
and compared with the source text: the docstring and every option's help must survive
word for word (only re-wrapped), every bracketed word with them, every choice of an option
must be listed, and no line may pass 80 columns.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any, get_args

import pytest
import typer
from typer.testing import CliRunner

from groundstation.cli import app

ROOT = Path(__file__).resolve().parents[1]
COLUMNS = 80


def _commands() -> Iterator[tuple[list[str], Any]]:
    """(command words, click command) for every leaf command of `gs`."""
    def walk(command: Any, words: list[str]) -> Iterator[tuple[list[str], Any]]:
        subcommands = getattr(command, "commands", None)
        if subcommands is None:
            yield words, command
            return
        for name, sub in subcommands.items():
            yield from walk(sub, [*words, name])

    yield from walk(typer.main.get_command(app), [])


COMMANDS = list(_commands())


def _flat(text: str) -> str:
    """``text`` without its wrapping: a word broken after a hyphen joined again, every run
    of whitespace one space (the renderer re-wraps; it must not drop or change a word)."""
    return " ".join(re.sub(r"-\n\s+", "-", text).split())


def _help(words: list[str]) -> str:
    result = CliRunner().invoke(app, [*words, "--help"], env={"COLUMNS": str(COLUMNS)})
    assert result.exit_code == 0, (words, result.output)
    return result.output


def _source_texts(command: Any) -> list[str]:
    """The help texts as written in the source: the docstring's paragraphs (as typer
    takes them: up to a form feed, without click's no-rewrap marker) and every shown
    parameter's help."""
    doc = (command.callback.__doc__ or "").split("\f")[0]
    paragraphs = [p.replace("\b", "") for p in re.split(r"\n\s*\n", doc)]
    helps = [p.help for p in command.params if getattr(p, "help", None) and not p.hidden]
    return [t for t in (*paragraphs, *helps) if t.strip()]


@pytest.mark.parametrize(("words", "command"), COMMANDS,
                         ids=[" ".join(w) for w, _ in COMMANDS])
def test_help_at_80_columns_keeps_every_word_of_the_source(words: list[str],
                                                           command: Any) -> None:
    shown = _help(words)
    flat = _flat(shown)
    for text in _source_texts(command):
        assert _flat(text) in flat, (words, text)
        for bracketed in re.findall(r"\[[^\[\]]+\]", text):
            assert bracketed in flat, (words, bracketed)
    assert "``" not in shown, words  # reST markup shows literally in a terminal
    assert "╭" not in shown and "│" not in shown, words  # plain text, no rich panels
    wide = [line for line in shown.splitlines() if len(line) > COLUMNS]
    assert not wide, (words, wide)


@pytest.mark.parametrize(("words", "command"), COMMANDS,
                         ids=[" ".join(w) for w, _ in COMMANDS])
def test_help_lists_every_choice(words: list[str], command: Any) -> None:
    flat = _flat(_help(words))
    for param in command.params:
        descriptor = getattr(param, "type_descriptor", None)  # typer's: Literal choices
        for choice in (descriptor.choices or ()) if descriptor is not None else ():
            assert str(choice) in flat, (words, param.name, choice)


def _words_listed(words: list[str], names: tuple[str, ...] | list[str]) -> None:
    flat = _flat(_help(words))
    missing = [n for n in names if n not in flat]
    assert not missing, (words, missing)


def test_fly_lists_every_trajectory_including_none_and_waypoints() -> None:
    from groundstation.control.trajectories import TRAJECTORY_NAMES

    assert {"none", "waypoints"} <= {*TRAJECTORY_NAMES, "none"}
    _words_listed(["fly"], [*TRAJECTORY_NAMES, "none"])
    _words_listed(["trajectory"], TRAJECTORY_NAMES)


def test_the_lists_the_help_carries_are_the_packages() -> None:
    """The CLI's lists (kept apart so `gs` starts without importing the evaluation suite
    or the identification) are the ones the package uses."""
    from groundstation.cli.options import Controller, Dialect, ScaleAxis
    from groundstation.config import ControllerConfig, SerialConfig
    from groundstation.identification import SCALE_AXES
    from sim_device.cli import SCENARIO_NAMES
    from sim_device.evaluation.scenarios import SUITE

    assert get_args(Controller) == get_args(ControllerConfig.model_fields["type"].annotation)
    assert get_args(Dialect) == get_args(SerialConfig.model_fields["protocol"].annotation)
    assert get_args(ScaleAxis) == tuple(SCALE_AXES)
    assert tuple(s.name for s in SUITE) == SCENARIO_NAMES


def test_every_eval_scenario_channel_and_axis_is_listed() -> None:
    from groundstation.identification import SCALE_AXES
    from sim_device.evaluation.scenarios import SUITE

    _words_listed(["eval"], [s.name for s in SUITE])
    _words_listed(["channels"], ["pitch", "roll", "yaw", "thrust"])
    _words_listed(["identify", "scales"], list(SCALE_AXES))


@pytest.mark.slow
def test_the_help_a_user_runs_keeps_the_words_rich_markup_ate() -> None:
    """The console script in a terminal 80 columns wide, as the issue's findings were made:
    `[hinf]`, the units of `gs goto`'s arguments, `[counts]`."""
    gs = [sys.executable, "-c", "import sys; from groundstation.cli import main; "
          "sys.argv[0] = 'gs'; main()"]
    env = {**os.environ, "COLUMNS": str(COLUMNS), "TERM": "xterm-256color"}
    expected = {("synth", "hinf"): ["pip install 'groundstation[hinf]'"],
                ("goto",): ["North [m].", "East [m].", "Down [m]", "[deg from north]"],
                ("calibrate", "imu"): ["zeros [counts] and noise"]}
    for words, texts in expected.items():
        run = subprocess.run([*gs, *words, "--help"], capture_output=True, text=True,
                             timeout=120, cwd=ROOT, env=env)
        assert run.returncode == 0, run.stderr
        for text in texts:
            assert text in _flat(run.stdout), (words, text, run.stdout)
