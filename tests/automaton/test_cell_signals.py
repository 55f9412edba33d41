"""Signals across PCs in the language: `input X from "peer"`, `output Y to cell`, `lost "peer"`;
the check that a wait for a peer handles its loss; the errors, each at its place."""

from __future__ import annotations

import pytest

from orccadd.automaton import Runner, compile_text, verify
from orccadd.errors import MissionError

HEAD = """
mission M
resource arm
input Stop
input Placed from "arm-a"
output Taken to cell
"""
SAFE = """
safe procedure Rest
  nothing
end
"""


def mission(body: str, head: str = HEAD) -> str:
    return head + "main procedure Main\n" + body + "\nend\n" + SAFE


HANDLED = mission("""
  handle
    do
      await Placed; emit Taken
    until Stop
  on lost "arm-a" do
    safe
  end""")


def test_a_peers_signal_and_its_loss_are_inputs_and_an_output_is_an_internal_signal() -> None:
    a = compile_text(HANDLED, "m.mission")
    p = a.program
    assert p.remote_inputs == (("Placed", "arm-a"),)
    assert p.lost_inputs == (("lost_arm_a", "arm-a"),)
    assert p.cell_outputs == ("Taken",)
    assert dict(zip(p.inputs, p.input_kind, strict=True))["Placed"] == "operator"  # any instant, or never
    assert verify(a).ok
    r = Runner(a)
    r.react(0)
    assert "emit Taken" in a.describe_actions(r.react(p.input_bit("Placed")))


def test_the_loss_of_the_peer_takes_its_handler() -> None:
    a = compile_text(HANDLED, "m.mission")
    r = Runner(a)
    r.react(0)
    assert r.react(a.program.input_bit("lost_arm_a")) & a.safe_bit


def test_a_wait_for_a_peer_without_its_loss_handled_is_refused_with_the_path() -> None:
    report = verify(compile_text(mission("  do\n    await Placed; emit Taken\n  until Stop"), "m.mission"))
    r = next(x for x in report.results if x.name == "peer loss")
    assert not r.ok and 'Placed from "arm-a"' in r.summary and r.counterexample, r
    assert 'on lost "arm-a"' in r.explanation


def test_a_loss_handled_only_around_part_of_the_wait_is_refused() -> None:
    body = """
  do
    handle
      await Placed
    on lost "arm-a" do
      nothing
    end;
    await Placed
  until Stop"""
    report = verify(compile_text(mission(body), "m.mission"))
    assert report.failed("peer loss")


def test_lost_of_a_peer_the_mission_takes_nothing_from_is_an_input_too() -> None:
    head = "mission M\nresource arm\ninput Stop\n"
    a = compile_text(mission('  do\n    await lost "cam-1"\n  until Stop', head), "m.mission")
    assert a.program.lost_inputs == (("lost_cam_1", "cam-1"),)
    assert not a.program.remote_inputs and verify(a).ok


@pytest.mark.parametrize(
    ("text", "words"),
    [
        (mission("  nothing", HEAD.replace("to cell", "to arm")), "an output goes `to cell`"),
        (mission("  nothing", HEAD.replace('"arm-a"', '"arm a"')), "must be a daemon's name"),
        (mission("  nothing", HEAD + 'input arm.x from "arm-b"\n'), "an input from a peer is a plain name"),
        (mission("  nothing", HEAD + "signal Taken\n"), "already declared"),
        (mission("  nothing", HEAD + "input lost_arm_a\n"), "already declared"),
        (mission('  await lost "arm-a" and lost "arm_a"'), "cannot both be told apart"),
    ],
)
def test_mistakes_are_refused_at_their_place(text: str, words: str) -> None:
    with pytest.raises(MissionError, match=words):
        compile_text(text, "m.mission")
