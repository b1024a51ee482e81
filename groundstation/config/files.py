"""Reading a configuration: the YAML file, validation with every problem named at its
line, overrides, the files a configuration names, and the configuration as YAML."""

from __future__ import annotations

import copy
import os
import re
from pathlib import Path
from typing import Any, NoReturn

import yaml
from pydantic import BaseModel, ValidationError
from yaml.reader import ReaderError

from groundstation.config.base import FieldValueError
from groundstation.config.schema import GroundStationConfig
from groundstation.errors import ConfigError

MAX_FILE_BYTES = 1 << 20
"""Largest configuration file read [bytes]; the shipped ones are a few KiB."""

MAX_YAML_VALUES = 100_000
"""Most values a file may expand to through YAML aliases (a "billion laughs" file would
otherwise take the validator and the error messages exponential time)."""

_YAML12_EXPONENT_FLOAT = re.compile(r"^[-+]?[0-9][0-9_]*(?:\.[0-9_]*)?[eE][-+]?[0-9]+$")


class _Loader(yaml.SafeLoader):
    """PyYAML's safe loader, reading ``1e-3`` and ``1e30`` as numbers (YAML 1.2; PyYAML
    follows YAML 1.1 and reads them as strings, which strict numbers would refuse)."""


_Loader.add_implicit_resolver("tag:yaml.org,2002:float", _YAML12_EXPONENT_FLOAT,
                              list("-+0123456789"))


def _check_keys(root: yaml.Node, source: str) -> dict[str, int]:
    """Refuse a mapping key given twice (YAML would keep the last silently) and a file
    that expands past :data:`MAX_YAML_VALUES` values. Walks aliases as expanded.

    Returns the line (from 1) of every key and list item by its dotted path
    (``vehicle.mass_kg``, ``safety.volume_x.0``), for error messages."""
    lines: dict[str, int] = {}
    budget = MAX_YAML_VALUES
    stack: list[tuple[yaml.Node, str]] = [(root, "")]
    while stack:
        node, path = stack.pop()
        budget -= 1
        if budget < 0:
            raise ConfigError(f"{source}: expands to more than {MAX_YAML_VALUES} values "
                              "(through YAML aliases): not a configuration")
        if isinstance(node, yaml.SequenceNode):
            for i, item in enumerate(node.value):
                here = f"{path}.{i}" if path else str(i)
                lines.setdefault(here, item.start_mark.line + 1)
                stack.append((item, here))
        elif isinstance(node, yaml.MappingNode):
            first: dict[str, int] = {}
            for key, value in node.value:
                name = key.value if isinstance(key, yaml.ScalarNode) else "<complex key>"
                line = key.start_mark.line + 1
                here = f"{path}.{name}" if path else name
                if key.tag != "tag:yaml.org,2002:merge" and isinstance(key, yaml.ScalarNode):
                    if name in first:
                        reason = (f"duplicate key (first at line {first[name]}; YAML would keep "
                                  "only the last)")
                        raise ConfigError(f"{source}:{line}: {here}: {reason}",
                                          [(here, name, reason)])
                    first[name] = line
                lines.setdefault(here, line)
                stack.append((value, here))
    return lines


def _parse_yaml(raw: bytes, source: str) -> tuple[Any, dict[str, int]]:
    """The YAML document in ``raw`` and the line of each key (:func:`_check_keys`);
    ConfigError (one line) for anything that is not one UTF-8 YAML document without
    repeated keys."""
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        where = _line_column(raw[:exc.start].decode("utf-8"))
        raise ConfigError(f"{source}:{where}: not UTF-8 text (byte 0x{raw[exc.start]:02x}): "
                          "save the file as UTF-8") from None
    try:
        loader = _Loader(text)  # refuses characters YAML does not allow, all at once
    except ReaderError as exc:
        code = exc.character if isinstance(exc.character, int) else ord(exc.character)
        name = " (a NUL byte)" if code == 0 else ""
        raise ConfigError(f"{source}:{_line_column(text[:exc.position])}: not valid YAML: "
                          f"character U+{code:04X}{name} is not allowed (YAML refuses "
                          "control characters other than tab and line breaks)") from None
    try:
        node = loader.get_single_node()
        if node is None:
            return None, {}
        lines = _check_keys(node, source)
        return loader.construct_document(node), lines
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        where = f"{source}:{mark.line + 1}:{mark.column + 1}" if mark else source
        why = ", ".join(part for part in (exc.context, exc.problem) if part)
        raise ConfigError(f"{where}: not valid YAML: {why}") from None
    except yaml.YAMLError as exc:
        raise ConfigError(f"{source}: not valid YAML: {exc}") from None
    except RecursionError:
        raise ConfigError(f"{source}: not valid YAML: nested too deeply") from None
    finally:
        loader.dispose()


