"""`orccadctl check --config ROBOT` and the daemon's `load` give the same verdict on every mission:
the good ones pass both, every bad one of the test suite fails both (a new user was told `ok` by
`check` for missions `load` then refused)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest

from orccadd.cli import orccadctl_main
from orccadd.daemon.machine import Machine
from orccadd.daemon.replies import CommandError
from tests.daemon.conftest import ROBOT, ROOT, load_in

DEMO = (ROOT / "configs/missions/demo.mission").read_text().replace('"../tasks/', f'"{ROOT}/configs/tasks/')
HOME_GOAL = "set traj.target_rad = [0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0]"


def variant(old: str, new: str) -> Callable[[], str]:
    def text() -> str:
        assert old in DEMO, old
        return DEMO.replace(old, new, 1)

    return text


MISSIONS: dict[str, Callable[[], str]] = {
    "the demo": lambda: DEMO,
    "a misspelt parameter": variant("set lost.threshold_rad", "set lost.treshold_rad"),
    "three numbers for six joints": variant(HOME_GOAL, "set traj.target_rad = [0.0, -1.5708, 1.5708]"),
    "an elbow target beyond its limit": variant(HOME_GOAL, HOME_GOAL.replace(", 1.5708,", ", 4.2,", 1)),
    "a parameter out of bounds": variant("set lost.threshold_rad = ", "set lost.threshold_rad = -"),
    "an infinite parameter": variant(HOME_GOAL, HOME_GOAL.replace("0.0]", "inf]")),
    "a task file that does not exist": variant(f'"{ROOT}/configs/tasks/', f'"{ROOT}/configs/nosuch/'),
    **{
        f"tests/automaton/missions/{p.relative_to(ROOT / 'tests/automaton/missions')}": p.read_text
        for p in sorted((ROOT / "tests/automaton/missions").rglob("*.mission"))
    },
}


def check_passes(path: Path) -> bool:
    return orccadctl_main(["check", str(path), "--config", str(ROBOT)]) == 0


def load_passes(machine: Machine, path: Path) -> bool:
    try:
        load_in(machine, path)
    except CommandError:
        return False
    return True


@pytest.mark.parametrize("name", list(MISSIONS))
def test_check_and_load_give_the_same_verdict(
    name: str, machine: Machine, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "m.mission"
    path.write_text(MISSIONS[name]())
    checked = check_passes(path)
    out = capsys.readouterr().out
    loaded = load_passes(machine, path)
    assert checked == loaded, f"check {'passes' if checked else 'fails'}, load does not agree\n{out}"
    if name == "the demo":
        assert checked  # the good one passes both
    elif not name.startswith("tests/"):
        assert not checked  # each made-bad one fails both
