"""Mission texts mutated along the grammar: the compiler answers with an automaton or a
`MissionError` (or another deliberate `OrccaddError`), never a `RecursionError`, `IndexError` …"""

from __future__ import annotations

from pathlib import Path

from hypothesis import given

from orccadd.automaton import compile_text, verify
from orccadd.errors import MissionError, OrccaddError
from orccadd.task.spec import read_task_interface
from tests.fuzz.conftest import fuzz
from tests.fuzz.strategies import missions

MAX_STATES = 2000  # keeps every example to milliseconds; larger is refused with a MissionError


def compile_outcome(seed: Path, text: str) -> str:
    """'compiled' or 'refused'; any other exception propagates (a defect)."""
    file = str(seed.parent / "fuzz.mission")  # `from "../tasks/…"` resolves as for the seed
    try:
        a = compile_text(text, file, max_states=MAX_STATES, task_files=read_task_interface)
    except MissionError as e:
        assert str(e).startswith(f"{file}:"), f"a MissionError that does not cite the file: {e}"
        return "refused"
    except OrccaddError as e:
        assert file in str(e) or "toml" in str(e), f"an error that names no file: {e!r}"
        return "refused"
    verify(a)  # a mission that compiles is checked without crashing
    return "compiled"


@fuzz(max_examples=60)
@given(missions())
def test_mutated_missions_compile_or_are_refused(case: tuple[Path, str]) -> None:
    compile_outcome(*case)