def _line_column(before: str) -> str:
    """``LINE:COLUMN`` (both from 1, the column in characters) of the character that
    follows the text ``before``, as editors count them."""
    return f"{before.count(chr(10)) + 1}:{len(before) - before.rfind(chr(10))}"


def _clip(value: object, chars: int = 1000) -> str:
    text = repr(value)
    return text if len(text) <= chars else text[:chars - 3] + "..."


Problem = tuple[str, object, str]
"""One problem of a configuration: (dotted field path, the value, the reason)."""


def validation_problems(exc: ValidationError, under: str = "") -> list[Problem]:
    """One :data:`Problem` per pydantic error, its path prefixed with ``under`` (the
    section a plugin validated: ``"sim"``); a :class:`FieldValueError` is reported at the
    field it names."""
    out = []
    for err in exc.errors(include_url=False):
        loc = tuple(err["loc"])
        reason = err["msg"].removeprefix("Value error, ")
        value = err.get("input")
        cause = (err.get("ctx") or {}).get("error")
        if isinstance(cause, FieldValueError):  # the value as the file wrote it
            loc = (*loc, cause.field)
            value = value.get(cause.field, cause.value) if isinstance(value, dict) \
                else cause.value
        path = ".".join(str(p) for p in (under, *loc) if p != "") or "<root>"
        if err["type"] == "extra_forbidden":
            reason = "unknown key"
        elif err["type"] == "missing":
            reason = "required field is missing"
        elif err["type"] in ("int_type", "float_type") and isinstance(value, bool):
            reason = f"{reason}, not a boolean"
        elif err["type"] == "int_type" and isinstance(value, float):
            reason = f"{reason}, not a fraction or exponent (whole numbers only)"
        elif err["type"] == "finite_number":
            reason = f"{reason}: a time, rate, length or gain is never infinite or NaN"
        out.append((path, value, reason))
    return out


def describe_problems(exc: ValidationError) -> str:
    """Every problem of ``exc`` on one line: ``field: reason; field: reason``."""
    return "; ".join(f"{path}: {reason}" for path, _value, reason in validation_problems(exc))


def _line_of(path: str, lines: dict[str, int]) -> int | None:
    """The line of ``path`` in the file, else of its nearest enclosing key (a missing
    field: its section), else None."""
    while path:
        if path in lines:
            return lines[path]
        path = path.rpartition(".")[0]
    return None


def raise_problems(problems: list[Problem], source: str,
                   lines: dict[str, int] | None = None) -> NoReturn:
    """Raise ConfigError with one line per problem: ``SOURCE:LINE: field: value: reason``
    (``SOURCE: field: ...`` where the line is not known: defaults, overrides)."""
    out = []
    for path, value, reason in problems:
        line = _line_of(path, lines or {})
        where = source if line is None else f"{source}:{line}"
        out.append(f"{where}: {path}: {_clip(value)}: {reason}")
    raise ConfigError("\n".join(out), problems)


def validate_config(data: dict[str, Any], source: str = "<config>",
                    lines: dict[str, int] | None = None) -> GroundStationConfig:
    """Validate a parsed mapping; raise ConfigError naming every bad field (and its line,
    from ``lines``: dotted path -> line in the file, as :func:`_check_keys` finds them).

    The ``sim:`` section belongs to the virtual lab, a plugin this layer does not know: it
    is kept as given (a mapping), and the lab validates it where the configuration is
    assembled (:func:`groundstation.flight.assembly.check_config`) or when it reads it.
    """
    if not isinstance(data, dict):
        raise_problems([("<root>", data, "the file must hold a mapping of sections")], source)
    problems: list[Problem] = []
    sections = {key: value for key, value in data.items() if key != "sim"}
    config = None
    try:
        config = GroundStationConfig.model_validate(sections)
    except ValidationError as exc:
        problems += validation_problems(exc)
    sim = data.get("sim")
    if sim is not None and not isinstance(sim, dict | BaseModel):
        problems.append(("sim", sim, "a section: a mapping of the virtual lab's keys"))
    if problems or config is None:
        raise_problems(problems, source, lines)
    return config if sim is None else config.model_copy(update={"sim": sim})


