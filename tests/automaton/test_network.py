"""A `par` of independent branches compiled as a network (network.py): it reacts as the one
explicit automaton does, its verdicts are never laxer, and the scale target compiles."""

from __future__ import annotations

import random
from pathlib import Path

import pytest

from orccadd.automaton import (
    Network,
    NetworkRunner,
    Runner,
    compile_file,
    compile_text,
    elaborate,
    parse_mission,
    verify,
    verify_network,
)
from orccadd.automaton.checks.interpreter import Interpreter
from orccadd.automaton.compiler.explicit import compile_program
from orccadd.automaton.compiler.network import compile_mission, find_split
from orccadd.automaton.language.program import Program
from orccadd.errors import MissionError
from tests.automaton.conftest import two_branch_network
from tests.automaton.random_par import random_mission

ROOT = Path(__file__).resolve().parents[2]
TEN = ROOT / "benchmarks" / "missions" / "concurrent10.mission"
SEVERITY = {"note": 1, "warning": 2, "error": 3}


def programs(seeds: range, branches: int = 3, depth: int = 3) -> list[tuple[int, Program]]:
    out = []
    for seed in seeds:
        try:
            out.append((seed, elaborate(parse_mission(random_mission(seed, branches, depth), "r.mission"))))
        except MissionError:
            continue  # the generator writes some missions the elaborator refuses (`on fatal` with no task)
    return out


def random_inputs(rng: random.Random, p: Program, active: tuple[int, ...]) -> int:
    inputs = 0
    for t in set(active):
        if rng.random() < 0.35:
            inputs |= rng.choice(p.tasks[t].events)[2]
    for i, kind in enumerate(p.input_kind):
        if kind == "operator" and rng.random() < 0.25:
            inputs |= 1 << i
    return inputs


@pytest.mark.parametrize(("branches", "depth", "seeds"), [(3, 3, 20), (2, 5, 20), (4, 2, 5)])
def test_the_network_reacts_as_the_product(branches: int, depth: int, seeds: int) -> None:
    compared = 0
    for seed, p in programs(range(seeds), branches, depth):
        try:
            a = compile_program(p, max_states=20_000)
        except MissionError:
            continue
        net = compile_mission(p, threshold=0)  # a network whenever the par splits
        assert isinstance(net, Network), seed
        rng = random.Random(seed)
        for _ in range(12):
            explicit, network = Runner(a), NetworkRunner(net)
            for instant in range(12):
                assert sorted(set(network.active())) == sorted(set(a.active[explicit.state]))
                inputs = random_inputs(rng, p, a.active[explicit.state])
                want, got = explicit.react(inputs), network.react(inputs)
                assert got == want, (seed, instant, a.describe_actions(want), a.describe_actions(got))
        compared += 1
    assert compared >= seeds * 2 // 3


def _worst(report_results: list, name: str) -> int:  # type: ignore[type-arg]
    return max((SEVERITY[r.level] for r in report_results if r.name == name and not r.ok), default=0)


def test_network_verdicts_are_never_laxer_than_the_products() -> None:
    """Every check fails in the network at least as severely as in the one automaton, and the
    mission's verdict (accepted or refused) is the same on these missions."""
    compared = 0
    for seed, p in programs(range(35)):
        try:
            explicit = verify(compile_program(p, max_states=20_000))
        except MissionError:
            with pytest.raises(MissionError):  # not causal where the mission gets: refused too
                net = compile_mission(p, threshold=0)
                assert isinstance(net, Network)
                verify_network(net)
            continue
        net = compile_mission(p, threshold=0)
        assert isinstance(net, Network)
        network = verify_network(net)
        for r in explicit.results:
            assert _worst(network.results, r.name) >= _worst(explicit.results, r.name), (seed, r.name)
        assert network.ok == explicit.ok, seed
        compared += 1
    assert compared >= 25


def test_the_scale_target_compiles_and_verifies_as_a_network() -> None:
    net = compile_file(TEN, allow_network=True)
    assert isinstance(net, Network)
    assert len(net.branches) == 10 and net.product_states > 10**8
    assert net.n_states < 100  # ten automata of 7 states and the context's 4
    report = verify_network(net)
    assert report.ok, report.format()
    assert "a network" in report.format()
    # not allowed a network, the one automaton is refused, naming the way out
    with pytest.raises(MissionError, match="allow_network=True"):
        compile_file(TEN)


def test_a_failure_in_one_branch_names_its_product_and_replays_as_a_run() -> None:
    bare = TEN.read_text().replace("  on fatal do\n    safe\n", "  on T0_0.E0 do\n    safe\n")
    net = compile_text(bare, "c.mission", allow_network=True)
    assert isinstance(net, Network)
    report = verify_network(net)
    safety = next(r for r in report.results if r.name == "safety")
    assert not safety.ok and "branch" in safety.summary and safety.automaton is not None
    # the counterexample is a run of the mission: the network reaches the unhandled exception
    runner = NetworkRunner(net)
    p, ctx = net.program, net.context
    actions = 0
    for step in safety.counterexample:
        actions = runner.react(step.inputs & ((1 << len(p.inputs)) - 1))  # the stand-in's inputs left out
    last = safety.counterexample[-1].inputs
    assert last & p.t3_masks[p.tasks.index(next(t for t in p.tasks if t.name == "T0_0"))]
    assert ctx.stops(actions) & 1 and not actions & ctx.safe_bit  # T0_0 stopped, no safe procedure
    assert not report.ok


