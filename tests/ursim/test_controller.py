"""The controller and ur_rtde's control script protocol, on simulated time: registers written
as ur_rtde writes them, the script's answers read back (no network, no client)."""

from __future__ import annotations

import numpy as np
import pytest

from orccadd.config.robot import RobotConfig
from orccadd.ursim.control_script import DONE_WITH_CMD, RDY_FOR_CMD, ControlScript
from orccadd.ursim.controller import UrController
from orccadd.ursim.series import CB3, E_SERIES
from orccadd.ursim.states import (
    BOOT_S,
    RELEASE_S,
    PowerEvent,
    RobotMode,
    RobotStatus,
    RuntimeState,
    SafetyMode,
    SafetyStatus,
)
from tests.ursim.conftest import Clocked, make_controller

MOVEJ, SPEEDJ, SERVOJ, SPEED_STOP, STOPJ, SET_WATCHDOG, STOP_SCRIPT = 1, 9, 11, 15, 34, 35, 255


def start_script(ctl: UrController, offset: int = 0) -> ControlScript:
    script = ControlScript(ctl, offset, offset)
    with ctl.lock:
        assert ctl.start_program(script, "rtde_control")
    return script


def command(
    ctl: UrController, cmd: int, doubles: list[float] = (), ints: list[int] = (), offset: int = 0
) -> None:
    """A data package of ur_rtde: the command id in int register 0, its arguments after it."""
    s = ctl.state
    with ctl.lock:
        s.in_int[offset] = cmd
        for i, v in enumerate(ints):
            s.in_int[offset + 1 + i] = v
        for i, v in enumerate(doubles):
            s.in_double[offset + i] = v


def test_movej_handshake_ready_done_clear_ready(clocked: Clocked) -> None:
    ctl = clocked.ctl
    start_script(ctl)
    clocked.run(0.01)
    assert ctl.state.out_int[0] == RDY_FOR_CMD
    goal = ctl.arm.q_rad + np.array([0.3, 0, 0, 0, 0, 0.2])
    command(ctl, MOVEJ, [*goal, 1.0, 2.0], [0])
    clocked.run(0.1)
    assert ctl.state.out_int[0] == RDY_FOR_CMD  # still moving: the script is inside movej
    clocked.run(1.5)
    assert ctl.state.out_int[0] == DONE_WITH_CMD
    assert np.allclose(ctl.target.q, goal)
    assert np.allclose(ctl.arm.q_rad, goal, atol=1e-3)  # the arm's own servo followed
    command(ctl, 0)  # the client clears the command
    clocked.run(0.01)
    assert ctl.state.out_int[0] == RDY_FOR_CMD


def test_async_movej_reports_progress_in_output_int_register_2(clocked: Clocked) -> None:
    ctl = clocked.ctl
    start_script(ctl)
    clocked.run(0.01)
    goal = ctl.arm.q_rad + 0.2
    command(ctl, MOVEJ, [*goal, 1.0, 2.0], [1])
    clocked.run(0.05)
    assert ctl.state.out_int[0] == DONE_WITH_CMD  # returns at once
    running = ctl.state.out_int[2]
    assert running & 0x8000 and running >> 24 == 1  # bit 15: running; bits 24-30: op id 1
    clocked.run(1.5)
    assert not ctl.state.out_int[2] & 0x8000  # finished
    assert np.allclose(ctl.target.q, goal)


def test_speedj_streams_then_speed_stop_stops(clocked: Clocked) -> None:
    ctl = clocked.ctl
    start_script(ctl)
    command(ctl, SPEEDJ, [0.0, 0.0, 0.0, 0.0, 0.0, 0.5, 1.0, 0.0])
    clocked.run(1.0)
    assert ctl.target.qd[5] == pytest.approx(0.5)
    assert ctl.state.out_int[0] == RDY_FOR_CMD  # real-time commands answer "ready"
    command(ctl, SPEED_STOP, [5.0])
    clocked.run(0.5)
    assert ctl.state.out_int[0] == DONE_WITH_CMD
    assert not ctl.target.qd.any()


def test_servoj_into_an_acceleration_violation_is_a_protective_stop(clocked: Clocked) -> None:
    ctl = clocked.ctl
    start_script(ctl)
    q = ctl.arm.q_rad.copy()
    q[0] += 0.5  # a step: gain × 0.5 rad is far above the acceleration limit
    command(ctl, SERVOJ, [*q, 0.5, 0.5, 0.002, 0.1, 300.0])
    clocked.run(0.5)
    assert ctl.safety_mode is SafetyMode.PROTECTIVE_STOP
    assert "acceleration limit" in ctl.stop_reason
    assert ctl.runtime_state is RuntimeState.PAUSED
    assert ctl.state.safety_status_bits & SafetyStatus.PROTECTIVE_STOPPED
    assert not ctl.state.robot_status_bits & RobotStatus.PROGRAM_RUNNING
    assert abs(ctl.target.q[0] - q[0]) > 0.4 and not ctl.target.qd.any()  # stopped short, at rest


