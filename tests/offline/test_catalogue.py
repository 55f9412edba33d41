"""`orccadctl modules`: every registered module type with its ports and parameters."""

from __future__ import annotations

from orccadd.cli import orccadctl_main
from orccadd.modules import MODULES
from orccadd.offline.catalogue import catalogue


def test_every_module_type_is_listed_with_ports_and_parameters() -> None:
    text = catalogue("sim-panda")
    assert "sized for panda (7 joints)" in text
    for name in MODULES:
        assert f"\n{name}: " in text
    assert "    in  q                7        rad" in text  # ports sized for the robot
    assert "    kp                   default 400            in [0, 100000] 1/s^2  (7, tunable)" in text


def test_the_command_line_prints_it(capsys: object) -> None:
    assert orccadctl_main(["modules", "--config", "sim-ur5e"]) == 0
    out = capsys.readouterr().out  # type: ignore[attr-defined]
    assert out.startswith("modules (") and "hold_position:" in out
