"""structlog configured once for the whole process.

Console renderer when stderr is a terminal, JSON lines otherwise (systemd,
Docker, CI) or when the configuration asks for it. Library modules only call
``structlog.get_logger(__name__)``; only the CLI calls :func:`configure_logging`.
"""

from __future__ import annotations

import logging
import sys
from typing import Literal

import structlog

LogFormat = Literal["auto", "console", "json"]
_LEVELS = {"debug": logging.DEBUG, "info": logging.INFO, "warning": logging.WARNING,
           "error": logging.ERROR}


def _stderr_logger(*_args: object) -> structlog.PrintLogger:
    """A logger on whatever ``sys.stderr`` is now (it may be replaced after configuration,
    e.g. by a test runner or a daemoniser; binding the object at configuration time would
    then write to a closed file)."""
    return structlog.PrintLogger(file=sys.stderr)


def configure_logging(level: str = "info", fmt: LogFormat = "auto") -> None:
    """Configure structlog: ``level`` is debug/info/warning/error, ``fmt`` auto/console/json.

    Output goes to stderr so stdout stays free for command results.
    """
    use_console = fmt == "console" or (fmt == "auto" and sys.stderr.isatty())
    renderer: structlog.typing.Processor = (
        structlog.dev.ConsoleRenderer() if use_console else structlog.processors.JSONRenderer()
    )
    structlog.configure(
        processors=[
            structlog.contextvars.merge_contextvars,
            structlog.processors.add_log_level,
            structlog.processors.TimeStamper(fmt="iso", utc=True),
            structlog.processors.StackInfoRenderer(),
            structlog.processors.format_exc_info,
            renderer,
        ],
        wrapper_class=structlog.make_filtering_bound_logger(_LEVELS[level]),
        logger_factory=_stderr_logger,
        cache_logger_on_first_use=False,
    )