def test_speedj_into_the_joint_range_is_a_protective_stop(ur5e: RobotConfig) -> None:
    clocked = Clocked(make_controller(ur5e))
    ctl = clocked.ctl
    start_script(ctl)
    command(ctl, SPEEDJ, [0.0, 0.0, 3.0, 0.0, 0.0, 0.0, 6.0, 0.0])  # the elbow: ±π
    clocked.run(3.0)
    assert ctl.safety_mode is SafetyMode.PROTECTIVE_STOP
    assert "joint 2 position limit" in ctl.stop_reason
    assert ctl.arm.q_rad[2] < np.pi + 0.05


def test_a_protective_stop_unlocks_only_after_the_delay(ur5e: RobotConfig) -> None:
    clocked = Clocked(make_controller(ur5e, unlock_delay_s=5.0))
    ctl = clocked.ctl
    clocked.run(0.01)
    ctl.protective_stop("test")
    clocked.run(1.0)
    assert "Cannot unlock protective stop until 5s after occurrence" in ctl.unlock_protective_stop()
    clocked.run(4.1)
    assert ctl.unlock_protective_stop() == ""
    assert ctl.safety_mode is SafetyMode.NORMAL


def test_stop_script_ends_the_program_and_unknown_commands_are_runtime_errors(clocked: Clocked) -> None:
    ctl = clocked.ctl
    start_script(ctl)
    command(ctl, STOP_SCRIPT)
    clocked.run(0.01)
    assert ctl.runtime_state is RuntimeState.STOPPED and ctl.program is None
    start_script(ctl)
    command(ctl, 3)  # movel: not simulated
    clocked.run(0.01)
    assert ctl.runtime_state is RuntimeState.STOPPED


def test_upper_range_registers_offset_every_index_by_24(clocked: Clocked) -> None:
    ctl = clocked.ctl
    start_script(ctl, offset=24)
    goal = ctl.arm.q_rad + 0.1
    command(ctl, MOVEJ, [*goal, 1.0, 2.0], [0], offset=24)
    clocked.run(1.0)
    assert ctl.state.out_int[24] == DONE_WITH_CMD and ctl.state.out_int[0] == 0
    assert np.allclose(ctl.target.q, goal)


def test_the_rtde_watchdog_stops_the_program_when_its_register_goes_unwritten(clocked: Clocked) -> None:
    ctl = clocked.ctl
    start_script(ctl)
    command(ctl, SET_WATCHDOG, [10.0])  # at least 10 Hz
    clocked.run(0.05)
    command(ctl, 0)
    for _ in range(10):  # written every 50 ms: alive
        with ctl.lock:
            ctl.inputs_written(("input_int_register_0",))
        clocked.run(0.05)
    assert ctl.runtime_state is RuntimeState.PLAYING
    clocked.run(0.2)
    assert ctl.runtime_state is RuntimeState.STOPPED


def test_inputs_that_kept_coming_through_a_late_cycle_feed_the_watchdog(clocked: Clocked) -> None:
    ctl = clocked.ctl
    start_script(ctl)
    command(ctl, SET_WATCHDOG, [10.0])
    clocked.run(0.05)
    command(ctl, 0)
    for _ in range(6):  # the cycle is 0.3 s late (a loaded machine); inputs come every 50 ms
        clocked.t_s += 0.05
        with ctl.lock:
            ctl.inputs_written(("input_int_register_0",))
    clocked.run(0.01)
    assert ctl.runtime_state is RuntimeState.PLAYING


def test_power_sequence_follows_the_table(ur5e: RobotConfig) -> None:
    clocked = Clocked(make_controller(ur5e))
    ctl = clocked.ctl
    clocked.run(0.01)
    ctl.power_event(PowerEvent.POWER_OFF)
    assert ctl.robot_mode is RobotMode.POWER_OFF and not ctl.arm.brakes_released
    ctl.power_event(PowerEvent.BRAKE_RELEASE)  # from power off: powers on, then releases
    assert ctl.robot_mode is RobotMode.POWER_ON
    clocked.run(BOOT_S + 0.01)
    assert ctl.robot_mode is RobotMode.IDLE
    clocked.run(RELEASE_S + 0.01)
    assert ctl.robot_mode is RobotMode.RUNNING and ctl.arm.brakes_released
    assert ctl.state.robot_status_bits & RobotStatus.POWER_ON


def test_a_brake_release_while_booting_opens_the_brakes_once_booted(ur5e: RobotConfig) -> None:
    """A stock script's power on then brake release at once: the controller does what it said."""
    clocked = Clocked(make_controller(ur5e))
    ctl = clocked.ctl
    clocked.run(0.01)
    ctl.power_event(PowerEvent.POWER_OFF)
    ctl.power_event(PowerEvent.POWER_ON)
    clocked.run(BOOT_S / 2)
    ctl.power_event(PowerEvent.BRAKE_RELEASE)  # still booting
    assert ctl.robot_mode is RobotMode.POWER_ON
    clocked.run(BOOT_S / 2 + 0.01)  # the boot ends when it would have without the release
    assert ctl.robot_mode is RobotMode.IDLE
    clocked.run(RELEASE_S + 0.01)
    assert ctl.robot_mode is RobotMode.RUNNING and ctl.arm.brakes_released


