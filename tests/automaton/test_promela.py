"""The table-replay Promela model and the reading of spin's verdicts. spin's runs, for both models
and every mission, are in test_promela_structure.py."""

from __future__ import annotations

import shutil

import pytest

from orccadd.automaton import compile_file, verify
from orccadd.automaton.promela.export import export_promela
from orccadd.automaton.promela.spin import c_compiler, check_name, parse_pan, run_spin
from orccadd.errors import OrccaddError
from tests.automaton.conftest import KEEPSTABLE, NO_GUARD, UNHANDLED_T3

PAN_OUTPUT = """pan:1: assertion violated ok_conflicts (at depth 9)
pan:2: assertion violated ok_prop0_NeverBoth (at depth 9)
pan:3: invalid end state (at depth 12)

(Spin Version 6.5.2 -- 6 December 2019)
	invalid end states	+

State-vector 44 byte, depth reached 20, errors: 3
       42 states, stored
"""


def test_pan_output_gives_the_verdict_of_each_check() -> None:
    v = parse_pan(PAN_OUTPUT)
    assert not v.ok and v.errors == 3 and v.states_stored == 42
    assert v.failed == {"conflicts", "property NeverBoth"}
    assert v.passed("safety") and not v.passed("conflicts")
    assert v.invalid_ends == 1
    assert check_name("prop12_A_b") == "property A_b"
    with pytest.raises(OrccaddError, match="cut short"):
        parse_pan("error: max search depth too small\nerrors: 0\n")


def test_the_table_model_asserts_each_check_by_name() -> None:
    model = export_promela(compile_file(KEEPSTABLE))
    for bit in ("ok_safety", "ok_conflicts", "ok_prop0_NeverBoth", "ok_prop2_StartsAndStopsAlternate"):
        assert f"assert({bit})" in model
    assert "Not exported: EveryStartIsStopped" in model
    only = export_promela(compile_file(KEEPSTABLE), ("safety",))
    assert "assert(ok_safety)" in only and "assert(ok_conflicts)" not in only


def test_the_failing_missions_do_fail_somewhere() -> None:
    # guard against an agreement that is only ever "ok": each failing mission fails the expected check
    assert verify(compile_file(NO_GUARD)).failed("conflicts")
    assert verify(compile_file(UNHANDLED_T3)).failed("safety")


@pytest.mark.skipif(shutil.which("spin") is None or c_compiler() is None, reason="needs spin, a C compiler")
def test_a_model_spin_cannot_parse_is_an_error() -> None:
    with pytest.raises(OrccaddError, match="spin -a model.pml failed"):
        run_spin("active proctype p() { x = 1 }")
