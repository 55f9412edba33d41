"""Logging for orccadd's processes: one line per event, named by subsystem, journald-aware.

Every process calls `setup_logging` at the start of its `main()`; modules log through
`logging.getLogger("orccadd.<subsystem>")` (`orccadd`, `orccadd.machine`, `orccadd.cmdd`,
`orccadd.drivesim`, `orccadd.plantsim`, `orccadd.canopen`, `orccadd.vcan`).

- On a terminal or a file: `HH:MM:SS.mmm LEVEL logger.name: message`.
- Under systemd, with stderr connected to the journal (`$JOURNAL_STREAM` names stderr's
  device:inode, see systemd.exec(5)): `<N>logger.name: message`, N the syslog priority of the
  level, which journald strips and records as the entry's PRIORITY. A multi-line record (a
  traceback from `log.exception`) keeps one journal entry per line: every continuation line gets
  the same `<N>` prefix, so the whole traceback is filed at the record's priority.

The level is `level` unless `$ORCCADD_LOG_LEVEL` is set (DEBUG, INFO, WARNING, ERROR or
CRITICAL, any case). It applies to orccadd's loggers; other libraries' loggers (python-can,
asyncio) stay at WARNING or above, whatever the level.

A leaf module: the standard library and `orccadd.errors` only.
"""

from __future__ import annotations

import logging
import os
import sys
import threading
from collections.abc import Mapping
from types import TracebackType
from typing import TextIO

from orccadd.errors import OrccaddError

ENV_LEVEL = "ORCCADD_LOG_LEVEL"
LEVELS: dict[str, int] = {
    "DEBUG": logging.DEBUG,
    "INFO": logging.INFO,
    "WARNING": logging.WARNING,
    "ERROR": logging.ERROR,
    "CRITICAL": logging.CRITICAL,
}
PLAIN_FORMAT = "%(asctime)s.%(msecs)03d %(levelname)s %(name)s: %(message)s"
PLAIN_DATEFMT = "%H:%M:%S"

_lock = threading.Lock()
_configured = False


class LogSetupError(OrccaddError, ValueError):
    """Logging cannot be set up as asked (a bad `$ORCCADD_LOG_LEVEL`)."""


def syslog_priority(levelno: int) -> int:
    """The syslog priority journald files a record of this level under (sd-daemon(3))."""
    if levelno >= logging.CRITICAL:
        return 2
    if levelno >= logging.ERROR:
        return 3
    if levelno >= logging.WARNING:
        return 4
    if levelno >= logging.INFO:
        return 6
    return 7


class JournalFormatter(logging.Formatter):
    """`<N>logger.name: message`; each further line of the record (traceback, stack, a message
    with newlines) is its own `<N>`-prefixed line, so journald keeps its priority."""

    def __init__(self) -> None:
        super().__init__("%(name)s: %(message)s")

    def format(self, record: logging.LogRecord) -> str:
        prefix = f"<{syslog_priority(record.levelno)}>"
        return "\n".join(prefix + line for line in super().format(record).splitlines() or [""])


class PlainFormatter(logging.Formatter):
    """`HH:MM:SS.mmm LEVEL logger.name: message` (a traceback follows on its own lines)."""

    def __init__(self) -> None:
        super().__init__(PLAIN_FORMAT, PLAIN_DATEFMT)

    def format(self, record: logging.LogRecord) -> str:
        return super().format(record).rstrip("\n")  # captured `warnings` end with a newline


def under_journald(stream: TextIO | None = None, environ: Mapping[str, str] | None = None) -> bool:
    """True when `stream` (stderr) is the journal's stream: `$JOURNAL_STREAM` is `DEV:INODE` of
    it. A child whose stderr was redirected inherits the variable but not the match."""
    env = os.environ if environ is None else environ
    dev, sep, ino = env.get("JOURNAL_STREAM", "").partition(":")
    if not (sep and dev.isdigit() and ino.isdigit()):
        return False
    try:
        st = os.fstat((sys.stderr if stream is None else stream).fileno())
    except (OSError, ValueError, AttributeError):  # closed, or not a real file (a test's capture)
        return False
    return (st.st_dev, st.st_ino) == (int(dev), int(ino))


def resolve_level(level: str | int, environ: Mapping[str, str] | None = None) -> int:
    """`$ORCCADD_LOG_LEVEL` if set (not empty), else `level`; LogSetupError names what is wrong."""
    env = os.environ if environ is None else environ
    value = env.get(ENV_LEVEL, "")
    allowed = ", ".join(LEVELS)
    if value:
        if value.strip().upper() not in LEVELS:
            raise LogSetupError(f"{ENV_LEVEL}={value!r} is not a log level (allowed: {allowed})")
        return LEVELS[value.strip().upper()]
    if isinstance(level, int):
        return level
    if level.upper() not in LEVELS:
        raise LogSetupError(f"log level {level!r} is not one of {allowed}")
    return LEVELS[level.upper()]


def setup_logging(process_name: str, level: str | int = "INFO") -> None:
    """Configure the root logger for this process, once (later calls do nothing).

    `process_name` is the process's own logger (its subsystem's, e.g. `orccadd.cmdd`):
    uncaught exceptions are logged there, at CRITICAL, with their traceback.
    Raises LogSetupError for a bad `$ORCCADD_LOG_LEVEL` (before anything is configured).
    """
    global _configured
    with _lock:
        if _configured:
            return
        lvl = resolve_level(level)
        handler = logging.StreamHandler(sys.stderr)
        handler.setFormatter(JournalFormatter() if under_journald(sys.stderr) else PlainFormatter())
        root = logging.getLogger()
        root.addHandler(handler)
        root.setLevel(max(lvl, logging.WARNING))  # other libraries: warnings and worse only
        logging.getLogger("orccadd").setLevel(lvl)
        logging.captureWarnings(True)  # `warnings` through the same handler, one prefix a line
        _install_excepthooks(logging.getLogger(process_name))
        _configured = True


def _install_excepthooks(log: logging.Logger) -> None:
    def hook(kind: type[BaseException], value: BaseException, tb: TracebackType | None) -> None:
        if issubclass(kind, KeyboardInterrupt):
            sys.__excepthook__(kind, value, tb)
            return
        log.critical("uncaught exception", exc_info=(kind, value, tb))

    def thread_hook(args: threading.ExceptHookArgs) -> None:
        if args.exc_type is SystemExit:
            return
        name = args.thread.name if args.thread is not None else "?"
        exc = args.exc_value if args.exc_value is not None else args.exc_type()
        log.critical(
            "uncaught exception in thread %s", name, exc_info=(args.exc_type, exc, args.exc_traceback)
        )

    sys.excepthook = hook
    threading.excepthook = thread_hook
