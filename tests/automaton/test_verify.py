"""Each check fails on a mission built to fail it, with a counterexample that replays."""

from __future__ import annotations

from collections.abc import Callable

import pytest

from orccadd.automaton import Automaton, compile_file, compile_text, verify
from orccadd.automaton.checks.verify import Report
from orccadd.automaton.compiler.automaton import END
from tests.automaton.conftest import UNHANDLED_T3

HEADER = """
mission M
resource Arm, Hand
input Go, Stop
signal Ready
task Move on Arm
  post
  T2 Lost
end
task Grip on Hand
  post
end
task Swing on Arm
  post
end
safe procedure Rest
  nothing
end
"""


def check(body: str) -> tuple[Automaton, Report]:
    a = compile_text(HEADER + body, "m.mission")
    return a, verify(a)


def failed(report: Report, name: str) -> str:
    r = next(r for r in report.results if r.name == name)
    assert not r.ok, report.format()
    return r.summary


def replay(a: Automaton, report: Report, name: str) -> int:
    r = next(r for r in report.results if r.name == name)
    s = 0
    for step in r.counterexample:
        s, actions = a.react(s, step.inputs)
        assert actions == step.actions
    return s


def test_unhandled_type3_is_refused_with_a_counterexample() -> None:
    a = compile_file(UNHANDLED_T3)
    report = verify(a)
    summary = failed(report, "safety")
    assert "Approach.T3." in summary
    r = next(r for r in report.results if r.name == "safety")
    assert r.counterexample[-1].inputs & a.program.t3_masks[0]
    assert "counterexample" in report.format()


def test_a_handled_mission_passes() -> None:
    _, report = check("main procedure P\n handle Move; Grip on fatal do safe end\nend")
    assert report.ok, report.format()


def test_conflict_on_one_resource() -> None:
    a, report = check("main procedure P\n handle par(Move || Swing) on fatal do safe end\nend")
    assert "Move and Swing" in failed(report, "conflicts")
    s = replay(a, report, "conflicts")
    assert sorted(a.active[s]) == [0, 2]


def test_tasks_on_different_resources_do_not_conflict() -> None:
    _, report = check("main procedure P\n handle par(Move || Grip) on fatal do safe end\nend")
    assert report.ok, report.format()


def test_joint_claims_overlap_only_when_they_share_a_joint() -> None:
    text = """
mission J
resource Arm
task Shoulder on Arm joints j1, j2
  post
end
task Wrist on Arm joints j5, j6
  post
end
task Elbow on Arm joints j2, j3
  post
end
safe procedure S
  nothing
end
main procedure P
  handle par(Shoulder || Wrist); par(Wrist || Elbow); par(Shoulder || Elbow) on fatal do safe end
end
"""
    report = verify(compile_text(text, "j.mission"))
    assert "Shoulder and Elbow active at once on resource Arm (joints ['j2'])" in failed(report, "conflicts")


def test_liveness_fails_when_success_cannot_be_reached() -> None:
    # waits for Grip's postcondition while Grip is not running: stuck forever, Stop does not help
    _, report = check("main procedure P\n handle Move; await Grip.done on fatal do safe end\nend")
    assert "success is unreachable" in failed(report, "liveness")


def test_liveness_accepts_a_loop_left_by_an_operator_input() -> None:
    _, report = check(
        "main procedure P\n handle do loop Move; Swing end until Stop on fatal do safe end\nend"
    )
    assert report.ok, report.format()


def test_liveness_fails_on_an_endless_loop() -> None:
    _, report = check("main procedure P\n handle loop Move; Swing end on fatal do safe end\nend")
    failed(report, "liveness")


def test_deadlock_is_found() -> None:
    _, report = check("main procedure P\n halt\nend")
    assert "deadlock" in failed(report, "deadlock")


def test_a_cycle_without_progress_is_found() -> None:
    _, report = check("main procedure P\n loop emit Ready; pause end\nend")
    assert "no progress" in failed(report, "deadlock")


def test_a_cycle_waiting_for_the_operator_is_progress() -> None:
    _, report = check("main procedure P\n do loop emit Ready; pause end until Stop\nend")
    assert report.ok, report.format()


