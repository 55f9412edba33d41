"""The structural spin model (written from the program's statements) against the table-replay model
and the verifier: on every mission shipped or under tests/, the verdict of each exported check is
the same three ways, and the lockstep model (both in one, spin asserting that they react alike in
every reachable instant) holds. The mutants fail, so a model that always passes is caught."""

from __future__ import annotations

import dataclasses
import re
import shutil
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from types import MappingProxyType

import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from orccadd.automaton import Automaton, compile_file, compile_text, verify
from orccadd.automaton.language import kernel as K
from orccadd.automaton.promela.export import export_model
from orccadd.automaton.promela.props import PROPERTIES, exported_checks
from orccadd.automaton.promela.spin import SpinVerdict, c_compiler, run_spin
from orccadd.automaton.promela.structure import Names, export_structure
from orccadd.errors import MissionError, OrccaddError
from orccadd.task.spec import read_task_interface
from tests.automaton.conftest import KEEPSTABLE, MISSIONS, NO_GUARD, TEST_MISSIONS, UNHANDLED_T3

HAVE_SPIN = shutil.which("spin") is not None and c_compiler() is not None
needs_spin = pytest.mark.skipif(not HAVE_SPIN, reason="spin and a C compiler are installed by make setup")

ALL_MISSIONS = sorted([*MISSIONS.glob("*.mission"), *TEST_MISSIONS.rglob("*.mission")])
MODELS = ("structure", "table", "lockstep")
SEMANTICS = TEST_MISSIONS / "semantics"


def _id(path: Path) -> str:
    return str(path.relative_to(path.parents[1]))


@pytest.fixture(scope="module")
def compiled() -> dict[Path, Automaton | str]:
    """Each mission compiled, or why the compiler refuses it (then there is nothing to compare)."""
    out: dict[Path, Automaton | str] = {}
    for path in ALL_MISSIONS:
        try:
            out[path] = compile_file(path, task_files=read_task_interface)
        except MissionError as e:
            out[path] = str(e)
    return out


@pytest.fixture(scope="module")
def spin(compiled: dict[Path, Automaton | str]) -> dict[tuple[Path, str], SpinVerdict]:
    """Every model of every mission through spin, two at a time (mostly the C compile: tcc's 0.05 s,
    gcc's 0.3-1.7 s)."""
    jobs = {
        (path, model): export_model(a, model)
        for path, a in compiled.items()
        if isinstance(a, Automaton)
        for model in MODELS
    }
    with ThreadPoolExecutor(max_workers=2) as pool:
        results = dict(zip(jobs, pool.map(run_spin, jobs.values()), strict=True))
    return results


@needs_spin
@pytest.mark.parametrize("path", ALL_MISSIONS, ids=_id)
def test_spin_agrees_with_the_verifier_both_ways(
    path: Path, compiled: dict[Path, Automaton | str], spin: dict[tuple[Path, str], SpinVerdict]
) -> None:
    a = compiled[path]
    if not isinstance(a, Automaton):
        pytest.skip("refused by the compiler: " + re.sub(r"^.*?:\d+:\d+: ", "", a.splitlines()[0])[:80])
    report = verify(a)
    for model in MODELS:
        v = spin[(path, model)]
        assert v.invalid_ends == 0, f"{model}: the model blocked\n{v.output[-2000:]}"
        assert v.states_stored > 0
        for check in exported_checks(a.program, PROPERTIES):
            ours = not report.failed(check)
            assert v.passed(check) == ours, f"{model}: {check}: spin {v.passed(check)}, verify {ours}"
    lockstep = spin[(path, "lockstep")]
    assert lockstep.passed("lockstep"), f"the compiler and the structure differ\n{lockstep.output[-2000:]}"


@needs_spin
def test_the_mutants_fail_in_spin(spin: dict[tuple[Path, str], SpinVerdict]) -> None:
    """Agreement on "ok" alone would not show much: each mutant fails its check in both models."""
    for model in ("structure", "table"):
        assert "conflicts" in spin[(NO_GUARD, model)].failed
        assert "property NeverBoth" in spin[(NO_GUARD, model)].failed
        assert "safety" in spin[(UNHANDLED_T3, model)].failed
        assert "safety" in spin[(SEMANTICS / "nested.mission", model)].failed
        assert not spin[(KEEPSTABLE, model)].failed
    failing = {check for path in SEMANTICS.glob("*.mission") for check in spin[(path, "structure")].failed}
    assert {"property BusyNever", "property WeakNever", "property BStopsFirst"} <= failing


