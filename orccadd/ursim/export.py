"""What the controller publishes each cycle: its modes, the arm's measured and target state, and
the quantities derived from them (TCP pose and speed, elbow, joint torques and currents), written
into the `RobotState` the RTDE clients read."""

from __future__ import annotations

from typing import Protocol

import numpy as np

from orccadd.ursim.arm import UrArm
from orccadd.ursim.motion import Target
from orccadd.ursim.robot_state import RobotState
from orccadd.ursim.speed_scaling import SpeedScaling
from orccadd.ursim.states import SAFETY_BITS, JointMode, RobotMode, RobotStatus, RuntimeState, SafetyMode

MAIN_VOLTAGE_V = 48.0
JOINT_MODES = {
    RobotMode.POWER_ON: JointMode.BOOTING,
    RobotMode.IDLE: JointMode.IDLE,
    RobotMode.RUNNING: JointMode.RUNNING,
}


class Exported(Protocol):
    """What is published (`controller.UrController`)."""

    state: RobotState
    arm: UrArm
    target: Target
    robot_mode: RobotMode
    safety_mode: SafetyMode
    runtime_state: RuntimeState
    speed: SpeedScaling


def export_state(ctl: Exported, now_s: float, exec_ms: float) -> None:
    """Update `ctl.state` at the end of a cycle (under the controller's lock)."""
    s, arm, tgt = ctl.state, ctl.arm, ctl.target
    s.timestamp_s = now_s
    s.actual_execution_time_ms = exec_ms
    s.actual_q[:], s.actual_qd[:] = arm.q_rad, arm.dq_rad_s
    s.target_q[:], s.target_qd[:], s.target_qdd[:] = tgt.q, tgt.qd, tgt.qdd
    s.actual_current_as_torque[:] = arm.tau_nm
    arm.current_a(arm.tau_nm, s.actual_current)
    if arm.brakes_released:
        arm.inverse_dynamics(tgt.q, tgt.qd, tgt.qdd, s.target_moment)
    else:
        s.target_moment[:] = 0.0
    arm.current_a(s.target_moment, s.target_current)
    elbow = (s.elbow_position, s.elbow_velocity)
    arm.kinematics(s.actual_q, s.actual_qd, s.actual_tcp_pose, s.actual_tcp_speed, elbow)
    arm.kinematics(tgt.q, tgt.qd, s.target_tcp_pose, s.target_tcp_speed)
    mode = ctl.robot_mode
    powered = mode in JOINT_MODES
    s.robot_mode = int(mode)
    s.safety_mode = int(ctl.safety_mode)
    s.runtime_state = int(ctl.runtime_state)
    s.joint_mode = [int(JOINT_MODES.get(mode, JointMode.POWER_OFF))] * arm.dof
    bits = RobotStatus.POWER_ON if powered else RobotStatus(0)
    if ctl.runtime_state is RuntimeState.PLAYING:
        bits |= RobotStatus.PROGRAM_RUNNING
    s.robot_status_bits = int(bits)
    s.safety_status_bits = int(SAFETY_BITS.get(ctl.safety_mode, 0))
    s.main_voltage_v = MAIN_VOLTAGE_V
    s.robot_voltage_v = MAIN_VOLTAGE_V if powered else 0.0
    s.actual_joint_voltage[:] = MAIN_VOLTAGE_V if powered else 0.0
    s.robot_current_a = float(np.abs(s.actual_current).sum()) * 0.1  # the motors' share at 48 V
    s.actual_momentum = float(np.abs(s.actual_qd).sum())
    s.target_speed_fraction = ctl.speed.slider
    s.speed_scaling = ctl.speed.scaling if ctl.runtime_state is RuntimeState.PLAYING else 0.0
