"""What a mission must pass before the daemon runs it: one function for `orccadctl check` and
for the daemon's `load` (which then builds the tasks against its robot, `daemon.mission`).

Compile (parse, elaborate, build the automaton: `MissionError` at file:line:col), then the
verifier's checks with the execution machine's own (one Robot-Task active at a time, every task
from a task file): the `Report`, whose failures the caller refuses with their counterexamples.
"""

from __future__ import annotations

from pathlib import Path

from orccadd.automaton import Automaton, Report, compile_file, verify
from orccadd.automaton.compiler import DEFAULT_MAX_STATES
from orccadd.automaton.verify import CheckResult
from orccadd.task.spec import read_task_interface


def check_mission(path: str | Path, max_states: int = DEFAULT_MAX_STATES) -> tuple[Automaton, Report]:
    """The compiled mission and its verification report; `MissionError` if it does not compile."""
    automaton = compile_file(path, max_states, read_task_interface)
    report = verify(automaton, one_task_at_a_time=True)
    report.results.append(_check_task_files(automaton))
    return automaton, report


def _check_task_files(automaton: Automaton) -> CheckResult:
    bare = [f"{d.name} (line {d.loc.line})" for d in automaton.program.ast.tasks if not d.source]
    if bare:
        return CheckResult(
            "task files", False, f"no task file for {', '.join(bare)}",
            explanation='the daemon runs tasks declared `from "file.toml"` only',
        )  # fmt: skip
    return CheckResult("task files", True, "every task is built from a task file")
