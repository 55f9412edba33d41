"""Bad missions, syntax and semantic: each refused at file:line:col, with a caret and a plain message."""

from __future__ import annotations

from pathlib import Path

import pytest

from orccadd.automaton import compile_text
from orccadd.errors import MissionError
from orccadd.task.spec import read_task_interface
from tests.conftest import MOVE_TASK

DECLS = """mission M
resource Arm, Hand
input Go, Stop
signal Ready
task MoveHome on Arm
  post
  T2 Lost
end
task Grasp on Hand
  post
  T2 Lost
end
safe procedure Rest
  nothing
end
"""
N = DECLS.count("\n")  # the first line after DECLS is N + 1


def main(body: str) -> str:
    return DECLS + "main procedure P\n" + body + "\nend\n"


CASES = [
    # (id, text, line, col, words the message must hold)
    ("unfinished task", "mission M\nresource Arm\ntask A on Arm\n  post\n", 4, 7, "ends too early"),
    ("stray character", main("  MoveHome $ Grasp"), N + 2, 12, "unexpected character '$'"),
    ("until without signal", main("  do MoveHome until ;"), N + 2, 21, "unexpected `;`"),
    ("keyword as a name", "mission M\ninput end\n", 2, 7, "`end` is a keyword"),
    ("missing end of procedure", DECLS + "main procedure P\n  MoveHome\nproperty X: never Go\n", N + 3, 1,
     "not finished (missing `end`?)"),
    ("unknown task", main("  MoveHme"), N + 2, 3, "unknown task or procedure `MoveHme`; did you mean MoveHome?"),
    ("unknown signal", main("  do MoveHome until Stpo"), N + 2, 21, "unknown signal `Stpo`; did you mean Stop?"),
    ("ambiguous short name", main("  do MoveHome until Lost"), N + 2, 21,
     "`Lost` is ambiguous: write one of MoveHome.T2.Lost, Grasp.T2.Lost"),
    ("emit an input", main("  emit Stop"), N + 2, 3, "cannot emit `Stop`"),
    ("undeclared resource", "mission M\ntask A on Wrist\nend\n", 2, 11, "not a declared resource"),
    ("a resource's input on an undeclared resource", "mission M\nresource Arm\ninput Hand.part\n", 3, 7,
     "`Hand.part` names resource `Hand`'s input, but `Hand` is not declared (declared resources: Arm)"),
    ("a resource's fault declared", "mission M\nresource Arm\ninput Arm.fault\n", 3, 7,
     "`Arm.fault` is the mission's own input for Arm's faults"),
    ("a resource's output on an undeclared resource", "mission M\nsignal Hand.close\n", 2, 8,
     "`Hand.close` names resource `Hand`'s output, but `Hand` is not declared (add `resource Hand`)"),
    ("declared twice", "mission M\ninput Go\ninput Go\n", 3, 7, "`Go` is already declared at line 2"),
    ("no main procedure", DECLS, 1, 1, "exactly one `main procedure`"),
    ("no safe procedure", "mission M\nmain procedure P\n  nothing\nend\n", 1, 1, "exactly one `safe procedure`"),
    ("recursion", DECLS + "procedure A\n  B\nend\nprocedure B\n  A\nend\nmain procedure P\n  A\nend\n", N + 1, 11,
     "procedure A calls itself (A -> B -> A)"),
    ("exit outside its trap", main("  trap T in MoveHome end; exit T"), N + 2, 27, "`exit T` is not inside `trap T`"),
    ("safe inside the safe procedure", DECLS.replace("  nothing\nend", "  safe\nend") + "main procedure P\n nothing\nend",
     N - 1, 3, "`safe` inside the safe procedure"),
    ("instantaneous loop", main("  loop emit Ready end"), N + 2, 3, "loop's body can end in the instant it starts"),
    ("property atom in a statement", main("  await active(MoveHome)"), N + 2, 9, "may only appear in a property"),
    ("a signal used as a statement", main("  Go"), N + 2, 3, "`Go` is a signal: to wait for it write `await Go`"),
    ("post with a name", "mission M\nresource Arm\ntask A on Arm\n  post Done\nend\n", 4, 8, "`post` takes no name"),
    ("unknown property atom", main("  MoveHome") + "property X: never running(MoveHome)\n", N + 4, 19,
     "unknown property atom `running(...)`"),
    ("alternate needs two operands", main("  MoveHome") + "property X: Go and Stop and Ready alternate\n", N + 4, 13,
     "`alternate` needs exactly two operands"),
    ("non-causal emission", main("  present Ready else emit Ready end; MoveHome"), N + 2, 22,
     "not causal, cycle Ready -> Ready: no consistent status"),
    ("self-justifying emission", main("  present Ready then emit Ready end; MoveHome"), N + 2, 22,
     "two consistent statuses"),
    ("fatal guarding nothing", main("  handle await Go on fatal do safe end"), N + 2, 19, "guards no Robot-Task"),
    ("calling the safe procedure", main("  Rest"), N + 2, 3, "enter it with `safe`"),
    ("unknown event of a task", main("  await MoveHome.Collision"), N + 2, 9, "task MoveHome has no event `Collision`"),
]  # fmt: skip


