"""Force mode, freedrive, tool contact, payload, TCP offset and the speed slider, through the
control script's registers on simulated time (`test_controller.py`'s way), with a wall and
pushes in the controller's world."""

from __future__ import annotations

import numpy as np
import pytest

from orccadd.ursim.controller import UrController
from orccadd.ursim.force_mode import ForceModeArgs, force_mode_error
from orccadd.ursim.states import RuntimeState, SafetyMode
from orccadd.ursim.task_frame import task_rotation
from orccadd.ursim.world import push_from_params, wall_from_params
from tests.ursim.conftest import Clocked
from tests.ursim.test_controller import command, start_script

FORCE_MODE, FORCE_MODE_STOP, ZERO_FTSENSOR, SET_PAYLOAD, TEACH_MODE = 6, 7, 8, 17, 18
SET_DAMPING, TOOL_CONTACT, SET_TCP, FREEDRIVE, END_FREEDRIVE, MOVEJ, SPEEDJ = 20, 25, 29, 52, 53, 1, 9
DOWN_10N = [0, 0, 0, 0, 0, 0, 0, 0, -10, 0, 0, 0, 0.1, 0.1, 0.1, 0.1, 0.1, 0.1]  # frame, wrench, limits
Z_ONLY = [2, 0, 0, 1, 0, 0, 0]  # type 2, selection: z compliant


def clear(clocked: Clocked) -> None:
    """The client clears a finished command (id 0), as ur_rtde does after "done"."""
    command(clocked.ctl, 0)
    clocked.run(0.01)


def started(clocked: Clocked) -> UrController:
    ctl = clocked.ctl
    start_script(ctl)
    clocked.run(0.02)
    return ctl


def floor_below(ctl: UrController, gap_m: float, stiffness_n_m: float = 5000.0) -> None:
    z = ctl.state.actual_tcp_pose[2] - gap_m
    wall = {"point_m": [0, 0, z], "normal": [0, 0, 1], "stiffness_n_m": stiffness_n_m}
    ctl.world.wall = wall_from_params(wall)


def test_force_mode_moves_at_its_speed_limit_then_presses_with_the_wrench(clocked: Clocked) -> None:
    ctl = started(clocked)
    p0 = ctl.state.actual_tcp_pose.copy()
    floor_below(ctl, 0.03)
    command(ctl, FORCE_MODE, DOWN_10N, Z_ONLY)
    clocked.run(0.15)
    assert ctl.state.actual_tcp_speed[2] == pytest.approx(-0.1, abs=0.005)  # free space: the limit
    assert ctl.forces.tool_contact(np.array([0, 0, -1.0])) == 0
    clocked.run(0.6)
    assert ctl.state.actual_tcp_force[0:3] == pytest.approx([0, 0, 10.0], abs=0.3)  # the floor's reaction
    assert ctl.state.actual_tcp_pose[0:2] == pytest.approx(p0[0:2], abs=1e-4)  # x, y held
    assert np.allclose(ctl.state.actual_tcp_pose[3:6], p0[3:6], atol=1e-3)  # orientation held
    assert ctl.forces.tool_contact(np.array([0, 0, -1.0])) > 100  # cycles since the contact began
    command(ctl, FORCE_MODE_STOP)
    clocked.run(0.05)
    assert ctl.motion.name == "stopj" and ctl.runtime_state is RuntimeState.PLAYING
    clear(clocked)
    command(ctl, ZERO_FTSENSOR)  # still pressed on the floor: that is the new zero
    clocked.run(0.01)
    assert ctl.state.actual_tcp_force[2] == pytest.approx(0.0, abs=0.3)
    ctl.world.wall = None
    clocked.run(0.1)
    assert ctl.state.actual_tcp_force[2] == pytest.approx(-10.0, abs=0.5)  # the change since


