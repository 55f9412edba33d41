"""One error tree for orccadd. Every error a user can cause derives from `OrccaddError`."""

from __future__ import annotations

import difflib
from collections.abc import Iterable


class OrccaddError(Exception):
    """Root of every error orccadd raises on purpose."""


class ConfigError(OrccaddError):
    """A configuration file is wrong: the message names the file, key path, value and what is allowed."""

    def __init__(self, file: str, key: str, message: str) -> None:
        self.file = file
        self.key = key
        self.detail = message
        where = f"{file}: {key}" if key else file
        super().__init__(f"{where} {message}" if key else f"{file}: {message}")


class WiringError(OrccaddError):
    """A Robot-Task's modules cannot be wired as declared (both ends are named)."""


class ModelError(OrccaddError):
    """The robot model (URDF) cannot be loaded or does not match the config."""


class ResourceError(OrccaddError):
    """A Physical Resource failed (configuration, lifecycle, or communication)."""


class LifecycleError(ResourceError):
    """A lifecycle transition was asked from a state that does not allow it."""


class ParameterError(OrccaddError):
    """A module parameter was set to a value outside its declaration (bounds, shape, tunable).

    `name` is the parameter's own name and `detail` the message without it, so a file loader
    can cite `modules.ct.kp (=-1.0) must be in [0, 100000] 1/s^2`.
    """

    def __init__(self, message: str, *, name: str = "", detail: str = "") -> None:
        super().__init__(message)
        self.name = name
        self.detail = detail or message


class MissionError(OrccaddError):
    """A mission file is wrong: `file:line:col: message`, then the line and a caret under the place."""

    def __init__(self, file: str, line: int, col: int, message: str, text: str = "") -> None:
        self.file = file
        self.line = line
        self.col = col
        self.detail = message
        lines = text.splitlines()
        shown = ""
        if 1 <= line <= len(lines):
            src = lines[line - 1].expandtabs(1)
            shown = f"\n    {src}\n    {' ' * max(col - 1, 0)}^"
        super().__init__(f"{file}:{line}:{col}: {message}{shown}")


class VerificationError(OrccaddError):
    """A mission compiled but failed a check; the message holds every failed check's counterexample."""


def did_you_mean(word: str, known: Iterable[str]) -> str:
    """ "; did you mean A or B?" for the known names nearest a mistyped one ("" when none is near)."""
    near = difflib.get_close_matches(word, list(known), n=3, cutoff=0.6)
    return f"; did you mean {' or '.join(near)}?" if near else ""
