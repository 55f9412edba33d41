"""Control-law modules driven directly (no resource): the torque blend cross-fades two laws."""

from __future__ import annotations

import numpy as np
import pytest

from orccadd.errors import ParameterError
from orccadd.model import RobotModel
from orccadd.modules import ModuleContext
from orccadd.modules.control import TorqueBlend
from orccadd.robot import load_robot_config
from tests.conftest import UR5E

CTX = ModuleContext("T", RobotModel.from_config(load_robot_config(UR5E)), 0.002)


@pytest.mark.parametrize("weight", [0.0, 0.25, 1.0])
def test_the_blend_is_law_a_then_law_b_as_the_weight_goes_from_0_to_1(weight: float) -> None:
    blend = TorqueBlend("blend", CTX)
    blend.configure({"weight": weight})
    a, b = np.arange(6.0), -2.0 * np.arange(6.0)
    blend.tau_a.value[:], blend.tau_b.value[:] = a, b
    blend.update(0.0)
    assert np.allclose(blend.tau.value, (1 - weight) * a + weight * b, rtol=0, atol=1e-12)
    # the same kernel runs in the compiled tick
    (tau,) = blend.kernel()(0.0, a.tolist(), b.tolist())
    assert tau == blend.tau.value.tolist()


def test_a_weight_outside_0_1_is_refused() -> None:
    with pytest.raises(ParameterError, match=r"blend.weight \(=1.5\) must be in \[0, 1\]"):
        TorqueBlend("blend", CTX).configure({"weight": 1.5})