def test_the_wrench_drives_the_arm_through_its_dynamics(clocked: Clocked) -> None:
    """The wall's reaction is a torque on the joints (Jᵀ F): the servo holding the arm against
    it works harder than in free space."""
    ctl = started(clocked)
    tau_free = ctl.arm.tau_nm.copy()
    floor_below(ctl, 0.005)
    command(ctl, FORCE_MODE, [*DOWN_10N[0:8], -40, *DOWN_10N[9:]], Z_ONLY)
    clocked.run(0.5)
    assert ctl.forces.external[2] == pytest.approx(40.0, abs=1.0)
    jac = np.zeros((6, 6))
    ctl.arm.tcp_jacobian(ctl.arm.q_rad, jac)
    expected = -(jac.T @ ctl.forces.external)  # the motors cancel the wall's torques
    assert ctl.arm.tau_nm - tau_free == pytest.approx(expected, abs=1.5)


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"frame_type": 5}, "type"),
        ({"selection": (0, 0, 2, 0, 0, 0)}, "selection_vector"),
        ({"wrench": (0, 0, -200, 0, 0, 0)}, "tool force limit"),
        ({"limits": (0.1, 0.1, 2.0, 0.1, 0.1, 0.1)}, "speed limit 2 m/s of axis 2"),
        ({"limits": (0.1, 0.1, -0.1, 0.1, 0.1, 0.1)}, "must be >= 0"),
    ],
)
def test_force_mode_arguments_the_controller_refuses(change: dict[str, object], message: str) -> None:
    base = ForceModeArgs((0,) * 6, (0, 0, 1, 0, 0, 0), (0, 0, -10, 0, 0, 0), 2, (0.1,) * 6)
    assert force_mode_error(base) == ""
    assert message in force_mode_error(ForceModeArgs(**{**base.__dict__, **change}))  # type: ignore[arg-type]


def test_a_refused_force_mode_or_damping_is_a_runtime_error(clocked: Clocked) -> None:
    ctl = started(clocked)
    command(ctl, FORCE_MODE, [*DOWN_10N[0:8], -500, *DOWN_10N[9:]], Z_ONLY)
    clocked.run(0.01)
    assert ctl.runtime_state is RuntimeState.STOPPED and ctl.program is None
    start_script(ctl)
    command(ctl, SET_DAMPING, [2.0])
    clocked.run(0.01)
    assert ctl.program is None


