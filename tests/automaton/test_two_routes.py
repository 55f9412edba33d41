"""Two routes: the direct interpreter (syntax tree) and the compiled automaton (table lookup) give the
same actions, instant by instant, on random programs and random input sequences."""

from __future__ import annotations

import random

import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from orccadd.automaton import Automaton, Runner, compile_file, compile_text
from orccadd.automaton.checks.interpreter import Interpreter, InterpreterError
from orccadd.automaton.compiler.explicit import ReactionError
from orccadd.automaton.language.elaborate import elaborate
from orccadd.automaton.language.parser import parse_mission
from orccadd.errors import MissionError
from tests.automaton.conftest import KEEPSTABLE

HEADER = """mission R
resource R1, R2
input I, J
signal S, U
task A on R1
  post
  T2 Fail
  T3 Boom
end
task B on R2
  post
  sync Half
end
task C on R1
  post
end
"""

LEAVES = [
    "A", "B", "C", "pause", "nothing", "emit S", "emit U", "await I", "await immediate J", "await A.done",
    "await B.Half", "safe", "halt", "await 2 I", "await 3 A.done or J",
]  # fmt: skip


def statements(depth: int) -> st.SearchStrategy[str]:
    leaf = st.sampled_from(LEAVES)
    if depth == 0:
        return leaf
    sub = statements(depth - 1)
    cond = st.sampled_from([
        "I", "J", "S", "U", "Fail", "A.done", "B.Half", "I or S", "not J", "I and U",
        "pre(I)", "pre(S)", "pre(A.done) or J", "I and not pre(I)", "pre(U) and U",
    ])  # fmt: skip
    return st.one_of(
        leaf,
        st.tuples(sub, sub).map(lambda t: f"{t[0]}; {t[1]}"),
        st.tuples(sub, sub).map(lambda t: f"par({t[0]} || {t[1]})"),
        st.tuples(sub, cond).map(lambda t: f"do {t[0]} until {t[1]}"),
        st.tuples(sub, cond).map(lambda t: f"weak do {t[0]} until {t[1]}"),
        st.tuples(sub, cond).map(lambda t: f"do {t[0]} until immediate {t[1]}"),
        st.tuples(sub, cond).map(lambda t: f"weak do {t[0]} until immediate {t[1]}"),
        st.tuples(sub, cond).map(lambda t: f"loop {t[0]} each {t[1]}"),
        st.tuples(sub, cond).map(lambda t: f"suspend {t[0]} when {t[1]}"),
        st.tuples(sub, cond).map(lambda t: f"suspend {t[0]} when immediate {t[1]}"),
        st.tuples(st.integers(1, 3), sub).map(lambda t: f"repeat {t[0]} times {t[1]} end"),
        sub.map(lambda s: f"loop {s}; pause end"),
        st.tuples(cond, sub, sub).map(lambda t: f"present {t[0]} then {t[1]} else {t[2]} end"),
        st.tuples(cond, sub).map(lambda t: f"when {t[0]} do {t[1]} end"),
        st.tuples(cond, sub, cond).map(lambda t: f"when {t[0]} do {t[1]} until {t[2]}"),
        st.tuples(cond, sub).map(lambda t: f"every {t[0]} do {t[1]} end"),
        st.tuples(st.integers(0, 99), sub, st.booleans()).map(
            lambda t: f"trap T{t[0]} in {t[1]}{'; exit T' + str(t[0]) if t[2] else ''} end"
        ),
        st.tuples(st.integers(0, 99), sub, cond).map(  # an exit that preempts a running branch
            lambda t: f"trap T{t[0]} in par({t[1]} || await {t[2]}; exit T{t[0]}) end"
        ),
        st.tuples(sub, cond).map(lambda t: f"par({t[0]} || await {t[1]}; safe)"),
        st.tuples(sub, sub).map(lambda t: f"handle {t[0]} on fatal do {t[1]} end"),
        st.tuples(sub, cond, sub).map(lambda t: f"handle {t[0]} on {t[1]} do {t[2]} end"),
    )


def program(main: str, safe: str) -> str:
    return HEADER + f"safe procedure Rescue\n  {safe}\nend\nmain procedure Main\n  {main}\nend\n"


def random_inputs(a: Automaton, state: int, rng: random.Random) -> int:
    """Inputs the environment may give: operator inputs at random, one resource's fault at most
    where none of the active tasks runs on it (not in the first instant), one event or none per
    active task."""
    p = a.program
    inputs = 0
    for i in range(len(p.inputs)):
        if p.input_kind[i] == "operator" and rng.random() < 0.3:
            inputs |= 1 << i
    faults = [b for _, b in p.fault_inputs if b & (p.faults_possible(a.active[state]) if state else 0)]
    if faults and rng.random() < 0.1:  # one resource's fault at most per instant
        inputs |= rng.choice(faults)
    for t in set(a.active[state]):
        events = [bit for _, _, bit in p.tasks[t].events]
        if rng.random() < 0.5:
            inputs |= rng.choice(events)
    return inputs


