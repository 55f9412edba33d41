"""Events the program cannot tell apart are explored once (orccadd/automaton/compiler/classes.py): a
task's built-in type 3 exceptions under one `on fatal` are one class; two type 2 exceptions the
procedure handles differently are two. Every member of a class reacts as its representative."""

from __future__ import annotations

from orccadd.automaton import Runner, compile_text, verify

MISSION = """mission M
resource Arm
input Go
task Move on Arm
  post
  T2 Slipped
  T2 Blocked
end
task Retry on Arm
  post
end
safe procedure S
  nothing
end
main procedure P
  {body}
on fatal do
  safe
end
"""

SAME = "handle Move on Move.T2.Slipped or Move.T2.Blocked do Retry end"
APART = "handle Move on Move.T2.Slipped do Retry on Move.T2.Blocked do nothing end"


def test_built_in_type_3_exceptions_handled_alike_are_one_class() -> None:
    a = compile_text(MISSION.format(body=SAME), "m.mission")
    p = a.program
    t3 = [i for i, name in enumerate(p.inputs) if name.startswith("Move.T3.")]
    assert len(t3) >= 4
    assert len({a.event_rep[i] for i in t3}) == 1  # one class: one representative
    slipped, blocked = p.input_bit("Move.T2.Slipped"), p.input_bit("Move.T2.Blocked")
    assert a.event_rep[slipped.bit_length() - 1] == a.event_rep[blocked.bit_length() - 1]
    assert verify(a).ok
    # each member reacts as its representative, through the table and through the runtime
    s, _ = a.react(0, 0)
    reactions = {a.react(s, 1 << i) for i in t3}
    assert len(reactions) == 1
    runner = Runner(a)
    runner.react(0)
    for i in t3:
        runner.state = s
        assert runner.react(1 << i) == next(iter(reactions))[1]


def test_events_the_procedure_tells_apart_stay_apart() -> None:
    a = compile_text(MISSION.format(body=APART), "m.mission")
    p = a.program
    slipped, blocked = p.input_bit("Move.T2.Slipped"), p.input_bit("Move.T2.Blocked")
    assert a.event_rep[slipped.bit_length() - 1] != a.event_rep[blocked.bit_length() - 1]
    s, _ = a.react(0, 0)
    to_retry, to_end = a.react(s, slipped), a.react(s, blocked)
    assert "start Retry" in a.describe_actions(to_retry[1])
    assert "start Retry" not in a.describe_actions(to_end[1])


def test_grouping_shrinks_the_table() -> None:
    a = compile_text(MISSION.format(body=SAME), "m.mission")
    s, _ = a.react(0, 0)
    # one row per class of the active task (none, done, T2 class, T3 class) and the operator's Go
    # when it is listened to: not one per event
    assert len(a.table[s]) <= 4, sorted(a.table[s])


def test_a_row_with_events_of_many_classes_is_not_multiplied_out() -> None:
    body = "handle par(Move || Retry) on Move.T2.Slipped do nothing end"
    a = compile_text(MISSION.format(body=body), "m.mission")
    t3 = 0
    for m in a.program.t3_masks:
        t3 |= m
    s, _ = a.react(0, 0)
    both = next(k for k in a.table[s] if bin(k & t3).count("1") == 2)  # a type 3 of each task
    assert len(a.stands_for(both)) >= 16  # every pair of members: a handful, expanded
    assert a.stands_for(both, limit=8) == [both]  # over the limit: the row as it is
    runner = Runner(a)
    runner.react(0)
    assert runner.react(both) == a.table[s][both][1]
