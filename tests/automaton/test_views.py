"""Pictures of a mission: states named by their active tasks, boxed per task set, edges with the
inputs that take them; a large automaton drawn abstract by default."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from orccadd.automaton import compile_file
from orccadd.automaton.checks.views import TYPE_3, full_view, to_dot
from orccadd.automaton.compiler.automaton import SAFE
from orccadd.task.spec import read_task_interface
from tests.conftest import ROOT


def test_the_full_view_names_inputs_actions_and_active_tasks() -> None:
    a = compile_file(ROOT / "configs/missions/demo.mission", task_files=read_task_interface)
    labels = {lab for _, lab, _ in full_view(a).edges}
    assert "Inspect.T2.TrackingLost / stop Inspect, start Approach" in labels
    # the least input sets that take an edge, as alternatives: Reach ends on done or a type 2
    assert (
        "Reach.T2.PreconditionTimeout ∨ Reach.T2.TrackingLost ∨ Reach.done / stop Reach, start Inspect"
        in labels
    )
    assert "start Home" in labels  # taken whatever the inputs
    dot = to_dot(full_view(a), a.program.name)
    assert "subgraph cluster_" in dot and 'label="Inspect"; ' in dot
    assert '\\nReach", tooltip=' in dot  # a state shows the task active in it
    assert "shape=doublecircle" in dot and "color=red" in dot  # the end, the safe procedure


def test_without_faults_the_safe_procedure_is_reached_by_one_summed_up_edge_per_state() -> None:
    """Type 3 edges left out entirely drew the safe procedure as unreachable."""
    a = compile_file(ROOT / "configs/missions/demo.mission", task_files=read_task_interface)
    safe = {s for s in range(a.n_states) if a.phase[s] == SAFE}
    edges = full_view(a).edges
    into_safe = {(s, lab) for s, lab, t in edges if t in safe and s not in safe}
    assert into_safe and all(lab == TYPE_3 for _, lab in into_safe)
    assert len(into_safe) == len({s for s, _ in into_safe})  # one per state, not one per exception
    assert 'style=dashed color=red fontcolor=red label="type 3"' in to_dot(full_view(a), "demo")
    assert not any(lab == TYPE_3 for _, lab, _ in full_view(a, faults=True).edges)  # each named


def test_a_large_automaton_is_drawn_abstract_unless_asked(tmp_path: Path) -> None:
    mission = ROOT / "benchmarks/missions/exomars_scale.mission"

    def graph(*extra: str) -> str:
        cmd = [
            sys.executable,
            "-m",
            "orccadd.cli",
            "graph",
            str(mission),
            "-o",
            str(tmp_path / "g.dot"),
            *extra,
        ]
        r = subprocess.run(cmd, capture_output=True, text=True, timeout=120, cwd=ROOT)
        assert r.returncode == 0, r.stderr
        return r.stdout

    out = graph()
    assert "75 states: the abstract view on Drive, " in out and "(--full for all)" in out
    assert "75 states" in graph("--full").splitlines()[-1]
