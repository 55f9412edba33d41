"""A resource's fault as a mission input (`R.fault`): offered after the first instant while no
active task runs on R, it enters the safe procedure from anywhere in the main procedure and ends
the safe procedure as failed; the checks neither await it nor count on it."""

from __future__ import annotations

from orccadd.automaton import Runner, compile_text, verify
from orccadd.automaton.checks.interpreter import Interpreter
from orccadd.automaton.checks.verify import Report
from orccadd.automaton.compiler.automaton import MAIN, SAFE
from orccadd.automaton.language.program import Program

HEADER = """
mission M
resource Arm, Hand
input Go, Stop
task Move on Arm
  post
end
task Grip on Hand
  post
end
"""

SAFE_ACK = """
safe procedure Rest
  await Stop
end
"""

MAIN_BODY = """
main procedure Main
  handle
    await Go; Move; Grip
  on fatal do
    safe
  end
end
"""


def bit(p: Program, name: str) -> int:
    return 1 << p.inputs.index(name)


def failed(report: Report, name: str) -> bool:
    return report.failed(name)


def test_each_declared_resource_has_its_fault_input_and_no_operator_input_more() -> None:
    a = compile_text(HEADER + SAFE_ACK + MAIN_BODY, "m.mission")
    p = a.program
    kinds = dict(zip(p.inputs, p.input_kind, strict=True))
    assert [n for n, k in kinds.items() if k == "fault"] == ["Arm.fault", "Hand.fault"]
    assert [n for n, k in kinds.items() if k == "operator"] == ["Go", "Stop"]
    assert p.signal("Arm.fault") == "Arm.fault"
    assert verify(a).ok


def test_a_fault_is_offered_only_where_no_task_runs_on_its_resource_and_not_at_once() -> None:
    a = compile_text(HEADER + SAFE_ACK + MAIN_BODY, "m.mission")
    p = a.program
    arm, hand = bit(p, "Arm.fault"), bit(p, "Hand.fault")
    assert not a.relevant[0] & (arm | hand)  # the first instant: every resource ready
    for s in range(1, a.n_states):
        if a.phase[s] not in (MAIN, SAFE):
            continue
        on = {p.tasks[t].resource for t in a.active[s]}
        assert bool(a.relevant[s] & arm) == ("Arm" not in on), a.where[s]
        assert bool(a.relevant[s] & hand) == ("Hand" not in on), a.where[s]


def test_the_hands_fault_while_the_arm_moves_enters_the_safe_procedure_at_once() -> None:
    a = compile_text(HEADER + SAFE_ACK + MAIN_BODY, "m.mission")
    p = a.program
    r = Runner(a)
    r.react(0)
    r.react(bit(p, "Go"))  # Move starts
    assert [p.tasks[t].name for t in a.active[r.state]] == ["Move"]
    assert r.react(bit(p, "Arm.fault")) == 0  # not offered while Move runs on the arm: no reaction
    actions = r.react(bit(p, "Hand.fault"))
    assert a.describe_actions(actions) == ["stop Move", "safe"]
    assert a.phase[r.state] == SAFE
    # inside the safe procedure, from its next instant, a fault ends the mission as failed
    assert "failed" in a.describe_actions(r.react(bit(p, "Arm.fault")))


def test_a_fault_where_the_initial_term_waits_again_is_not_the_first_instants() -> None:
    """`await immediate Go` with Go absent leaves the main procedure's term as it began: a later
    instant there is not the first, so a resource's fault may come and enters the safe procedure
    (the compiler took state 0's term for the first instant and ignored it; the lockstep spin
    model found it on a random program)."""
    main = """
main procedure Main
  handle
    await immediate Go; Move
  on fatal do
    safe
  end
end
"""
    a = compile_text(HEADER + SAFE_ACK + main, "m.mission")
    p = a.program
    arm = bit(p, "Arm.fault")
    assert not a.relevant[0] & arm  # the first instant: every resource ready
    r = Runner(a)
    r.react(0)
    assert not a.active[r.state] and r.state != 0  # the initial term again, a state of its own
    assert a.relevant[r.state] & arm
    assert a.describe_actions(r.react(arm)) == ["safe"]
    assert a.phase[r.state] == SAFE
    assert verify(a).ok


def test_the_safe_procedure_can_tell_which_resource_faulted() -> None:
    safe = """
safe procedure Rest
  present Hand.fault then Move else Grip end
end
"""
    a = compile_text(HEADER + safe + MAIN_BODY, "m.mission")
    p = a.program
    for fault, task in (("Hand.fault", "start Move"), ("Arm.fault", "start Grip")):
        r = Runner(a)
        r.react(0)
        assert task in a.describe_actions(r.react(bit(p, fault)))  # waiting for Go: both idle
    assert verify(a).ok


def test_a_fault_that_would_move_a_stuck_procedure_does_not_hide_its_deadlock() -> None:
    stuck = """
main procedure Main
  handle
    Move; halt
  on fatal do
    safe
  end
end
"""
    a = compile_text(HEADER + SAFE_ACK + stuck, "m.mission")
    report = verify(a)
    assert failed(report, "deadlock") and failed(report, "strong liveness"), report.format()
    assert report.level(next(x for x in report.results if x.name == "strong liveness")) == "error"


def test_a_main_procedure_without_a_handler_still_enters_the_safe_procedure_on_a_fault() -> None:
    bare = """
main procedure Main
  await Go
end
"""
    a = compile_text(HEADER + SAFE_ACK + bare, "m.mission")
    report = verify(a)
    assert not failed(report, "safety"), report.format()
    r = Runner(a)
    r.react(0)
    assert "safe" in a.describe_actions(r.react(bit(a.program, "Arm.fault") | bit(a.program, "Go")))


def test_the_interpreter_reacts_to_a_fault_as_the_automaton() -> None:
    a = compile_text(HEADER + SAFE_ACK + MAIN_BODY, "m.mission")
    p = a.program
    seq = [0, bit(p, "Go"), bit(p, "Hand.fault"), 0, bit(p, "Arm.fault")]
    interp, runner = Interpreter(p), Runner(a)
    assert [interp.react(x) for x in seq] == [runner.react(x) for x in seq]