def _program(main: str) -> Program:
    text = (
        "mission M\nresource R1, R2\ninput I, J\nsignal S\n"
        "task A on R1\n  post\nend\ntask B on R2\n  post\nend\ntask C on R1\n  post\nend\n"
        f"safe procedure Safe1\n  nothing\nend\nmain procedure P\n  {main}\nend\n"
    )
    return elaborate(parse_mission(text, "m.mission"))


def test_what_does_not_split() -> None:
    assert find_split(_program("par(A || B)")) is not None
    assert find_split(_program("par(A || await I; C)")) is None  # A and C claim R1
    assert find_split(_program("par(await I; A || await I; B)")) is None  # both react to I
    assert find_split(_program("par(A; emit S || await S; B)")) is None  # a signal crosses
    assert find_split(_program("par(A || B); present S then nothing end")) is not None
    assert find_split(_program("par(A || await pre(I); B)")) is None  # pre(S): memory in the states
    # a branch waiting for a task that runs beside the par, not in it
    assert find_split(_program("par(par(await C.done || B) || C)")) is None
    assert find_split(_program("C; par(await immediate C.done; A || B)")) is None  # C ends as it starts


def test_a_par_in_a_loop_splits_unless_it_restarts_in_the_instant_it_ends() -> None:
    # ended and started again in one instant: the context would step it twice, one automaton
    assert not isinstance(compile_mission(_program("loop par(A || B) end"), threshold=0), Network)
    assert isinstance(compile_mission(_program("loop await I; par(A || B) end"), threshold=0), Network)
    # killed and started afresh in one instant (a loop around a preemption) splits, and reacts as
    # the one automaton: the new A sees the event the old one raised in that instant
    p = _program("loop do par(handle A on A.done do nothing end || B); await I until J end")
    net, a = compile_mission(p, threshold=0), compile_program(p)
    assert isinstance(net, Network)
    explicit, network = Runner(a), NetworkRunner(net)
    j, a_done = p.input_bit("J"), p.input_bit("A.done")
    for inputs in (0, 0, j | a_done, 0, a_done, j):
        assert network.react(inputs) == explicit.react(inputs)


def test_the_dual_arm_station_is_a_network_that_passes_and_runs_as_its_product() -> None:
    """Five cycles (two arms, a gripper, a camera, a conveyor); the safe procedure homes both
    arms with tasks the branches also run (their events are then the context's)."""
    cell = ROOT / "benchmarks" / "missions" / "dual_arm_station.mission"
    net = compile_file(cell, allow_network=True)
    assert isinstance(net, Network) and len(net.branches) == 5
    report = verify_network(net)
    assert report.ok, report.format()
    p = net.program
    rng = random.Random(7)
    for _ in range(15):  # against the reference interpreter (the product takes minutes to build)
        reference, network = Interpreter(p), NetworkRunner(net)
        for _ in range(25):
            inputs = random_inputs(rng, p, tuple(reference.active))
            assert network.react(inputs) == reference.react(inputs)
            assert sorted(network.active()) == sorted(reference.active)


def test_inputs_outside_the_model_are_reduced_as_the_one_automaton_reduces_them() -> None:
    """Any input bits at all (events of tasks not running, several events of one task): the
    network never raises and reacts as the one automaton (`Automaton.normalize`)."""
    compared = 0
    for seed, p in programs(range(12)):
        try:
            a = compile_program(p, max_states=20_000)
        except MissionError:
            continue
        net = compile_mission(p, threshold=0)
        assert isinstance(net, Network)
        rng = random.Random(seed)
        for _ in range(10):
            explicit, network = Runner(a), NetworkRunner(net)
            for _ in range(10):
                n = len(p.inputs)
                inputs = rng.getrandbits(n) & rng.getrandbits(n) & rng.getrandbits(n)
                assert network.react(inputs) == explicit.react(inputs), seed
        compared += 1
    assert compared >= 8


def test_a_counterexample_through_the_stand_in_says_what_it_abstracts() -> None:
    """Branch 2 halts after thirty-four tasks and an operator input: the product with branch 1
    shows its stand-in going idle in one of the product's instants; the counterexample says what
    that means and the run branch 2 needs to get there (its own instants, not the product's)."""
    text = two_branch_network("await Go; halt")
    net = compile_text(text, "idle.mission", allow_network=True)
    assert isinstance(net, Network)
    deadlock = next(r for r in verify_network(net).results if r.name == "deadlock")
    assert not deadlock.ok and "(branch 2 of the par at line 13).idle" in deadlock.explanation
    assert "branch 2 gets there after 36 instants of its own: {}, then {T1.done} ×34, then {Go}" in (
        deadlock.explanation
    ), deadlock.explanation
