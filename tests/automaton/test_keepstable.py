"""The seed's KEEPSTABLE procedure: every check passes, and a mutant is caught."""

from __future__ import annotations

from orccadd.automaton import compile_file, verify
from orccadd.automaton.checks.views import minimize, project
from tests.automaton.conftest import KEEPSTABLE, NO_GUARD
from tests.conftest import ROOT


def test_keepstable_passes_every_check() -> None:
    report = verify(compile_file(KEEPSTABLE))
    assert report.ok, report.format()
    names = {r.name for r in report.results}
    assert {"determinism", "deadlock", "safety", "liveness", "conflicts"} <= names
    assert "property NeverBoth" in names  # mutual exclusion, stated as an observer as well


def test_the_two_tasks_are_never_active_together() -> None:
    a = compile_file(KEEPSTABLE)
    names = [t.name for t in a.program.tasks]
    for active in a.active:
        assert len(active) <= 1, [names[t] for t in active]


def test_abstract_view_is_the_alternation_loop_with_stop_as_the_only_exit() -> None:
    a = compile_file(KEEPSTABLE)
    view = minimize(project(a, ["KeepStableCam", "KeepStableUS", "Stop"]))
    # seed figure 6: begin with KeepStableUS (arc 1), alternate (arcs 2, 3), Stop exits (arcs 4, 5)
    assert view.n == 4
    assert len(view.edges) == 5
    succ = {(s, lab): t for s, lab, t in view.edges}
    us_state = succ[(view.initial, "start(KeepStableUS)")]
    cam_state = succ[(us_state, "start(KeepStableCam)")]
    assert succ[(cam_state, "start(KeepStableUS)")] == us_state  # the alternation loop
    end = succ[(us_state, "Stop")]
    assert succ[(cam_state, "Stop")] == end  # Stop is the only way out, from either mode
    assert not [e for e in view.edges if e[0] == end]


def test_mutant_without_the_t2_guard_fails_the_conflict_check_with_a_counterexample() -> None:
    report = verify(compile_file(NO_GUARD))
    assert not report.ok
    conflict = next(r for r in report.results if r.name == "conflicts")
    assert not conflict.ok
    assert (
        "KeepStableUS and KeepStableCam" in conflict.summary
        or "KeepStableCam and KeepStableUS" in conflict.summary
    )
    text = report.format()
    assert "instant 2: inputs {KeepStableUS.T2.Stabilized}" in text
    assert "start KeepStableCam" in text


def test_counterexample_replays_to_the_conflicting_state() -> None:
    a = compile_file(NO_GUARD)
    conflict = next(r for r in verify(a).results if r.name == "conflicts")
    s = 0
    for step in conflict.counterexample:
        s, actions = a.react(s, step.inputs)
        assert actions == step.actions
    assert len(a.active[s]) == 2


def test_exomars_scale_mission_passes_every_check() -> None:
    path = ROOT / "benchmarks" / "missions" / "exomars_scale.mission"  # no task files: a scale test
    a = compile_file(path)
    assert len(a.program.tasks) == 12
    assert _task_activations(a.program.main) == 63  # the seed's ExoMars: 63 actions in 12 tasks
    report = verify(a)
    assert report.ok, report.format()


def _task_activations(t: object) -> int:
    from orccadd.automaton.language import kernel as K

    if isinstance(t, K.Run):
        return 1
    if isinstance(t, K.Seq):
        return sum(_task_activations(x) for x in t.items)
    if isinstance(t, K.Par):
        return sum(_task_activations(b) for b in t.branches)
    if isinstance(t, K.Abort | K.Trap | K.Loop):
        return _task_activations(t.body)
    if isinstance(t, K.Present):
        return _task_activations(t.then) + _task_activations(t.orelse)
    if isinstance(t, K.Handle):
        return _task_activations(t.body) + sum(_task_activations(h) for h in t.handlers)
    return 0
