"""Robot-Procedures: the mission language, compiled to one explicit automaton and verified.

    text -parse-> syntax tree -elaborate-> Program (kernel terms) -compile-> Automaton -verify-> Report

The automaton that passed `verify` is exactly what the execution machine steps (`Runner`).

With `allow_network=True`, a mission whose main procedure runs a `par` of independent branches
that would multiply out compiles to a `Network` instead (an automaton per branch and one for the
context), checked by `verify_network` and stepped by `NetworkRunner`.

One subpackage per stage, each importing only those before it:

    language/   grammar and parser, syntax tree, semantic checks and expansion, the kernel
    compiler/   kernel terms -> explicit automaton (constructive causality) or network
    checks/     properties with counterexamples, coverage, the interpreter (the second route), views
    promela/    the spin models that cross-check the checks
    runtime/    `Runner` and `NetworkRunner`, what the daemon's automaton thread steps

This module is their front: compile a mission's text or file, check it, step it.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Literal, overload

from orccadd.automaton.checks.network_verify import verify_network
from orccadd.automaton.checks.verify import Report, verify
from orccadd.automaton.compiler.automaton import Automaton
from orccadd.automaton.compiler.explicit import DEFAULT_MAX_STATES, Progress, compile_program
from orccadd.automaton.compiler.network import Network, compile_mission, find_split
from orccadd.automaton.language import ast as A
from orccadd.automaton.language.elaborate import elaborate
from orccadd.automaton.language.parser import load_mission_file, parse_mission
from orccadd.automaton.language.program import Program
from orccadd.automaton.runtime.network_runner import NetworkRunner
from orccadd.automaton.runtime.runner import Runner
from orccadd.errors import MissionError
from orccadd.types import TaskFileReader

__all__ = [
    "Automaton",
    "Network",
    "NetworkRunner",
    "Program",
    "Report",
    "Runner",
    "compile_file",
    "compile_text",
    "elaborate",
    "load_mission_file",
    "parse_mission",
    "verify",
    "verify_network",
]


@overload
def compile_text(
    text: str,
    file: str = ...,
    max_states: int = ...,
    task_files: TaskFileReader | None = ...,
    progress: Progress | None = ...,
    allow_network: Literal[False] = ...,
) -> Automaton: ...
@overload
def compile_text(
    text: str,
    file: str = ...,
    max_states: int = ...,
    task_files: TaskFileReader | None = ...,
    progress: Progress | None = ...,
    *,
    allow_network: Literal[True],
) -> Automaton | Network: ...
def compile_text(
    text: str,
    file: str = "<mission>",
    max_states: int = DEFAULT_MAX_STATES,
    task_files: TaskFileReader | None = None,
    progress: Progress | None = None,
    allow_network: bool = False,
) -> Automaton | Network:
    """Parse, check and compile a mission; `MissionError` on any problem. `task_files` reads
    the interface of tasks declared `from "file"` (see `elaborate`); `progress` is told how far
    a long compilation has come; `allow_network`: a `Network` where the main procedure splits
    (see the module docstring). Not for a tick."""
    return _compile(
        lambda: parse_mission(text, file), str(file), max_states, task_files, progress, allow_network
    )


@overload
def compile_file(
    path: str | Path,
    max_states: int = ...,
    task_files: TaskFileReader | None = ...,
    progress: Progress | None = ...,
    allow_network: Literal[False] = ...,
) -> Automaton: ...
@overload
def compile_file(
    path: str | Path,
    max_states: int = ...,
    task_files: TaskFileReader | None = ...,
    progress: Progress | None = ...,
    *,
    allow_network: Literal[True],
) -> Automaton | Network: ...
def compile_file(
    path: str | Path,
    max_states: int = DEFAULT_MAX_STATES,
    task_files: TaskFileReader | None = None,
    progress: Progress | None = None,
    allow_network: bool = False,
) -> Automaton | Network:
    return _compile(
        lambda: load_mission_file(path), str(path), max_states, task_files, progress, allow_network
    )


def _compile(
    parse: Callable[[], A.MissionAst],
    file: str,
    max_states: int,
    task_files: TaskFileReader | None,
    progress: Progress | None = None,
    allow_network: bool = False,
) -> Automaton | Network:
    """The parser and the elaborator bound nesting and size (`parser.MAX_NESTING`, ...); should a
    pass still run out of stack, the mission is refused like any other, never with a traceback."""
    try:
        p = elaborate(parse(), task_files)
        if allow_network:
            return compile_mission(p, max_states, progress=progress)
        try:
            return compile_program(p, max_states, progress)
        except MissionError as e:
            if find_split(p) is None or ("exceeds" not in e.detail and "input combinations" not in e.detail):
                raise
            hint = (
                "; its main procedure runs a `par` of independent branches: compiled with "
                "`allow_network=True` (as `orccadctl check` and the daemon's `load` do), it is "
                "a network of one automaton per branch"
            )
            raise MissionError(e.file, e.line, e.col, e.detail + hint, p.text) from None
    except RecursionError:
        raise MissionError(file, 0, 0, "the mission is nested too deeply to compile") from None
