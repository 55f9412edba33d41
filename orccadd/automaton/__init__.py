"""Robot-Procedures: the mission language, compiled to one explicit automaton and verified.

    text -parse-> syntax tree -elaborate-> Program (kernel terms) -compile-> Automaton -verify-> Report

The automaton that passed `verify` is exactly what the execution machine steps (`Runner`).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from orccadd.automaton import ast as A
from orccadd.automaton.automaton import Automaton, Runner
from orccadd.automaton.compiler import DEFAULT_MAX_STATES, Progress, compile_program
from orccadd.automaton.elaborate import elaborate
from orccadd.automaton.parser import load_mission_file, parse_mission
from orccadd.automaton.program import Program
from orccadd.automaton.verify import Report, verify
from orccadd.errors import MissionError
from orccadd.types import TaskFileReader

__all__ = [
    "Automaton",
    "Program",
    "Report",
    "Runner",
    "compile_file",
    "compile_text",
    "elaborate",
    "load_mission_file",
    "parse_mission",
    "verify",
]


def compile_text(
    text: str,
    file: str = "<mission>",
    max_states: int = DEFAULT_MAX_STATES,
    task_files: TaskFileReader | None = None,
    progress: Progress | None = None,
) -> Automaton:
    """Parse, check and compile a mission; `MissionError` on any problem. `task_files` reads
    the interface of tasks declared `from "file"` (see `elaborate`); `progress` is told how far
    a long compilation has come. Not for a tick."""
    return _compile(lambda: parse_mission(text, file), str(file), max_states, task_files, progress)


def compile_file(
    path: str | Path,
    max_states: int = DEFAULT_MAX_STATES,
    task_files: TaskFileReader | None = None,
    progress: Progress | None = None,
) -> Automaton:
    return _compile(lambda: load_mission_file(path), str(path), max_states, task_files, progress)


def _compile(
    parse: Callable[[], A.MissionAst],
    file: str,
    max_states: int,
    task_files: TaskFileReader | None,
    progress: Progress | None = None,
) -> Automaton:
    """The parser and the elaborator bound nesting and size (`parser.MAX_NESTING`, ...); should a
    pass still run out of stack, the mission is refused like any other, never with a traceback."""
    try:
        return compile_program(elaborate(parse(), task_files), max_states, progress)
    except RecursionError:
        raise MissionError(file, 0, 0, "the mission is nested too deeply to compile") from None