@pytest.mark.parametrize(("text", "line", "col", "words"), [c[1:] for c in CASES], ids=[c[0] for c in CASES])
def test_bad_mission_is_refused_at_its_place(text: str, line: int, col: int, words: str) -> None:
    with pytest.raises(MissionError) as info:
        compile_text(text, "bad.mission")
    e = info.value
    assert (e.line, e.col) == (line, col), str(e)
    shown = str(e)
    assert shown.startswith(f"bad.mission:{line}:{col}: "), shown
    assert words in shown, shown
    caret_line = [ln for ln in shown.splitlines() if ln.strip() == "^"]
    assert caret_line, shown
    assert caret_line[0].index("^") == 4 + col - 1, shown


def test_the_cases_fail_only_where_they_say() -> None:
    # The shared declarations with a plain main procedure compile: each refusal above comes from
    # the line under test, not from DECLS.
    a = compile_text(main("  do MoveHome until Stop; Grasp"), "good.mission")
    assert a.program.name == "M" and [t.name for t in a.program.tasks] == ["MoveHome", "Grasp"]
    # and no two cases test the same thing (a copied row would not add coverage)
    for column in (0, 1, 4):
        values = [c[column] for c in CASES]
        assert len(set(values)) == len(values), [v for v in values if values.count(v) > 1]


def test_task_signature_must_agree_with_the_task_file(tmp_path: Path) -> None:
    text = f'mission M\nresource arm\ntask Move on arm from "{MOVE_TASK}"\n  T2 Collision\nend\n'
    with pytest.raises(MissionError) as info:
        compile_text(text, "sig.mission", task_files=read_task_interface)
    assert "signature mismatch" in str(info.value)
    assert "declares no T2 event Collision for Move" in str(info.value)
    assert "T2 TrackingLost" in str(info.value)  # what the file does offer
    assert (info.value.line, info.value.col) == (4, 6)


def test_task_file_gives_its_events_to_the_mission() -> None:
    text = (
        f'mission M\nresource arm\ntask Move on arm from "{MOVE_TASK}"\nend\n'
        "safe procedure S\n nothing\nend\n"
        "main procedure P\n handle do Move until TrackingLost on fatal do safe end\nend\n"
    )
    a = compile_text(text, "ok.mission", task_files=read_task_interface)
    assert "Move.T2.TrackingLost" in a.program.inputs
    assert "Move.T3.NearJointLimit" in a.program.inputs
    assert "Move.T2.PreconditionTimeout" in a.program.inputs  # the file has preconditions
    assert "Move.T3.Timeout" in a.program.inputs  # and no `timeout_s = inf`: it may time out


def test_a_task_file_runs_on_the_resource_its_mission_binds_it_to() -> None:
    # the file's `resource = "arm"` names the resource in its wires; `on Left` binds it (one
    # file for both arms of a cell); whether it fits Left's joints is checked against the robot
    text = (
        f'mission M\nresource Left, Right\ntask MoveL on Left from "{MOVE_TASK}"\nend\n'
        f'task MoveR on Right from "{MOVE_TASK}"\nend\n'
        "safe procedure S\n nothing\nend\n"
        "main procedure P\n handle par(MoveL || MoveR) on fatal do safe end\nend\n"
    )
    a = compile_text(text, "res.mission", task_files=read_task_interface)
    assert [(t.name, t.resource) for t in a.program.tasks] == [("MoveL", "Left"), ("MoveR", "Right")]


def test_state_explosion_is_refused_clearly() -> None:
    inputs = "input " + ", ".join(f"I{i}" for i in range(10)) + "\n"
    branches = " || ".join(f"loop await I{i}; await I{i} end" for i in range(10))
    text = "mission Big\n" + inputs + "safe procedure S\n nothing\nend\n"
    text += f"main procedure P\n par({branches})\nend\n"
    with pytest.raises(MissionError, match="exceeds 100 states"):
        compile_text(text, "big.mission", max_states=100)


def test_too_many_tasks_active_at_once_is_refused_clearly() -> None:
    tasks = "".join(f"task X{i} on R{i}\n  post\nend\n" for i in range(12))
    res = "resource " + ", ".join(f"R{i}" for i in range(12)) + "\n"
    branches = " || ".join(f"X{i}" for i in range(12))
    text = "mission Wide\n" + res + tasks + "safe procedure S\n nothing\nend\n"
    text += f"main procedure P\n handle par({branches}) on fatal do safe end\nend\n"
    with pytest.raises(MissionError, match="input combinations"):
        compile_text(text, "wide.mission")


def test_non_causal_cycle_through_two_signals_is_named() -> None:
    text = DECLS.replace("signal Ready", "signal Ready, Set") + (
        "main procedure P\n  par(present Ready then emit Set end || present Set else emit Ready end); MoveHome\nend\n"
    )
    with pytest.raises(MissionError) as info:
        compile_text(text, "cycle.mission")
    assert "cycle Ready -> Set -> Ready" in str(info.value)
