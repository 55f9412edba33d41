"""Missions that wait for each other across daemons: the split hand-over (configs/missions/
cell_handover_a/b.mission) on two daemons of a cell, each a separate process on a simulated arm,
to success on both; arm A's daemon killed while B waits for it → B's `on lost` branch, its arm held."""

from __future__ import annotations

import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.cellnet.conftest import Member, start_member

ROOT = Path(__file__).resolve().parents[2]
MISSIONS = ROOT / "configs/missions"


@pytest.fixture
def pair(tmp_path: Path, certs: Path) -> Iterator[tuple[Member, Member]]:
    members: list[Member] = []
    try:
        a = start_member(tmp_path, "test", "arm-a", certs, [], control=("console", "arm-b"))
        members.append(a)
        b = start_member(tmp_path, "test", "arm-b", certs, [a.endpoint], control=("console", "arm-a"))
        members.append(b)
        yield a, b
    finally:
        for m in members:
            m.daemon.stop()


def load_and_start(m: Member, mission: str) -> None:
    m.daemon.call("load", path=str(MISSIONS / mission))
    m.daemon.call("start")


def ended(status: dict[str, object]) -> bool:
    return status["state"] == "ready" and status["result"] != "none"


def events(m: Member) -> list[dict[str, object]]:
    return list(m.daemon.call("events", last=200)["events"])


def test_the_split_handover_runs_to_success_on_both(pair: tuple[Member, Member]) -> None:
    a, b = pair
    load_and_start(b, "cell_handover_b.mission")  # B waits for A's PartPlaced
    load_and_start(a, "cell_handover_a.mission")
    for m in (a, b):
        m.daemon.wait(ended, timeout_s=90)
        assert m.daemon.status()["result"] == "success", m.daemon.log_text(4000)
    took = [e for e in events(b) if e.get("inputs") == ["PartPlaced"]]
    assert len(took) == 1  # one instant, once
    took = [e for e in events(a) if e.get("inputs") == ["PartTaken"]]
    assert len(took) == 1


def test_a_peer_killed_mid_mission_takes_the_other_to_its_lost_branch(pair: tuple[Member, Member]) -> None:
    a, b = pair
    load_and_start(b, "cell_handover_b.mission")
    deadline = time.monotonic() + 60
    while not any("stop Home" in e.get("actions", []) for e in events(b)):  # type: ignore[operator]
        assert time.monotonic() < deadline, events(b)
        time.sleep(0.05)
    time.sleep(0.3)  # B waits at `await PartPlaced`, its arm held at Home
    killed_s = time.time()
    a.daemon.kill()
    b.daemon.wait(ended, timeout_s=30)
    lost = [e for e in events(b) if e.get("inputs") == ["lost_arm_a"]]
    assert len(lost) == 1, events(b)
    assert float(lost[0]["wall_s"]) - killed_s < 1.0  # its liveliness token went with its process
    st = b.daemon.status()
    assert st["result"] == "safe" and not st["faulted"], st
    q0 = [j["q_rad"] for j in st["joints"]]
    time.sleep(0.5)
    q1 = [j["q_rad"] for j in b.daemon.status()["joints"]]
    assert max(abs(x - y) for x, y in zip(q0, q1, strict=True)) < 1e-3  # held where it was
