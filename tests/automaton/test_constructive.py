"""Constructive causality (Esterel v5's rule, `orccadd.automaton.compiler.constructive`): a signal's status
in an instant is established by what must or cannot be emitted, never by a guess that justifies
itself. Programs Esterel refuses are refused at their line, naming the signal; programs it accepts
keep their meaning; a network's branches follow the same rule."""

from __future__ import annotations

import pytest

from orccadd.automaton import Network, Runner, compile_text, verify_network
from orccadd.automaton.compiler.constructive import Env, analyse, establish
from orccadd.errors import MissionError
from tests.automaton.conftest import two_branch_network

HEAD = """mission M
resource arm
input Stop, Go
signal X, Y, O
task Move on arm
  post
end
safe procedure S
  await Stop
end
main procedure P
"""


def compile_body(body: str) -> object:
    return compile_text(HEAD + body + "\nend\n", "c.mission")


def first_instant(body: str, inputs: set[str] = frozenset()) -> list[str]:  # type: ignore[assignment]
    a = compile_text(HEAD + body + "\nend\n", "c.mission")
    bits = sum(1 << a.program.inputs.index(n) for n in inputs)
    return a.describe_actions(Runner(a).react(bits))


@pytest.mark.parametrize(
    ("body", "line"),
    [
        ("  present X then emit X else emit X end", 12),  # one consistent status, self-justified
        ("  present X then emit O end;\n  emit X", 13),  # tested before, in sequence, the emission
        ("  par(present X then emit Y end || present Y then emit X else emit X end)", 12),
        ("  Move;\n  present X then emit O end;\n  emit X", 14),  # in a later instant too
        ("  present Y then emit O end;\n  par(present Go then emit Y end || emit X)", 13),  # with Go
    ],
)
def test_what_esterel_refuses_is_refused_naming_the_signal(body: str, line: int) -> None:
    with pytest.raises(MissionError, match=r"not constructive, .*the status of [XY] ") as e:
        compile_body(body)
    assert e.value.line == line, str(e.value)
    assert "reached by: instant 1" in str(e.value)


@pytest.mark.parametrize(
    ("body", "actions"),
    [
        ("  emit X;\n  present X then emit O end", ["emit X", "emit O", "success"]),
        ("  par(present X then emit O end || emit X)", ["emit X", "emit O", "success"]),
        ("  present X then emit O end", ["success"]),  # nothing can emit X: absent
        ("  par(present X then emit Y end || present Go then emit X end)", ["success"]),
        ("  present Y then emit O end;\n  pause;\n  emit Y", []),  # Y cannot be emitted before the pause
        (
            "  weak do\n    emit X; await Go\n  until immediate X;\n  present X then emit O end",
            ["emit X", "emit O", "success"],
        ),
        (
            "  trap T in\n    par(emit X; exit T || present X then emit O end)\n  end",
            ["emit X", "emit O", "success"],
        ),
    ],
)
def test_what_esterel_accepts_keeps_its_meaning(body: str, actions: list[str]) -> None:
    assert first_instant(body) == actions


def test_go_decides_the_status_where_it_is_known() -> None:
    body = "  par(present X then emit O end || present Go then emit X end);\n  Move"
    assert first_instant(body, {"Go"}) == ["start Move", "emit X", "emit O"]
    assert first_instant(body) == ["start Move"]


def test_three_valued_analysis_of_a_test_on_an_unknown_signal() -> None:
    """`present X then emit X else emit Y end` with X unknown: nothing must be emitted, X and Y
    can; the fixpoint establishes nothing (X stays unknown)."""
    a = compile_text(HEAD + "  present X then emit Y end\nend\n", "c.mission")
    x, y = (1 << a.program.internals.index(s) for s in ("X", "Y"))
    from orccadd.automaton.language import kernel as K

    term = K.Present((K.INT, x), K.Emit(x), K.Emit(y))
    o = analyse(term, Env(0, 0, 0))
    assert (o.must, o.can, o.must_code) == (0, x | y, None)
    assert analyse(term, Env(0, x, 0)).must == x  # X known present: its branch must run
    assert analyse(term, Env(0, 0, x)).must == y
    present, absent = establish(
        x | y, lambda p, ab: (lambda o: (o.must, o.can))(analyse(term, Env(0, p, ab)))
    )
    assert (present, absent) == (0, 0)