def test_task_frame_types_turn_the_frame_as_urscript_says() -> None:
    frame = np.array([1.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    r1 = task_rotation(frame, 1, np.zeros(3), np.zeros(3))
    assert r1[:, 1] == pytest.approx([1, 0, 0])  # y from the TCP towards the frame's origin
    r3 = task_rotation(frame, 3, np.zeros(3), np.array([0.0, 0.2, 0.3]))
    assert r3[:, 0] == pytest.approx([0, 1, 0]) and r3[:, 2] == pytest.approx([0, 0, 1])  # x along the speed
    assert task_rotation(frame, 2, np.zeros(3), np.ones(3)) == pytest.approx(np.eye(3))
    for r in (r1, r3):
        assert r @ r.T == pytest.approx(np.eye(3)) and np.linalg.det(r) == pytest.approx(1.0)


def test_freedrive_moves_with_a_push_on_its_free_axes_and_holds_without(clocked: Clocked) -> None:
    ctl = started(clocked)
    p0 = ctl.state.actual_tcp_pose.copy()
    command(ctl, FREEDRIVE, [0.0] * 6, [1, 1, 0, 0, 0, 0])  # feature: base; free: x, y
    clocked.run(0.1)
    assert ctl.motion.name == "freedrive"
    clocked.run(0.3)
    assert ctl.state.actual_tcp_pose[0:3] == pytest.approx(p0[0:3], abs=1e-4)  # no push: still
    ctl.world.push = push_from_params({"force_n": [10, 0, 10], "duration_s": 0.3}, ctl.now_s())
    clocked.run(0.8)
    moved = ctl.state.actual_tcp_pose[0:3] - p0[0:3]
    assert moved[0] > 0.03  # along the push's free component
    assert moved[2] == pytest.approx(0.0, abs=2e-3)  # z is not free
    assert np.abs(ctl.state.actual_tcp_speed).max() < 1e-3  # let go: it stops
    clear(clocked)
    command(ctl, END_FREEDRIVE)
    clocked.run(0.05)
    assert ctl.motion_finished(ctl.motion) and ctl.program is not None
    clear(clocked)
    command(ctl, TEACH_MODE)
    clocked.run(0.02)
    assert ctl.motion.name == "teach_mode"


def test_payload_changes_the_gravity_the_arm_holds_and_too_heavy_is_refused(clocked: Clocked) -> None:
    ctl = started(clocked)
    moment0 = ctl.state.target_moment.copy()
    command(ctl, SET_PAYLOAD, [3.0, 0.0, 0.0, 0.05])
    clocked.run(0.3)
    assert ctl.state.payload_kg == 3.0 and ctl.arm.payload_kg == 3.0
    lever_m = abs(ctl.state.actual_tcp_pose[0])  # the flange's reach from the shoulder's axis
    assert abs(ctl.state.target_moment[1] - moment0[1]) == pytest.approx(3.0 * 9.81 * lever_m, rel=0.05)
    assert ctl.state.actual_q == pytest.approx(ctl.target.q, abs=1e-3)  # and holds it up
    assert ctl.state.actual_tcp_force == pytest.approx(np.zeros(6), abs=1e-9)  # compensated
    clear(clocked)
    command(ctl, SET_PAYLOAD, [8.0, 0.0, 0.0, 0.05])
    clocked.run(0.02)
    assert ctl.program is None and ctl.state.payload_kg == 3.0


def test_the_tcp_offset_moves_the_contact_point(clocked: Clocked) -> None:
    ctl = started(clocked)
    floor_below(ctl, 0.05)
    assert ctl.world.wall is not None
    floor_z = ctl.world.wall.point_m[2]
    command(ctl, SET_TCP, [0, 0, 0.06, 0, 0, 0])  # the tool points down at home: 6 cm lower
    clocked.run(0.1)
    tcp_z = ctl.state.actual_tcp_pose[2]
    assert floor_z - 0.01 < tcp_z < floor_z - 0.005  # in the floor (the servo yields a little)
    assert ctl.forces.external[2] == pytest.approx(5000.0 * (floor_z - tcp_z), rel=0.02)
    assert ctl.state.actual_tcp_force[2] == pytest.approx(ctl.forces.external[2])


def test_the_tool_force_limit_is_a_protective_stop(clocked: Clocked) -> None:
    ctl = started(clocked)
    floor_below(ctl, 0.01, stiffness_n_m=20000.0)
    q = ctl.arm.q_rad.copy()
    q[1] += 0.1  # shoulder: the flange goes down
    command(ctl, MOVEJ, [*q, 0.5, 1.0], [0])
    clocked.run(1.0)
    assert ctl.safety_mode is SafetyMode.PROTECTIVE_STOP and "tool force limit" in ctl.stop_reason


def test_the_speed_slider_scales_speedj_and_its_outputs(clocked: Clocked) -> None:
    ctl = started(clocked)
    s = ctl.state
    s.speed_slider_mask, s.speed_slider_fraction = 1, 0.5  # what setSpeedSlider(0.5) writes
    clocked.run(0.3)
    assert s.target_speed_fraction == 0.5 and s.speed_scaling == pytest.approx(0.5)
    s.speed_slider_mask = 0  # a later package without the mask: the slider keeps its value
    command(ctl, SPEEDJ, [0, 0, 0, 0, 0, 0.4, 4.0, 0.0])
    clocked.run(0.5)
    assert ctl.arm.dq_rad_s[5] == pytest.approx(0.2, abs=0.01)
    assert s.target_speed_fraction == 0.5


def test_the_speed_slider_plays_movej_in_scaled_time(clocked: Clocked) -> None:
    def duration(fraction: float) -> float:
        command(clocked.ctl, 0)  # no command left from a run before
        ctl = started(clocked)
        ctl.state.speed_slider_mask, ctl.state.speed_slider_fraction = 1, fraction
        clocked.run(0.5)  # the scaling reaches the slider
        goal = ctl.target.q + np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.5])
        command(ctl, MOVEJ, [*goal, 1.0, 2.0], [0])
        t = 0.0
        while not np.allclose(ctl.target.q, goal) and t < 5.0:
            clocked.run(0.01)
            t += 0.01
        ctl.stop_program("the next run")
        return t

    full = duration(1.0)
    assert full == pytest.approx(1.0, abs=0.03)  # 0.5 rad at 1 rad/s, 0.5 s accelerating at 2
    assert duration(0.5) == pytest.approx(2.0 * full, abs=0.03)  # half the speed, twice the time
