"""Esterel's derived statements and `until immediate`: what they compile to, and their errors."""

from __future__ import annotations

import pytest

from orccadd.automaton import Runner, compile_text
from orccadd.errors import MissionError

HEAD = """mission M
resource arm
input Stop, Go, Tick
task Move on arm
  post
end
safe procedure S
  await Stop
end
main procedure P
"""


def run(body: str, instants: list[set[str]]) -> list[list[str]]:
    """The actions of each instant, from the compiled automaton."""
    a = compile_text(HEAD + body + "\n  on fatal do safe\nend\n", "c.mission")
    r, out = Runner(a), []
    for names in instants:
        bits = sum(1 << a.program.inputs.index(a.program.signal(n)) for n in names)
        out.append(a.describe_actions(r.react(bits)))
    return out


def test_repeat_runs_the_body_n_times() -> None:
    acts = run("repeat 3 times Move end repeat", [set(), {"Move.done"}, {"Move.done"}, {"Move.done"}])
    assert acts[0] == ["start Move"] and acts[1] == acts[2] == ["stop Move", "start Move"]
    assert acts[3] == ["stop Move", "success"]


def test_await_n_counts_from_the_next_instant() -> None:
    acts = run("await 2 Tick; Move", [{"Tick"}, {"Tick"}, {"Tick"}])
    assert acts == [[], [], ["start Move"]]  # the first instant's Tick does not count


def test_loop_each_restarts_the_body_at_each_signal() -> None:
    acts = run("loop Move each Go", [set(), {"Go"}, {"Move.done"}, {"Go"}])
    assert acts == [["start Move"], ["stop Move", "start Move"], ["stop Move"], ["start Move"]]


def test_until_immediate_preempts_in_the_first_instant_too() -> None:
    assert run("await Tick; do Move until immediate Go", [set(), {"Tick", "Go"}])[1] == ["success"]
    assert run("await Tick; do Move until Go", [set(), {"Tick", "Go"}])[1] == ["start Move"]
    # weak: Move reacts in that instant (it starts), then is killed in the same instant: a task
    # started and stopped within one instant is never sent to the arm
    assert run("await Tick; weak do Move until immediate Go", [set(), {"Tick", "Go"}])[1] == ["success"]


@pytest.mark.parametrize(
    ("body", "message"),
    [
        ("repeat 0 times Move end", "the count must be a whole number from 1 to 1000"),
        ("repeat 1001 times Move end", "from 1 to 1000"),
        ("await 2.5 Tick", "the count must be a whole number"),
        ("await immediate 2 Tick", "`await immediate` takes no count"),
    ],
)
def test_bad_counts_are_refused_at_their_place(body: str, message: str) -> None:
    with pytest.raises(MissionError, match=message) as info:
        compile_text(HEAD + body + "\nend\n", "c.mission")
    assert info.value.line == HEAD.count("\n") + 1
