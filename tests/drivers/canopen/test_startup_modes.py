"""The master and the drive's supported drive modes (0x6502), against strict simulated drives."""

from __future__ import annotations

from pathlib import Path

import pytest

from orccadd.errors import ResourceError
from orccadd.physres.canopen402 import Canopen402Arm
from orccadd.robot import create_resource, load_robot_config
from tests.canopen_rig import canopen_rig, consuming_elmo, edit_dcf


def test_a_drive_whose_0x6502_lacks_the_mode_is_refused_naming_it(tmp_path: Path) -> None:
    """The drive's own 0x6502 read at configure, before 0x6060 is written (the drive would abort
    that write, 0x06090030): the error names the node, the value and the mode."""
    dcf = edit_dcf(
        consuming_elmo(tmp_path), tmp_path / "Elmo-no-csp.dcf", {"6502": {"DefaultValue": "0x300"}}
    )
    with canopen_rig(tmp_path, dcf) as rig:
        arm = create_resource(load_robot_config(rig.config))
        assert isinstance(arm, Canopen402Arm)
        try:
            with pytest.raises(ResourceError) as e:
                arm.configure()
        finally:
            arm.shutdown()
    assert str(e.value) == (
        "node 1 (shoulder_pan_joint): the drive reports supported drive modes 0x300 (0x6502) without "
        "csp: it cannot run this config"
    )