def test_a_network_branch_follows_the_same_rule() -> None:
    """Two independent branches, one of them non-constructive where the mission gets: a network's
    component leaves the instant out of its table and the verifier's product refuses it, with the
    same words as one automaton."""
    text = two_branch_network("present X then emit O end; emit X")
    net = compile_text(text, "n.mission", allow_network=True)
    assert isinstance(net, Network)
    with pytest.raises(MissionError, match="not constructive"):
        verify_network(net)


@pytest.mark.parametrize(
    "body",
    [
        "  present X then emit X else emit X end",
        "  present X then emit O end;\n  emit X",
        "  par(present X then emit Y end || present Y then emit X else emit X end)",
    ],
)
def test_the_reference_interpreter_refuses_them_too(body: str) -> None:
    """The interpreter (on the syntax tree, its own three-valued evaluation) refuses what the
    compiler refuses, in the instant it happens."""
    from orccadd.automaton.checks.interpreter import Interpreter, InterpreterError
    from orccadd.automaton.language.elaborate import elaborate
    from orccadd.automaton.language.parser import parse_mission

    text = HEAD + body + "\nend\n"
    interp = Interpreter(elaborate(parse_mission(text, "c.mission")))
    with pytest.raises(InterpreterError, match="not constructive: the status of X"):
        interp.react(0)


@pytest.mark.parametrize(
    ("body", "actions"),
    [
        ("  emit X;\n  present X then emit O end", ["emit X", "emit O", "success"]),
        ("  par(present X then emit O end || emit X)", ["emit X", "emit O", "success"]),
        ("  present X then emit O end", ["success"]),
        (
            "  weak do\n    emit X; await Go\n  until immediate X;\n  present X then emit O end",
            ["emit X", "emit O", "success"],
        ),
        (
            "  trap T in\n    par(emit X; exit T || present X then emit O end)\n  end",
            ["emit X", "emit O", "success"],
        ),
    ],
)
def test_the_reference_interpreter_accepts_what_the_compiler_accepts(body: str, actions: list[str]) -> None:
    from orccadd.automaton.checks.interpreter import Interpreter

    a = compile_text(HEAD + body + "\nend\n", "c.mission")
    assert a.describe_actions(Interpreter(a.program).react(0)) == actions == first_instant(body)


PRE = """mission P
resource arm
input Stop, Go
signal O
task Move on arm
  post
end
main procedure M
  handle
    loop
      await Go; emit O; {then}
    end
  on fatal do
    safe
  end
end
safe procedure S
  await Stop
end
property NoTwice: never (O and pre(O))
"""


def test_pre_in_a_property_is_the_instant_before() -> None:
    """`never (O and pre(O))`: O in two instants running. Holds when a task runs between two O's;
    violated, with the run, when the loop can go round in one instant per Go."""
    from orccadd.automaton import verify

    ok = verify(compile_text(PRE.format(then="Move"), "p.mission"))
    assert next(r for r in ok.results if r.name == "property NoTwice").ok
    bad = verify(compile_text(PRE.format(then="present Stop then Move end"), "p.mission"))
    r = next(r for r in bad.results if r.name == "property NoTwice")
    a = bad.automaton
    steps = [a.describe_actions(s.actions) for s in r.counterexample]
    assert not r.ok and steps[-2:] == [["emit O"], ["emit O"]], steps


def test_pre_of_a_task_or_an_unknown_signal_in_a_property_is_refused() -> None:
    for arg, why in (
        ("Nope", "unknown signal `Nope`"),
        ("Move", "`Move` is a task, not a signal: did you mean Move.done"),
    ):
        with pytest.raises(MissionError, match=why):
            compile_text(PRE.format(then="Move").replace("pre(O))", f"pre({arg}))"), "p.mission")
    compile_text(PRE.format(then="Move").replace("pre(O))", "pre(Move.done))"), "p.mission")
