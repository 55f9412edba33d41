"""spin agrees with our safety and conflict verdicts, on passing and failing missions."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from orccadd.automaton import compile_file, verify
from orccadd.automaton.promela import export_promela, run_spin
from tests.automaton.conftest import KEEPSTABLE, NO_GUARD, UNHANDLED_T3

pytestmark = pytest.mark.skipif(
    shutil.which("spin") is None or shutil.which("gcc") is None,
    reason="spin and gcc are installed by make setup",
)


@pytest.mark.parametrize("mission", [KEEPSTABLE, NO_GUARD, UNHANDLED_T3], ids=lambda p: Path(p).stem)
@pytest.mark.parametrize("prop", ["safety", "conflicts"])
def test_spin_agrees_with_our_verdict(mission: Path, prop: str) -> None:
    a = compile_file(mission)
    ours = not verify(a).failed(prop)
    theirs = run_spin(export_promela(a, (prop,)))
    assert theirs.ok == ours, theirs.output[-2000:]
    assert theirs.states_stored > 0


def test_the_failing_missions_do_fail_somewhere() -> None:
    # guard against an agreement that is only ever "ok": each failing mission fails the expected check
    assert verify(compile_file(NO_GUARD)).failed("conflicts")
    assert verify(compile_file(UNHANDLED_T3)).failed("safety")