def load_config(path: str | Path) -> GroundStationConfig:
    """Read and validate a YAML configuration file.

    Raises ConfigError, with a one-line reason, if the file is missing, larger than
    :data:`MAX_FILE_BYTES`, not UTF-8, not one YAML document, repeats a key, or holds
    nothing; and naming every bad field if it fails validation. Files the configuration
    names are checked by :func:`check_files`; the ``sim:`` section is kept as given (see
    :func:`validate_config`).
    """
    path = Path(path)
    try:
        with path.open("rb") as file:
            raw = file.read(MAX_FILE_BYTES + 1)
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read: {exc.strerror}") from exc
    if len(raw) > MAX_FILE_BYTES:
        raise ConfigError(f"{path}: larger than {MAX_FILE_BYTES >> 10} KiB: "
                          "not a configuration")
    data, lines = _parse_yaml(raw, str(path))
    if data is None:
        raise ConfigError(f"{path}: empty (no sections, only comments or nothing): a "
                          "configuration names at least one section; see config/lab.yaml")
    return validate_config(data, str(path), lines)


def key_lines(path: str | Path) -> dict[str, int]:
    """The line of every key of a configuration file by its dotted path (empty if the
    file cannot be read or parsed: then :func:`load_config` says why)."""
    try:
        raw = Path(path).read_bytes()[:MAX_FILE_BYTES + 1]
        return _parse_yaml(raw, str(path))[1]
    except (OSError, ConfigError):
        return {}


def file_problems(config: GroundStationConfig) -> list[Problem]:
    """The files the configuration names that cannot be used as the flight will open them:
    the waypoint CSV and the H-infinity gain (absent, not a file, not readable). Relative
    paths are taken from the working directory, as the flight takes them."""
    problems: list[Problem] = []
    for field, path in (("trajectory.file", config.trajectory.file),
                        ("controller.hinf.gain_file", config.controller.hinf.gain_file)):
        if path is None:
            continue
        if not path.exists():
            problems.append((field, str(path), "no such file"))
        elif not path.is_file():
            problems.append((field, str(path), "not a file"))
        elif not os.access(path, os.R_OK):
            problems.append((field, str(path), "not readable"))
    return problems


def check_files(config: GroundStationConfig, source: str = "<config>",
                lines: dict[str, int] | None = None) -> None:
    """Raise ConfigError naming every field of :func:`file_problems` (and its line in the
    file: ``lines`` as :func:`key_lines` gives them). The CURVE keys and the ``sim:``
    section, which need other modules, are checked where the configuration is assembled
    (:func:`groundstation.flight.assembly.check_config`)."""
    problems = file_problems(config)
    if problems:
        raise_problems(problems, source, lines)


def apply_overrides(
    config: GroundStationConfig, overrides: dict[str, Any]
) -> GroundStationConfig:
    """Return a copy with dotted-path fields replaced, re-validated as a whole.

    ``apply_overrides(cfg, {"serial.port": "/dev/pts/3", "vicon.port": 51002})``.
    ``None`` values are skipped (an option the user did not give). An unknown
    path or an invalid value raises ConfigError naming the path.
    """
    data = config.model_dump(mode="json")
    for dotted, value in overrides.items():
        if value is None:
            continue
        node = data
        *parents, leaf = dotted.split(".")
        for i, key in enumerate(parents):
            if node.get(key) is None:
                node[key] = {}
            if not isinstance(node[key], dict):
                raise_problems([(".".join(parents[:i + 1]), node[key], "not a section")],
                               "override")
            node = node[key]
        node[leaf] = copy.deepcopy(value)
    return validate_config(data, "override")


def dump_config(config: GroundStationConfig) -> str:
    """The validated configuration as YAML (what `gs check-config` prints)."""
    return yaml.safe_dump(config.model_dump(mode="json"), sort_keys=False)