@needs_spin
def test_lockstep_catches_a_table_that_differs() -> None:
    """Drop one start action from KEEPSTABLE's compiled table: the lockstep model must fail."""
    a = compile_file(KEEPSTABLE)
    rows = [dict(r) for r in a.table]
    key, (n, actions) = next((k, v) for k, v in rows[0].items() if a.starts(v[1]))
    rows[0][key] = (n, actions & ~(((1 << len(a.program.tasks)) - 1) << a.start_base))
    broken = dataclasses.replace(a, table=tuple(MappingProxyType(r) for r in rows))
    v = run_spin(export_model(broken, "lockstep"))
    assert "lockstep" in v.failed


RANDOM_HEADER = """mission R
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
safe procedure Rescue
  await I
end
"""
LEAVES = ["A", "B", "pause", "nothing", "emit S", "emit U", "await I", "await immediate J", "await A.done",
          "await B.Half", "safe", "halt"]  # fmt: skip
CONDS = ["I", "J", "S", "U", "Fail", "I or S", "not J", "I and U", "Boom"]


def statements(depth: int) -> st.SearchStrategy[str]:
    leaf = st.sampled_from(LEAVES)
    if depth == 0:
        return leaf
    part = {"s": statements(depth - 1), "c": st.sampled_from(CONDS)}
    forms = [
        ("ss", "{}; {}"), ("ss", "par({} || {})"), ("sc", "do {} until {}"), ("sc", "weak do {} until {}"),
        ("s", "loop {}; pause end"), ("css", "present {} then {} else {} end"), ("cs", "every {} do {} end"),
        ("sc", "trap T in par({} || await {}; exit T) end"), ("ss", "handle {} on fatal do {} end"),
        ("scs", "handle {} on {} do {} end"),
    ]  # fmt: skip
    return st.one_of(leaf, *(st.tuples(*(part[k] for k in kinds)).map(_fill(f)) for kinds, f in forms))


def _fill(form: str) -> Callable[[tuple[str, ...]], str]:
    return lambda parts: form.format(*parts)


@needs_spin
@settings(
    max_examples=3, deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much]
)
@given(statements(3))
def test_random_programs_react_alike_in_lockstep(main: str) -> None:
    """A few random programs each run (a campaign of 866, nested 3 and 4 deep, found no difference)."""
    try:
        a = compile_text(RANDOM_HEADER + f"main procedure Main\n  {main}\nend\n", max_states=2000)
    except MissionError:  # not causal, a nested trap T, an instantaneous loop, too big...
        assume(False)
        return
    v = run_spin(export_model(a, "lockstep"))
    assert v.passed("lockstep") and v.invalid_ends == 0, main + "\n" + v.output[-2000:]


# the model's text: no spin needed ---------------------------------------------------------------------


def test_a_process_per_parallel_branch_and_classes_of_events() -> None:
    a = compile_file(KEEPSTABLE)
    model = export_structure(a.program)
    assert "active proctype b1()" in model and "active proctype b2()" in model
    assert "active proctype b3()" not in model
    names = Names(a.program)
    # KeepStableUS: its T2, and its six type 3 exceptions (tested by `fatal` only) as one choice
    assert [(c.kind, c.bits.bit_count()) for c in names.classes[0]] == [("T2", 1), ("T3", 6)]
    assert "EveryStartIsStopped (`-> eventually`" in model  # said, not silently dropped


def test_internal_signals_are_guessed_and_checked_per_instant() -> None:
    a = compile_file(SEMANTICS / "signals.mission")
    model = export_structure(a.program)
    assert "inline resolve_Busy()" in model
    assert "goto end_discard" in model


SMALL = """mission M
resource R
input Go
task A on R
  post
end
main procedure P
  handle A on fatal do safe end
end
safe procedure S
  nothing
end
"""


def test_a_property_about_an_input_is_left_to_the_table_model() -> None:
    a = compile_text(SMALL + "property NoGo: never Go\n")
    with pytest.raises(
        OrccaddError, match=r"property NoGo \(line 13\): it mentions the input Go.*--model table"
    ):
        export_structure(a.program)
    assert "ok_prop0_NoGo" in export_model(a, "table")
    assert "ok_prop0_NoGo" not in export_structure(a.program, ("safety", "conflicts"))


def test_a_construct_the_model_does_not_cover_is_refused_by_name() -> None:
    a = compile_text(SMALL)
    p = dataclasses.replace(a.program, main=K.Running(0, a.program.tasks[0].loc))
    with pytest.raises(OrccaddError, match="does not cover a task already running.*--model table"):
        export_structure(p)
    with pytest.raises(OrccaddError, match="unknown model 'graph'"):
        export_model(a, "graph")
    with pytest.raises(OrccaddError, match="unknown property 'liveness'"):
        export_structure(a.program, ("liveness",))