@pytest.mark.parametrize(
    ("prop", "ok"),
    [
        ("never (active(Move) and active(Grip))", False),
        ("never (active(Move) and active(Swing))", True),
        ("start(Move) -> eventually stop(Move)", True),
        ("Go -> eventually start(Swing)", True),  # on the runs no fault hands to the safe procedure
        ("start(Move) and stop(Move) alternate", True),
        ("stop(Move) and start(Move) alternate", False),
    ],
)
def test_observers(prop: str, ok: bool) -> None:
    body = (
        "main procedure P\n handle await Go; par(Move || Grip); Swing on fatal do safe end\nend\n"
        f"property X: {prop}\n"
    )
    a, report = check(body)
    r = next(r for r in report.results if r.name == "property X")
    assert r.ok is ok, report.format()
    if ok:
        return
    # The counterexample replays on the automaton from the initial state, reaction for reaction,
    # and its last instant really violates the property.
    assert r.counterexample, report.format()
    s, trace = 0, []
    for step in r.counterexample:
        s, actions = a.react(s, step.inputs)
        assert actions == step.actions, report.format()
        trace.append((step.inputs, a.describe_actions(actions)))
    if prop.startswith("never"):  # the forbidden situation: both tasks active at the end
        assert {"Move", "Grip"} <= {a.program.tasks[t].name for t in a.active[s]}, trace
    elif prop.startswith("Go ->"):  # Go, then no start of Swing, and none can follow any more
        first_go = next(i for i, (ins, _) in enumerate(trace) if ins & a.program.input_bit("Go"))
        assert not any("start Swing" in acts for _, acts in trace[first_go:]), trace
        assert a.phase[s] == END or not _can_reach(a, s, lambda acts: "start Swing" in acts), trace
    else:  # stop(Move) and start(Move) alternate: Move started before it was ever stopped
        assert "start Move" in trace[-1][1], trace
        assert not any("stop Move" in acts for _, acts in trace), trace


def _can_reach(a: Automaton, s: int, hit: Callable[[list[str]], bool]) -> bool:
    """Some reaction reachable from state `s` has actions satisfying `hit`."""
    seen, todo = {s}, [s]
    while todo:
        for n, actions in a.table[todo.pop()].values():
            if hit(a.describe_actions(actions)):
                return True
            if n not in seen:
                seen.add(n)
                todo.append(n)
    return False


def test_t3_inside_the_safe_procedure_ends_the_mission_failed() -> None:
    text = HEADER.replace("safe procedure Rest\n  nothing\nend", "safe procedure Rest\n  Grip\nend")
    a = compile_text(text + "main procedure P\n handle Move on fatal do safe end\nend", "m.mission")
    report = verify(a)
    assert report.ok, report.format()
    move_t3 = a.program.input_bit("Move.T3.CommLost")
    grip_t3 = a.program.input_bit("Grip.T3.Overrun")
    s, actions = a.react(0, 0)
    s, actions = a.react(s, move_t3)
    assert a.describe_actions(actions) == ["stop Move", "start Grip", "safe"]
    s, actions = a.react(s, grip_t3)
    assert a.describe_actions(actions) == ["stop Grip", "failed"]


def test_eventually_is_checked_like_liveness_on_runs_without_a_fault_or_a_type_3() -> None:
    """A resource's fault in Go's own instant (`{Go, Arm.fault} -> safe`) refuted every
    `Go -> eventually X` of a mission with a resource, while liveness assumed no exceptions."""
    text = HEADER.replace("safe procedure Rest\n  nothing\nend", "safe procedure Rest\n  Grip\nend")
    body = (
        "main procedure P\n handle await Go; Move; Swing on fatal do safe end\nend\n"
        "property Starts: Go -> eventually start(Move)\n"
        "property Swings: start(Move) -> eventually start(Swing)\n"
        "property Again: start(Swing) -> eventually start(Move)\n"
        "property NoGrip: never start(Grip)\n"
    )
    report = verify(compile_text(text + body, "m.mission"))
    assert not report.failed("property Starts") and not report.failed("property Swings"), report.format()
    assert report.failed("property Again")  # still refuted where no fault is needed to refute it
    # a `never` still holds on every run: the safe procedure (after a fault) starts Grip
    assert report.failed("property NoGrip")
