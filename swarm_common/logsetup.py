"""One logging setup for every entry point (``vehicle-sim``, ``offboard``, ``gcs``).

Each command line takes ``--log-level`` (validated against :class:`LogLevel`), and
:func:`configure_logging` sends records to stderr as one line each::

    12:00:01.234 WARNING offboard.3: lost neighbour 5 (no estimate for 0.45 s)

Modules log through ``logging.getLogger(__name__)``; nothing prints diagnostics with
``print(..., file=sys.stderr)`` except the one-line fatal errors of the CLIs (exit 2).
"""

from __future__ import annotations

import argparse
import logging
import sys
from enum import StrEnum


class LogLevel(StrEnum):
    """The levels a user may pass to ``--log-level``."""

    DEBUG = "debug"
    INFO = "info"
    WARNING = "warning"
    ERROR = "error"


FORMAT = "%(asctime)s.%(msecs)03d %(levelname)s %(name)s: %(message)s"


def add_log_level_argument(
    parser: argparse.ArgumentParser, default: LogLevel = LogLevel.INFO
) -> None:
    """Add ``--log-level {debug,info,warning,error}`` to a command line."""
    parser.add_argument(
        "--log-level",
        type=str.lower,
        choices=[str(lv) for lv in LogLevel],
        default=str(default),
        help=f"diagnostics on stderr at this level and above (default: {default})",
    )


def configure_logging(level: str | LogLevel = LogLevel.INFO) -> None:
    """Route the ``logging`` tree to stderr at ``level``; calling it again replaces the
    handler it installed (no duplicate lines)."""
    root = logging.getLogger()
    for h in list(root.handlers):
        if getattr(h, "_swarm_handler", False):
            root.removeHandler(h)
    handler = logging.StreamHandler(sys.stderr)
    handler._swarm_handler = True  # type: ignore[attr-defined]
    handler.setFormatter(logging.Formatter(FORMAT, datefmt="%H:%M:%S"))
    root.addHandler(handler)
    root.setLevel(getattr(logging, LogLevel(str(level).lower()).name))
