"""Missions at and beyond the language's limits: long ones compile, too deep or too big ones are
refused with a MissionError that says which limit and where, never with a RecursionError."""

from __future__ import annotations

import sys

import pytest

from orccadd.automaton import compile_text, verify
from orccadd.automaton.language.elaborate import MAX_EXPANDED_NESTING, MAX_EXPANDED_STATEMENTS
from orccadd.automaton.language.parser import MAX_MISSION_CHARS, MAX_NESTING
from orccadd.automaton.runtime.runner import Runner
from orccadd.errors import MissionError
from tests.conftest import ROOT


def mission(body: str, n_tasks: int = 1, procedures: str = "", inputs: str = "Stop") -> str:
    tasks = "\n".join(f"task T{i} on arm\n  post\nend" for i in range(n_tasks))
    return (
        f"mission M\nresource arm\ninput {inputs}\n{tasks}\n{procedures}\n"
        f"main procedure P\n{body}\nend\nsafe procedure S\n  await Stop\nend\n"
    )


def test_a_sequence_of_three_hundred_tasks_compiles_and_verifies() -> None:
    body = "handle\n" + ";\n".join(f"T{i}" for i in range(300)) + "\non fatal do safe end"
    a = compile_text(mission(body, n_tasks=300))
    assert a.n_states >= 300
    assert verify(a).ok


@pytest.mark.parametrize(
    ("name", "opening", "closing", "inner"),
    [
        ("SEQ blocks", "SEQ(", ")", "T0"),
        ("do … until", "do ", " until Stop", "T0"),
        ("loop … end", "loop ", " end", "T0"),
        ("handle … on", "handle ", " on Stop do nothing end", "T0"),
        ("not", "not ", "", "Stop"),
    ],
)
def test_nesting_up_to_the_limit_compiles_and_beyond_is_refused_where_it_goes_too_deep(
    name: str, opening: str, closing: str, inner: str
) -> None:
    def text(depth: int) -> str:
        nested = opening * depth + inner + closing * depth
        return mission(f"await {nested}" if name == "not" else nested)

    compile_text(text(MAX_NESTING - 2))
    for depth in (MAX_NESTING + 1, 5000):
        with pytest.raises(MissionError, match=f"nested more than {MAX_NESTING} deep") as e:
            compile_text(text(depth))
        assert e.value.line == 9 and e.value.col > 1  # the statement that goes one level too deep


def test_long_and_or_chains_compile_flat() -> None:
    names = [f"S{i % 8}" for i in range(2000)]
    inputs = ", ".join(["Stop", *sorted(set(names))])

    def first_reactions(op: str, present: set[str]) -> list[str]:
        a = compile_text(mission(f"await {op.join(names)}; T0", inputs=inputs))
        assert a.n_states < 10  # flat: 2000 terms are one condition, not a nest of states
        bits = sum(1 << a.program.inputs.index(n) for n in present)
        r = Runner(a)
        r.react(0)  # the first instant: the await begins (it counts from the next one)
        return a.describe_actions(r.react(bits))

    assert first_reactions(" or ", {"S5"}) == ["start T0"]  # any one of them
    assert first_reactions(" or ", set()) == []
    assert first_reactions(" and ", {f"S{i}" for i in range(8)}) == ["start T0"]  # all of them
    assert first_reactions(" and ", {f"S{i}" for i in range(7)}) == []  # S7 missing


def test_procedure_calls_nesting_too_deep_once_expanded_are_refused_naming_the_chain() -> None:
    n = MAX_EXPANDED_NESTING
    procs = "\n".join(f"procedure P{i}\n  do P{i + 1} until Stop\nend" for i in range(n))
    procs += f"\nprocedure P{n}\n  T0\nend"
    with pytest.raises(MissionError, match=r"once the procedures are expanded \(through P -> P0 -> P1 -> …"):
        compile_text(mission("P0", procedures=procs))


def test_procedures_that_expand_exponentially_are_refused_not_expanded() -> None:
    procs = "\n".join(f"procedure P{i}\n  P{i + 1}; P{i + 1}\nend" for i in range(40))
    procs += "\nprocedure P40\n  T0\nend"
    with pytest.raises(MissionError, match=f"more than {MAX_EXPANDED_STATEMENTS} statements"):
        compile_text(mission("P0", procedures=procs))


def test_a_mission_over_the_size_limit_is_refused_before_parsing() -> None:
    text = mission("T0") + "-- " + "x" * MAX_MISSION_CHARS
    with pytest.raises(MissionError, match=f"the limit is {MAX_MISSION_CHARS}"):
        compile_text(text)


def test_a_pass_that_still_runs_out_of_stack_is_a_mission_error(monkeypatch: pytest.MonkeyPatch) -> None:
    """The net under the limits: with the stack made tiny, a legal mission is refused, not a crash."""
    text = mission("do " * 40 + "T0" + " until Stop" * 40)
    frames = len(__import__("inspect").stack(0))
    old = sys.getrecursionlimit()
    sys.setrecursionlimit(frames + 60)
    try:
        with pytest.raises(MissionError, match="nested too deeply to compile"):
            compile_text(text)
    finally:
        sys.setrecursionlimit(old)


def test_a_long_compilation_reports_its_progress(monkeypatch: pytest.MonkeyPatch) -> None:
    from orccadd.automaton import compile_file
    from orccadd.automaton.compiler import explicit as compiler

    monkeypatch.setattr(compiler, "PROGRESS_EVERY_S", 0.0)  # every 64 states, however quick
    seen: list[tuple[int, int]] = []
    a = compile_file(
        ROOT / "benchmarks/missions/exomars_scale.mission",
        progress=lambda states, transitions, _s: seen.append((states, transitions)),
    )
    assert seen and all(0 < s <= a.n_states and 0 < t <= a.n_transitions for s, t in seen)
    assert seen == sorted(seen)