def agree(a: Automaton, seed: int, instants: int = 25) -> None:
    rng = random.Random(seed)
    interp = Interpreter(a.program)
    runner = Runner(a)
    for k in range(instants):
        inputs = random_inputs(a, runner.state, rng)
        want = interp.react(inputs)
        got = runner.react(inputs)
        assert got == want, (
            k,
            a.program.describe_inputs(inputs),
            a.describe_actions(got),
            a.describe_actions(want),
        )
        assert sorted(interp.active) == sorted(a.active[runner.state])


@settings(
    max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much]
)
@given(statements(3), statements(1).filter(lambda s: "safe" not in s), st.integers(0, 2**32 - 1))
def test_interpreter_and_automaton_agree_on_random_programs(main: str, safe: str, seed: int) -> None:
    try:
        a = compile_text(program(main, safe), "random.mission", max_states=3000)
    except MissionError:
        assume(False)
        return
    agree(a, seed)


def test_interpreter_and_automaton_agree_on_keepstable() -> None:
    a = compile_file(KEEPSTABLE)
    for seed in range(50):
        agree(a, seed, instants=40)


def test_runner_keeps_the_most_severe_event_of_a_task() -> None:
    a = compile_file(KEEPSTABLE)
    p = a.program
    r = Runner(a)
    r.react(0)  # starts KeepStableUS
    both = p.input_bit("KeepStableUS.T2.Stabilized") | p.input_bit("KeepStableUS.T3.ThrusterFault")
    stray = p.input_bit("KeepStableCam.T2.UnStableCam")  # KeepStableCam is not running: ignored
    actions = r.react(both | stray)
    assert a.describe_actions(actions) == ["stop KeepStableUS", "safe"]


def test_a_pickled_automaton_reacts_as_the_original() -> None:
    """The daemon compiles in a child process and unpickles the result: same table, read-only."""
    import pickle
    from types import MappingProxyType

    a = compile_file(KEEPSTABLE)
    b = pickle.loads(pickle.dumps(a))
    assert all(isinstance(row, MappingProxyType) for row in b.table)
    assert b.table == a.table and b.action_names == a.action_names and b.active == a.active
    rng = random.Random(1)
    sa = sb = 0
    for _ in range(2000):
        inputs = rng.choice(sorted(a.table[sa]))  # an input combination the state reacts to
        (sa, acts_a), (sb, acts_b) = a.react(sa, inputs), b.react(sb, inputs)
        assert (sa, acts_a) == (sb, acts_b)


# shapes where a signal is tested before (or apart from) what emits it, mixed into random programs
PRONE = st.sampled_from([
    "present S then emit U end; emit S", "present S then emit S else emit S end",
    "par(present S then emit U end || present U then emit S end)", "present U then emit S end; emit U",
    "par(present S then emit U else emit S end || nothing)", "do emit S; await I until immediate U; emit U",
    "par(await immediate S; emit U || present U then emit S end)", "weak do emit S until immediate S",
])  # fmt: skip


@settings(
    max_examples=int(__import__("os").environ.get("STRESS", "60")),
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much],
)
@given(
    st.tuples(statements(2), PRONE, statements(1), st.booleans()).map(
        lambda t: f"{t[0]}; par({t[1]} || {t[2]})" if t[3] else f"{t[0]}; {t[1]}; {t[2]}"
    ),
    statements(1).filter(lambda s: "safe" not in s),
)
def test_what_the_compiler_finds_not_constructive_the_interpreter_refuses_on_the_same_path(
    main: str, safe: str
) -> None:
    """Constructive causality, two implementations (kernel terms; the syntax tree's nodes): a
    program the compiler refuses as not constructive, replayed on the interpreter along the path
    the refusal names, is refused by it at that path's last instant, and not before; one it
    accepts, the interpreter runs instant by instant as the automaton does."""
    try:
        a = compile_text(program(main, safe), "random.mission", max_states=3000)
    except ReactionError as e:
        if "not constructive" not in str(e):
            assume(False)
            return
        path = e.path
    except MissionError:
        assume(False)
        return
    else:  # accepted: the interpreter, its own judge of causality, agrees instant by instant
        agree(a, len(main))
        return
    interp = Interpreter(elaborate(parse_mission(program(main, safe), "random.mission")))
    for inputs in path[:-1]:
        interp.react(inputs)
    with pytest.raises(InterpreterError, match="not constructive"):
        interp.react(path[-1])
