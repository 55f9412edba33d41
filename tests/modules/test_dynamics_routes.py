"""Two routes agree: RNEA against M(q)·a + h(q, dq); computed torque on a perfect model tracks
a Ruckig trajectory with near-zero error."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from orccadd.model import RobotModel
from orccadd.robot import load_robot_config
from orccadd.runtime import SimClock
from orccadd.session import Session
from orccadd.types import Phase
from tests.conftest import MOVE_TASK, PANDA, UR5E


@pytest.mark.parametrize("config", [UR5E, PANDA], ids=["ur5e", "panda"])
def test_rnea_equals_mass_matrix_route(config) -> None:  # type: ignore[no-untyped-def]
    model = RobotModel.from_config(load_robot_config(config))
    data = model.new_data()
    rng = np.random.default_rng(3)
    for _ in range(20):
        q = rng.uniform(model.q_min_rad, model.q_max_rad)
        dq = rng.uniform(-model.v_max_rad_s, model.v_max_rad_s)
        a = rng.uniform(-model.a_max_rad_s2, model.a_max_rad_s2)
        tau_rnea = pin.rnea(model.model, data, q, dq, a).copy()
        M = pin.crba(model.model, data, q).copy()
        M = np.triu(M) + np.triu(M, 1).T
        h = pin.nonLinearEffects(model.model, data, q, dq).copy()
        np.testing.assert_allclose(tau_rnea, M @ a + h, rtol=1e-9, atol=1e-9)
        # and forward dynamics inverts it
        np.testing.assert_allclose(pin.aba(model.model, data, q, dq, tau_rnea), a, rtol=1e-7, atol=1e-7)


@pytest.mark.parametrize("config", [UR5E, PANDA], ids=["ur5e", "panda"])
def test_computed_torque_on_perfect_model_tracks_ruckig(config, robot_variant, tmp_path) -> None:  # type: ignore[no-untyped-def]
    text = config.read_text()
    start = text.index("viscous_friction_nm_s_rad")
    end = text.index("initial_q_rad")
    perfect = robot_variant((text[start:end], ""), base=config)  # no friction: model = plant
    s = Session.open(perfect)
    task = s.task(MOVE_TASK)
    traj = next(m for m in task.modules if m.name == "traj")
    loop = s.loop(SimClock())
    worst = 0.0

    def step(t_s: float) -> None:
        nonlocal worst
        task.tick(t_s)
        if task.phase is Phase.RUN:
            worst = max(worst, float(np.abs(traj.q_des.value - s.resource.state.q_rad).max()))

    loop.executor.step = step
    phase = loop.run_task(task, timeout_s=5.0)
    assert phase is Phase.DONE
    # Only the zero-order hold of the torque over one period separates plant and model.
    assert worst < 1e-3, worst
    s.close()
