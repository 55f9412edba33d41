"""The front end never shows a traceback: any text gives a mission or a MissionError."""

from __future__ import annotations

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from orccadd.automaton import compile_text, verify
from orccadd.automaton.language.parser import parse_mission
from orccadd.errors import MissionError
from tests.automaton.conftest import KEEPSTABLE

BASE = KEEPSTABLE.read_text()
TOKENS = [
    "mission", "task", "on", "end", "procedure", "main", "safe", "do", "until", "when", "loop", "par", "seq",
    "(", ")", "||", ";", ":", ",", ".", "->", "T2", "T3", "post", "emit", "await", "immediate", "present",
    "then", "else", "trap", "exit", "every", "handle", "fatal", "property", "never", "alternate", "and",
    "or", "not", "Stop", "KeepStableUS", "Stabilized", "X", "\n", " ", '"p.toml"', "from", "--", "#", "é",
    "\t",
]  # fmt: skip


def refused_where(e: MissionError, text: str) -> None:
    """A refusal names the file and a place in the text (or none: a whole-mission check)."""
    assert str(e).startswith("fuzz.mission:"), e
    if e.line:
        assert 1 <= e.line <= text.count("\n") + 1 and e.col >= 1, (e.line, e.col, str(e))


def outcome(text: str) -> None:
    try:
        a = compile_text(text, "fuzz.mission", max_states=2000)
    except MissionError as e:
        refused_where(e, text)
        return
    # compiled: a well-formed automaton (every transition to a state of the table), and checked
    assert 1 <= a.n_states <= 2000
    assert all(nxt < a.n_states for row in a.table for nxt, _ in row.values())
    report = verify(a)
    assert report.results and all(r.name for r in report.results)


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(st.sampled_from(TOKENS), max_size=60).map(" ".join))
def test_token_soup_never_crashes(text: str) -> None:
    outcome(text)


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.text(max_size=200))
def test_any_text_never_crashes_the_parser(text: str) -> None:
    try:
        m = parse_mission(text, "fuzz.mission")
    except MissionError as e:
        refused_where(e, text)
        return
    assert m.file == "fuzz.mission" and m.text == text
    assert not m.name or "mission" in text  # a name only from a `mission` declaration


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    st.lists(
        st.tuples(st.integers(0, len(BASE) - 1), st.integers(0, 12), st.sampled_from([*TOKENS, "", "", ""])),
        min_size=1,
        max_size=4,
    )
)
def test_mutated_keepstable_never_crashes(edits: list[tuple[int, int, str]]) -> None:
    text = BASE
    for pos, cut, insert in edits:
        pos %= max(len(text), 1)
        text = text[:pos] + insert + text[pos + cut :]
    outcome(text)