def test_emergency_stop_stops_then_powers_off(clocked: Clocked) -> None:
    ctl = clocked.ctl
    start_script(ctl)
    command(ctl, SPEEDJ, [0.5, 0.0, 0.0, 0.0, 0.0, 0.0, 2.0, 0.0])
    clocked.run(0.5)
    with ctl.lock:
        ctl.emergency_stop()
    assert ctl.runtime_state is RuntimeState.STOPPED
    clocked.run(0.5)
    assert ctl.robot_mode is RobotMode.POWER_OFF
    bits = SafetyStatus(ctl.state.safety_status_bits)
    assert SafetyStatus.EMERGENCY_STOPPED in bits and SafetyStatus.ROBOT_EMERGENCY_STOPPED in bits
    ctl.power_event(PowerEvent.POWER_ON)
    assert ctl.robot_mode is RobotMode.POWER_OFF  # not while the emergency stop is engaged
    with ctl.lock:
        ctl.release_emergency_stop()
    assert ctl.safety_mode is SafetyMode.NORMAL
    ctl.power_event(PowerEvent.POWER_ON)
    assert ctl.robot_mode is RobotMode.POWER_ON


def test_a_cb3_controller_runs_at_125_hz(ur5e: RobotConfig) -> None:
    ctl = make_controller(ur5e, CB3)
    assert ctl.period_s == pytest.approx(0.008)
    clocked = Clocked(ctl)
    start_script(ctl)
    goal = ctl.arm.q_rad + 0.1
    command(ctl, MOVEJ, [*goal, 1.0, 2.0], [0])
    clocked.run(1.0)
    assert np.allclose(ctl.arm.q_rad, goal, atol=2e-3)
    assert ctl.state.timestamp_s == pytest.approx(ctl.cycles * 0.008)


def test_a_program_paused_by_a_protective_stop_resumes_its_servo_on_play(clocked: Clocked) -> None:
    ctl = clocked.ctl
    start_script(ctl)
    q = ctl.arm.q_rad.copy()
    command(ctl, SERVOJ, [*q, 0.5, 0.5, 0.002, 0.1, 300.0])
    clocked.run(0.1)
    with ctl.lock:
        ctl.protective_stop("test")
    clocked.run(0.1)
    assert ctl.runtime_state is RuntimeState.PAUSED
    assert ctl.unlock_protective_stop() == ""
    assert ctl.resume_program()  # the dashboard's "play"
    q[4] += 0.01  # a step the servo takes within the acceleration limit (300 × 0.01 rad/s²)
    command(ctl, SERVOJ, [*q, 0.5, 0.5, 0.002, 0.1, 300.0])
    clocked.run(2.0)
    assert ctl.safety_mode is SafetyMode.NORMAL
    assert ctl.target.q[4] == pytest.approx(q[4], abs=1e-4)


DIRECT_TORQUE = 66


def test_direct_torque_adds_to_gravity_and_a_cycle_without_it_returns_to_position_control(
    clocked: Clocked,
) -> None:
    """`direct_torque(tau)`: the joints take tau on top of the controller's gravity compensation
    (zero torque: the arm floats where it is); a cycle without a new command (the script's
    command register cleared) is back to position control, held where the arm is."""
    ctl = clocked.ctl
    start_script(ctl)
    q0 = ctl.arm.q_rad.copy()
    command(ctl, DIRECT_TORQUE, [0.0] * 6)
    clocked.run(0.2)
    assert ctl.motion.name == "direct_torque" and not ctl.motion_done
    assert np.abs(ctl.arm.q_rad - q0).max() < 1e-3  # gravity compensated: it stays
    command(ctl, DIRECT_TORQUE, [0.0, 0.0, 0.0, 0.0, 0.0, 0.05])  # a push on the wrist
    clocked.run(0.1)
    assert ctl.arm.dq_rad_s[5] > 0.02 and np.allclose(ctl.target.q, ctl.arm.q_rad)  # target = arm
    command(ctl, 0)  # no more direct_torque
    clocked.run(0.5)
    assert ctl.motion_done and ctl.safety_mode is SafetyMode.NORMAL
    q1 = ctl.arm.q_rad.copy()
    clocked.run(0.2)
    assert np.abs(ctl.arm.q_rad - q1).max() < 1e-3  # held by the position servo


def test_direct_torque_is_nothing_before_5_26(ur5e: RobotConfig) -> None:
    """ur_rtde 1.6's script has `direct_torque` from PolyScope 5.26 on: on an older controller
    its command 66 does nothing (the arm stays under position control)."""
    clocked = Clocked(make_controller(ur5e, E_SERIES.with_software("5.11.1")))
    ctl = clocked.ctl
    start_script(ctl)
    q0 = ctl.arm.q_rad.copy()
    command(ctl, DIRECT_TORQUE, [0.0, 0.0, 0.0, 0.0, 0.0, 0.5])
    clocked.run(0.3)
    assert ctl.motion.name != "direct_torque" and ctl.runtime_state is RuntimeState.PLAYING
    assert np.abs(ctl.arm.q_rad - q0).max() < 1e-3
