"""Verdicts of issue 19: liveness judged per procedure and per state, a task active twice refused,
the safe procedure's guard not immediate, the dead-code check and strong liveness (lassos)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import pytest

from orccadd.automaton import Automaton, compile_file, compile_text, verify
from orccadd.automaton.checks.interpreter import Interpreter
from orccadd.automaton.checks.verify import CheckResult, Report, format_trace
from orccadd.errors import MissionError
from orccadd.offline.commands import cmd_check
from orccadd.task.spec import read_task_interface
from orccadd.types import CommandMode, TaskInterface
from tests.automaton.conftest import KEEPSTABLE, MISSIONS, TEST_MISSIONS

STUCK = TEST_MISSIONS / "stuck_main_safe_awaits.mission"
TWICE = TEST_MISSIONS / "refused" / "task_twice.mission"
SAFE_REUSES = TEST_MISSIONS / "safe_reuses_task.mission"
DEAD = TEST_MISSIONS / "dead_code.mission"
RETRY = TEST_MISSIONS / "retry_forever.mission"
SPIN = TEST_MISSIONS / "spin_forever.mission"


def result(report: Report, name: str) -> CheckResult:
    return next(r for r in report.results if r.name == name)


def replay(a: Automaton, r: CheckResult) -> list[int]:
    """The states a counterexample goes through, its reactions checked against the automaton."""
    states = [0]
    for step in r.counterexample:
        nxt, actions = a.react(states[-1], step.inputs)
        assert actions == step.actions
        states.append(nxt)
    return states


# 1. liveness per procedure: the safe procedure's inputs do not keep the main one alive


def test_a_stuck_main_procedure_is_a_deadlock_though_the_safe_procedure_awaits_an_input() -> None:
    a = compile_file(STUCK)
    report = verify(a)
    deadlock = result(report, "deadlock")
    assert not deadlock.ok, report.format()
    end = replay(a, deadlock)[-1]
    assert "halt" in a.where[end] and a.relevant[end]  # Stop is tested there: it moves nothing
    assert not any("only an operator input can move" in w for w in report.warnings)
    strong = result(report, "strong liveness")
    assert not strong.ok and strong.level == "error", report.format()


# 2. a task active twice at once is refused at elaboration, naming both places


def test_a_task_in_two_branches_through_two_procedures_is_refused_naming_both_places() -> None:
    with pytest.raises(MissionError) as e:
        compile_file(TWICE)
    msg = str(e.value)
    assert "task Move may be active twice at once" in msg
    assert f"{TWICE}:18:3 (in Reach, called at {TWICE}:28:9)" in msg
    assert f"{TWICE}:23:3 (in Fetch, called at {TWICE}:28:18)" in msg
    assert (e.value.line, e.value.col) == (28, 5)  # the `par`


@pytest.mark.parametrize(
    "body",
    [
        "par(Move || Move)",
        "par(Move || await Move.done; Move)",  # one after the other: refused all the same
        "par(Grip || par(Move || Grip))",
    ],
)
def test_a_task_in_two_branches_of_a_par_is_refused(body: str) -> None:
    with pytest.raises(MissionError, match="may be active twice at once"):
        compile_text(_mission(f"handle {body} on fatal do safe end"), "m.mission")


def test_a_task_in_one_branch_or_in_sequence_is_accepted() -> None:
    a = compile_text(_mission("handle par(Move; Move || Grip); Move; Grip on fatal do safe end"), "m.mission")
    assert verify(a).ok


# 3. the safe procedure may run the task whose type 3 exception entered it


def test_the_safe_procedure_reruns_the_failed_task_instead_of_failing_at_once() -> None:
    a = compile_file(SAFE_REUSES)
    assert verify(a).ok
    t3 = a.program.input_bit("Move.T3.CommLost")
    s, _ = a.react(0, 0)
    s, actions = a.react(s, t3)
    assert a.describe_actions(actions) == ["stop Move", "start Move", "safe"]
    _, actions = a.react(s, t3)  # from the next instant on, its type 3 ends the mission
    assert a.describe_actions(actions) == ["stop Move", "failed"]
    s, actions = a.react(s, a.program.input_bit("Move.done"))
    assert a.describe_actions(actions) == ["stop Move"] and "await" in a.where[s]


def test_the_interpreter_agrees_on_the_safe_procedure_rerunning_a_task() -> None:
    a = compile_file(SAFE_REUSES)
    p = a.program
    t3, done, stop = p.input_bit("Move.T3.LawError"), p.input_bit("Move.done"), p.input_bit("Stop")
    for inputs in ([0, t3, t3], [0, t3, done, stop], [0, t3, 0, done]):
        interp, s = Interpreter(p), 0
        for i in inputs:
            s, actions = a.react(s, i)
            assert interp.react(i) == actions, a.describe_actions(actions)


# 4. dead code: a warning, an error when strict


def test_dead_code_names_each_dead_statement_once() -> None:
    report = verify(compile_file(DEAD))
    dead = result(report, "dead code")
    assert not dead.ok and dead.level == "warning"
    assert dead.explanation.splitlines() == [
        f"{DEAD}:19:6: task Spare is declared but never run",
        f"{DEAD}:27:7: the `then` of `present Unseen` never runs",
        f"{DEAD}:34:7: `emit Unseen` is never executed",
        f"{DEAD}:38:3: the handler `on Grip.done` never runs",
    ]
    assert report.ok and "warn dead code: 4 statements" in report.format()
    report.strict = True
    assert not report.ok and "FAIL dead code" in report.format()


@pytest.mark.parametrize("path", [*sorted(MISSIONS.glob("*.mission")), RETRY], ids=lambda p: p.stem)
def test_a_mission_without_dead_code_passes_the_check(path: Path) -> None:
    # demo.mission: a handler whose body starts with a task (its start is the task's)
    report = verify(compile_file(path, task_files=read_task_interface))
    assert result(report, "dead code").ok, report.format()


def test_check_strict_fails_on_dead_code(capsys: pytest.CaptureFixture[str]) -> None:
    assert _check(DEAD, strict=False) == 0
    out = json.loads(capsys.readouterr().out)
    dead = next(c for c in out["checks"] if c["name"] == "dead code")
    assert out["ok"] and not dead["ok"] and dead["level"] == "warning"
    assert _check(DEAD, strict=True) == 1
    out = json.loads(capsys.readouterr().out)
    assert not out["ok"] and next(c for c in out["checks"] if c["name"] == "dead code")["level"] == "error"


# 5. strong liveness: lassos, an error only where nothing runs and nothing leads out


def test_a_retry_loop_is_a_note_with_a_lasso() -> None:
    a = compile_file(RETRY)
    report = verify(a)
    strong = result(report, "strong liveness")
    assert report.ok and result(report, "liveness").ok
    assert not strong.ok and strong.level == "note"
    assert "may run forever: it loops until Move.done" in strong.summary
    states = replay(a, strong)
    assert strong.loop_start is not None and states[strong.loop_start] == states[-1]
    loop = strong.counterexample[strong.loop_start :]
    assert any(step.inputs == a.program.input_bit("Move.T2.Lost") for step in loop)
    lines = format_trace(a, strong.counterexample, strong.loop_start)
    assert lines[strong.loop_start].startswith(f"instant {strong.loop_start + 1} (loop start):")
    assert lines[-1] == f"... then from instant {strong.loop_start + 1} again, forever"


def test_a_loop_with_nothing_running_and_no_way_out_fails_strong_liveness() -> None:
    a = compile_file(SPIN)
    report = verify(a)
    assert result(report, "deadlock").ok  # Go changes the reaction: not a deadlock
    strong = result(report, "strong liveness")
    assert not strong.ok and strong.level == "error", report.format()
    assert "nothing running and no way out" in strong.summary
    states = replay(a, strong)
    assert strong.loop_start is not None and states[strong.loop_start] == states[-1]
    assert not any(a.active[s] for s in states[strong.loop_start :])


def test_waiting_for_the_operator_forever_is_a_note() -> None:
    a = compile_file(KEEPSTABLE)
    report = verify(a)
    strong = result(report, "strong liveness")
    assert report.ok and not strong.ok and strong.level == "note"
    assert "wait forever for an operator input (Stop)" in strong.summary
    states = replay(a, strong)
    loop = states[strong.loop_start or 0 :]
    # the loop is fair: each task running at its start is stopped in it
    for t in a.active[loop[0]]:
        assert any(a.stops(step.actions) >> t & 1 for step in strong.counterexample[strong.loop_start or 0 :])


@pytest.mark.parametrize(("times_out", "ok"), [(True, True), (False, False)])
def test_only_a_task_that_times_out_is_assumed_to_end(times_out: bool, ok: bool) -> None:
    def reader(path: Path) -> TaskInterface:
        return TaskInterface(
            str(path), "Arm", CommandMode.POSITION, (), (), True, False, (), (), (), times_out
        )

    text = _mission("handle Hold on fatal do safe end").replace(
        "task Move on Arm", 'task Hold on Arm from "hold.toml"\nend\ntask Move on Arm'
    )
    report = verify(compile_text(text, "m.mission", task_files=reader))
    strong = result(report, "strong liveness")
    assert strong.ok is ok, report.format()
    if not ok:
        assert strong.level == "note" and "until Hold.done" in strong.summary


def test_strong_liveness_passes_when_every_run_ends() -> None:
    report = verify(
        compile_text(_mission("handle Move; par(Grip || Move) on fatal do safe end"), "m.mission")
    )
    assert result(report, "strong liveness").ok, report.format()


def _mission(main: str) -> str:
    return (
        "mission M\nresource Arm, Hand\ninput Go\ntask Move on Arm\n  post\nend\n"
        "task Grip on Hand\n  post\nend\nsafe procedure S\n  nothing\nend\n"
        f"main procedure P\n  {main}\nend\n"
    )


def _check(path: Path, *, strict: bool) -> int:
    args = argparse.Namespace(
        file=str(path), json=True, strict=strict, max_states=10_000, language_only=True, config=None
    )
    return cmd_check(args)
