"""The `ur_rtde` backend against the UR controller simulator (a separate process that stock
ur_rtde talks to): device-paced motion, the controller's safety stops as type 3 exceptions,
what `reset` can and cannot clear, a dead controller, and the startup checks."""

from __future__ import annotations

import dataclasses
import re
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from orccadd.errors import ConfigError, ResourceError
from orccadd.model import RobotModel
from orccadd.physres.ur_rtde import UrRtdeArm
from orccadd.robot import load_robot_config
from orccadd.session import Session
from orccadd.task import RobotTask
from orccadd.task.loop import resource_clock
from orccadd.types import CommandMode, Phase, Status
from orccadd.ursim.process import UrSimProcess
from tests.conftest import ROOT
from tests.safety import TickRecorder, assert_commands_within_limits, assert_safe_stop_in_time, status_shows

CONFIG = ROOT / "configs/robots/ur5e-rtde-sim.toml"
MOVE = ROOT / "configs/tasks/move_joints_csp.toml"
REACH = [0.5, -1.3, 1.3, -1.6, -1.3, 0.3]
HOME = [0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0]

# ur_rtde blocks in C++ holding the interpreter: only a thread can time such a test out
pytestmark = pytest.mark.timeout(180, method="thread")


@pytest.fixture
def sim() -> Iterator[UrSimProcess]:
    with UrSimProcess(CONFIG, "--boot", "running", "--unlock-delay-s", "1", "--priority", "70") as s:
        yield s


@pytest.fixture
def arm(sim: UrSimProcess) -> Iterator[Session]:
    s = Session.open(CONFIG, CommandMode.POSITION)
    yield s
    s.close()  # ur_rtde's clients go before the simulator does


def move(s: Session, target: list[float]) -> tuple[RobotTask, TickRecorder]:
    task = s.task(MOVE)
    next(m for m in task.modules if m.name == "traj").configure({"target_rad": target, "speed_scale": 0.5})
    loop = TickRecorder(s.resource, resource_clock(s.resource), overrun_limit=10**6)
    return task, loop


def reset_once_unlockable(res: Any, loop: TickRecorder) -> None:
    """`reset` after a protective stop, again while the controller does not allow the unlock yet
    (1 s after the stop here; 5 s on a real one), the loop ticking meanwhile."""
    deadline = time.monotonic() + 10
    while True:
        try:
            res.reset_fault()
            return
        except ResourceError as e:
            assert "reset again then" in str(e) and time.monotonic() < deadline, e
            loop.run_for(0.2)


def test_a_motion_is_paced_by_the_controllers_stream_and_reaches_its_target(arm: Session) -> None:
    task, loop = move(arm, REACH)
    phase = loop.run_task(task, timeout_s=20.0)
    assert phase is Phase.DONE, (task.fault_reason, arm.resource.fault_message)
    assert arm.event_names() == ["MoveJointsCSP.done"]
    period_us = arm.config.control_period_s * 1e6
    assert period_us / 3 < loop.stats.release_period.median_us < 3 * period_us  # the controller's 500 Hz
    assert max(abs(q - t) for q, t in zip(arm.resource.state.q_rad, REACH, strict=True)) < 0.01
    assert_commands_within_limits(loop.ticks(), arm.config)
    d = arm.resource.diagnostics()
    assert d.details["controller"] == "UR5e 5.26.0.0"
    assert len(str(d.details["actual_current_a"]).split()) == 6
    assert len(str(d.details["tcp_pose_m_rad"]).split()) == 6
    assert float(d.details["controller_time_s"]) > 0


def test_protective_stop_mid_motion_is_a_type_3_then_reset_unlocks_and_it_moves_again(
    sim: UrSimProcess, arm: Session
) -> None:
    task, loop = move(arm, REACH)
    task.activate()
    loop.active = task
    loop.run_for(0.5)
    sim.inject("protective_stop")
    loop.run_for(0.5)
    assert task.phase is Phase.FAULT
    assert [n for n in arm.event_names() if ".T3." in n] == ["MoveJointsCSP.T3.ResourceFault"]
    assert "safety mode PROTECTIVE_STOP" in arm.resource.fault_message
    ticks = loop.ticks()
    assert_safe_stop_in_time(ticks, status_shows(ticks, Status.FAULT))
    assert_commands_within_limits(ticks, arm.config)
    res = arm.resource
    reset_once_unlockable(res, loop)
    loop.run_for(1.0)
    assert not res.state.status & Status.FAULT, res.fault_message
    assert res.state.status & Status.STOPPED
    res.clear_stop()
    task2, loop2 = move(arm, HOME)
    phase = loop2.run_task(task2, timeout_s=20.0)
    assert phase is Phase.DONE, (task2.fault_reason, arm.resource.fault_message)


def test_an_emergency_stop_cannot_be_reset_from_here(sim: UrSimProcess, arm: Session) -> None:
    task, loop = move(arm, REACH)
    task.activate()
    loop.active = task
    loop.run_for(0.3)
    sim.inject("emergency_stop")
    loop.run_for(0.5)
    assert task.phase is Phase.FAULT
    assert "EMERGENCY_STOP" in arm.resource.fault_message
    with pytest.raises(ResourceError, match="release the emergency stop button"):
        arm.resource.reset_fault()


def test_a_stalled_stream_is_comm_lost_after_stall_periods(sim: UrSimProcess, arm: Session) -> None:
    task, loop = move(arm, REACH)
    task.activate()
    loop.active = task
    loop.run_for(0.3)
    sim.inject("stream_stall", duration_s=1.0)
    loop.executor.run(max_ticks=20)  # released by the clock's stall timeout (3 periods each)
    assert task.phase is Phase.FAULT
    assert [n for n in arm.event_names() if ".T3." in n] == ["MoveJointsCSP.T3.CommLost"]
    stall = arm.resource.settings.stall_periods  # type: ignore[attr-defined]
    silent = re.search(r"no RTDE package for (\d+) periods", arm.resource.fault_message)
    ticks = loop.ticks()
    lost = status_shows(ticks, Status.COMM_LOST)
    first = next(i for i in range(len(ticks.seq)) if lost(i))
    # declared by the first tick whose silence reached stall_periods, however late that tick came
    # (a loaded machine delays this test's loop: the count is of the controller's periods)
    late = round((ticks.t_s[first] - ticks.t_s[first - 1]) / arm.config.control_period_s)
    assert silent is not None and stall <= int(silent[1]) <= stall + late, arm.resource.fault_message
    assert_safe_stop_in_time(ticks, lost)


def test_a_dropped_connection_is_comm_lost_this_process_lives_on_and_reset_reconnects(
    sim: UrSimProcess, arm: Session
) -> None:
    """The controller closes every connection and takes new ones (a network glitch, a restarted
    PolyScope): ur_rtde reconnects from its own threads and then runs two receive threads on one
    connection, which crashed the process it ran in (issue 31). It runs in the link process now:
    here, CommLost within a few periods, that process ended, ours running on; `reset` starts a
    new link process and the arm moves again."""
    task, loop = move(arm, REACH)
    task.activate()
    loop.active = task
    loop.run_for(0.3)
    res = arm.resource
    first = res.link.process  # type: ignore[attr-defined]
    sim.inject("drop_connection", ports="all")
    loop.executor.run(max_ticks=40)  # each released by the stream or the clock's stall timeout
    assert task.phase is Phase.FAULT
    assert [n for n in arm.event_names() if ".T3." in n] == ["MoveJointsCSP.T3.CommLost"]
    assert first.wait(timeout=5.0) != 0  # ended (by us, or by ur_rtde's crash), not by itself
    loop.executor.run(max_ticks=100)  # ur_rtde would have crashed us by now
    ticks = loop.ticks()
    assert_safe_stop_in_time(ticks, status_shows(ticks, Status.COMM_LOST))
    deadline = time.monotonic() + 20
    while not res.state.status & Status.STOPPED:  # no controller confirms: the stop's timeout
        assert time.monotonic() < deadline
        loop.run_for(0.2)
    res.reset_fault()
    assert res.link.process is not first and res.link.process.poll() is None  # type: ignore[attr-defined]
    loop.run_for(1.0)
    assert not res.state.status & (Status.FAULT | Status.COMM_LOST), res.fault_message
    res.clear_stop()
    task2, loop2 = move(arm, HOME)
    phase = loop2.run_task(task2, timeout_s=20.0)
    assert phase is Phase.DONE, (task2.fault_reason, arm.resource.fault_message)


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"control_period_s": 0.004}, "period"),
        ({"model": "UR10e"}, "the controller drives a UR5e, the config describes a UR10e"),
    ],
)
def test_a_config_that_is_not_this_controller_is_refused(
    sim: UrSimProcess, tmp_path: Path, change: dict[str, object], message: str
) -> None:
    cfg = load_robot_config(CONFIG)
    if "model" in change:
        settings = dataclasses.replace(cfg.backend_settings, model=change["model"])
        cfg = dataclasses.replace(cfg, backend_settings=settings)
        res = UrRtdeArm(cfg, RobotModel.from_config(cfg))
        with pytest.raises(ResourceError, match=message):
            res.configure()
        return
    text = CONFIG.read_text().replace("control_period_s = 0.002", "control_period_s = 0.004")
    text = text.replace('"../urdf/', f'"{ROOT}/configs/urdf/')
    path = tmp_path / "ur.toml"
    path.write_text(text)
    with pytest.raises(Exception, match=message):
        load_robot_config(path)


def test_commands_that_stop_coming_mid_speedj_are_stopped_by_the_controllers_watchdog(
    sim: UrSimProcess,
) -> None:
    """This process killed or stalled mid-motion in velocity mode: the controller's RTDE watchdog
    (armed at the first tick, `watchdog_s`) stops the control script, and the arm."""
    s = Session.open(CONFIG, CommandMode.VELOCITY)
    try:
        res = s.resource
        qd = np.array([0.3, 0.0, 0.0, 0.0, 0.0, 0.0])
        for _ in range(250):  # 0.5 s of speedJ through the backend, device-paced
            t_ns = res.wait_for_cycle(0.05)
            t_s = (t_ns if t_ns > 0 else time.monotonic_ns()) * 1e-9
            res.read(t_s)
            res.write(t_s, qd)
        assert sim.status()["runtime_state"] == "PLAYING"
        time.sleep(res.settings.watchdog_s + 0.5)  # type: ignore[attr-defined]  # "stalls": nothing sent
        st = sim.status()
        assert st["runtime_state"] == "STOPPED", st
        assert "RTDE watchdog" in sim.log_text()
        q0 = st["q_rad"][0]
        time.sleep(0.2)
        assert sim.status()["q_rad"][0] == pytest.approx(q0, abs=1e-4)  # at rest
    finally:
        s.close()


@pytest.mark.parametrize("power_on", [True, False])
def test_power_on_and_brake_release_only_when_the_config_says_so(tmp_path: Path, power_on: bool) -> None:
    text = CONFIG.read_text().replace('"../urdf/', f'"{ROOT}/configs/urdf/')
    text = text.replace('host = "127.0.0.1"', f'host = "127.0.0.1"\npower_on = {str(power_on).lower()}')
    path = tmp_path / "ur.toml"
    path.write_text(text)
    with UrSimProcess(CONFIG, "--priority", "70") as sim:  # boots powered off, as a real one
        assert sim.status()["robot_mode"] == "POWER_OFF"
        if not power_on:
            with pytest.raises(ResourceError, match="the arm is POWER_OFF .*power_on = true"):
                Session.open(path, CommandMode.POSITION)
            assert sim.status()["robot_mode"] == "POWER_OFF"  # nothing done to it
            return
        s = Session.open(path, CommandMode.POSITION)
        try:
            assert sim.status()["robot_mode"] == "RUNNING"
        finally:
            s.close()


CT_MOVE = ROOT / "configs/tasks/move_joints.toml"  # Ruckig + computed torque: a torque task


def test_a_computed_torque_motion_runs_on_the_controllers_direct_torque(sim: UrSimProcess) -> None:
    """The computed-torque task, unchanged, on a controller with direct torque (5.26): the
    backend sends its torque less gravity (the controller adds gravity itself); the arm reaches
    the target within the task's tolerance, every command within the limits."""
    s = Session.open(CONFIG, CommandMode.TORQUE)
    try:
        assert CommandMode.TORQUE in s.resource.description.modes
        task = s.task(CT_MOVE)
        next(m for m in task.modules if m.name == "traj").configure({"target_rad": REACH, "speed_scale": 0.3})
        loop = TickRecorder(s.resource, resource_clock(s.resource), overrun_limit=10**6)
        phase = loop.run_task(task, timeout_s=30.0)
        assert phase is Phase.DONE, (task.fault_reason, s.resource.fault_message)
        assert np.abs(s.resource.state.q_rad - REACH).max() < 0.01
        assert_commands_within_limits(loop.ticks(), s.config)
        assert sim.status()["safety_mode"] == "NORMAL"
    finally:
        s.close()


def test_torque_needs_a_controller_with_direct_torque(tmp_path: Path) -> None:
    """ur_rtde 1.6's script calls direct_torque from PolyScope 5.26 on: a config that wants torque
    (min_version 5.26) refuses an older controller at connect, naming its version; a config
    without it has no torque mode, and a torque task is refused before anything moves."""
    with UrSimProcess(CONFIG, "--boot", "running", "--software", "5.11.1", "--priority", "70") as old:
        with pytest.raises(
            ResourceError, match=r"controller software 5\.11\.1.* older than min_version 5\.26"
        ):
            Session.open(CONFIG, CommandMode.POSITION)
        text = CONFIG.read_text().replace('"../urdf/', f'"{ROOT}/configs/urdf/')
        path = tmp_path / "ur.toml"
        path.write_text(text.replace('min_version = "5.26"', 'min_version = "5.4"'))
        with pytest.raises(ResourceError, match="cannot command torque"):
            Session.open(path, CommandMode.TORQUE)
        assert old.status()["robot_mode"] == "RUNNING" and old.status()["q_rad"] == pytest.approx(
            [0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0], abs=1e-3
        )


def test_the_configs_payload_and_tcp_are_set_on_the_controller_and_a_bad_one_refused(
    sim: UrSimProcess, tmp_path: Path
) -> None:
    """The tool from the config, set each time the control script starts: the controller reports
    the payload, and the TCP moves actual_TCP_pose 0.1 m along the flange's z."""
    base = load_robot_config(CONFIG)
    poses = []
    for tcp in ([0.0] * 6, [0.0, 0.0, 0.1, 0.0, 0.0, 0.0]):
        s = dataclasses.replace(
            base.backend_settings, payload_kg=2.0, payload_cog_m=[0.0, 0.0, 0.05], tcp_m_rad=tcp
        )
        arm = UrRtdeArm(dataclasses.replace(base, backend_settings=s), RobotModel.from_config(base))
        arm.configure()
        try:
            d = arm.diagnostics().details
            assert float(d["payload_kg"]) == pytest.approx(2.0), d
            poses.append(np.array([float(x) for x in str(d["tcp_pose_m_rad"]).split()]))
        finally:
            arm.shutdown()
    assert np.linalg.norm(poses[1][:3] - poses[0][:3]) == pytest.approx(0.1, abs=1e-3)
    with pytest.raises(ConfigError, match=r"payload_kg \(=6\) exceeds the UR5e's rated payload \(5 kg\)"):
        text = CONFIG.read_text().replace("[resource.settings]\n", "[resource.settings]\npayload_kg = 6.0\n")
        (tmp_path / "six.toml").write_text(text.replace('"../', f'"{CONFIG.parent.parent}/'))
        load_robot_config(tmp_path / "six.toml")


@pytest.mark.parametrize(
    ("line", "message"),
    [
        (
            'digital_inputs = { part = "DI8" }',
            r"digital_inputs\.part \(='DI8'\) is not one of DI0-DI7, CI0-CI7, TI0-TI1",
        ),
        ('digital_inputs = { fault = "DI0" }', r"digital_inputs\.fault must be an identifier"),
        (
            'digital_outputs = { close = "TO0" }',
            r"digital_outputs\.close \(='TO0'\) must be OUTPUT=on or OUTPUT=off",
        ),
        ('digital_outputs = { close = "TO2=on" }', r"is not one of DO0-DO7, CO0-CO7, TO0-TO1"),
    ],
)
def test_a_digital_io_the_controller_does_not_have_is_refused_naming_it(
    tmp_path: Path, line: str, message: str
) -> None:
    text = CONFIG.read_text().replace('"../', f'"{CONFIG.parent.parent}/')
    text = "\n".join(t for t in text.splitlines() if not t.startswith(("digital_inputs", "digital_outputs")))
    (tmp_path / "io.toml").write_text(text.replace("[resource.settings]\n", f"[resource.settings]\n{line}\n"))
    with pytest.raises(ConfigError, match=message):
        load_robot_config(tmp_path / "io.toml")


def _tcp_position(model: RobotModel, q: list[float]) -> np.ndarray:
    import pinocchio as pin

    m = model.model
    data = m.createData()
    pin.framesForwardKinematics(m, data, np.asarray(q, dtype=np.float64))
    return np.array(data.oMf[m.getFrameId("tool0")].translation)


@pytest.mark.parametrize("wall", [True, False])
def test_a_guarded_move_ends_on_the_contact_the_controllers_sensor_measures(
    sim: UrSimProcess, arm: Session, wall: bool
) -> None:
    """configs/tasks/approach_until_contact.toml on the simulated controller: a wall half-way
    between the tool and where the target would bring it (placed through the simulator's
    control channel) stops the approach on its postcondition, the controller's actual_TCP_force
    (`arm.wrench`) above `contact.force_n`; without the wall the target is reached: `NoContact`."""
    res = arm.resource
    start = _tcp_position(res.model, res.state.q_rad.tolist())
    end = _tcp_position(res.model, REACH)
    normal = (start - end) / np.linalg.norm(start - end)
    if wall:
        sim.inject("wall", point_m=((start + end) / 2).tolist(), normal=normal.tolist(), stiffness_n_m=5000)
    task = arm.task(ROOT / "configs/tasks/approach_until_contact.toml")
    next(m for m in task.modules if m.name == "traj").configure({"target_rad": REACH, "speed_scale": 0.2})
    loop = TickRecorder(res, resource_clock(res), overrun_limit=10**6)
    phase = loop.run_task(task, timeout_s=30.0)
    force = float(np.linalg.norm(res.signals["wrench"][:3]))
    if wall:
        assert phase is Phase.DONE and arm.event_names() == ["ApproachUntilContact.done"], arm.event_names()
        assert force > 15.0, force
        tcp = _tcp_position(res.model, res.state.q_rad.tolist())
        assert abs(float((tcp - (start + end) / 2) @ normal)) < 0.02  # stopped at the wall
    else:
        assert phase is Phase.ABORTED and arm.event_names() == ["ApproachUntilContact.T2.NoContact"]
        assert force < 1.0, force


def _tcp(res: Any) -> np.ndarray:
    return _tcp_position(res.model, res.state.q_rad.tolist())


def _run_ur_task(arm: Session, name: str, timeout_s: float, **params: Any) -> tuple[RobotTask, Phase]:
    task = arm.task(ROOT / f"configs/tasks/{name}.toml")
    for path, value in params.items():
        module, param = path.split("__")
        next(m for m in task.modules if m.name == module).configure({param: value})
    loop = TickRecorder(arm.resource, resource_clock(arm.resource), overrun_limit=10**6)
    return task, loop.run_task(task, timeout_s=timeout_s)


def test_force_mode_presses_on_a_surface_with_the_force_asked_then_a_motion_follows(
    sim: UrSimProcess, arm: Session
) -> None:
    """configs/tasks/ur_press.toml: the controller's force mode, asked by the task's module
    every tick, brings the tool down onto a surface 3 cm below it (the simulator's wall) and
    presses with 20 N, which its sensor reads (the postcondition); the next task (a servoJ
    motion) ends force mode and moves the arm from where force mode left it."""
    res = arm.resource
    z0 = float(_tcp(res)[2])
    sim.inject("wall", point_m=[0.0, 0.0, z0 - 0.03], normal=[0.0, 0.0, 1.0], stiffness_n_m=5000)
    _, phase = _run_ur_task(arm, "ur_press", 20.0)
    assert phase is Phase.DONE and arm.event_names() == ["UrPress.done"], (
        arm.event_names(),
        res.fault_message,
    )
    assert float(res.signals["wrench"][2]) == pytest.approx(20.0, abs=3.0)
    assert float(_tcp(res)[2]) == pytest.approx(z0 - 0.03, abs=0.01)
    sim.inject("wall_remove")
    move_task, loop = move(arm, HOME)
    loop.run_for(0.1)  # the press task still writes nothing now: force mode ends in the first tick
    assert loop.run_task(move_task, timeout_s=20.0) is Phase.DONE, res.fault_message


def test_a_force_above_the_configs_limit_is_a_type_3_and_force_mode_never_starts(
    sim: UrSimProcess, arm: Session
) -> None:
    res = arm.resource
    before = _tcp(res)
    _, phase = _run_ur_task(arm, "ur_press", 5.0, press__wrench_n_nm=[0.0, 0.0, -80.0, 0.0, 0.0, 0.0])
    assert phase is Phase.FAULT and arm.event_names() == ["UrPress.T3.ResourceFault"], arm.event_names()
    assert "80 N asked, above force_mode_max_force_n = 50 N" in res.fault_message
    assert np.linalg.norm(_tcp(res) - before) < 0.002
    assert sim.status()["motion"] != "force_mode", sim.status()


def test_freedrive_follows_a_hand_and_a_motion_follows_it(sim: UrSimProcess, arm: Session) -> None:
    """configs/tasks/ur_freedrive.toml: a push on the tool (the simulator's hand) moves the arm
    while the task runs; the next task ends freedrive and moves the arm by servoJ."""
    res = arm.resource
    task = arm.task(ROOT / "configs/tasks/ur_freedrive.toml")
    loop = TickRecorder(res, resource_clock(res), overrun_limit=10**6)
    task.activate()
    loop.active = task
    loop.run_for(0.3)
    before = _tcp(res)
    sim.inject("push", force_n=[8.0, 0.0, 0.0], torque_nm=[0.0, 0.0, 0.0], duration_s=0.4)
    loop.run_for(1.5)
    moved = _tcp(res) - before
    assert moved[0] > 0.01 and task.phase is Phase.RUN, (moved, res.fault_message)
    move_task, loop2 = move(arm, HOME)
    assert loop2.run_task(move_task, timeout_s=20.0) is Phase.DONE, res.fault_message


def _tool_on_controller(res: Any) -> tuple[float, np.ndarray]:
    """The payload the controller reports (RTDE), and its TCP less the flange (base frame)."""
    d = res.diagnostics().details
    tcp = np.array([float(x) for x in str(d["tcp_pose_m_rad"]).split()])[:3]
    return float(d["payload_kg"]), tcp - _tcp(res)


def test_a_task_sets_the_payload_and_tcp_at_its_start_and_they_stay_across_a_reset(
    sim: UrSimProcess, arm: Session
) -> None:
    """configs/tasks/ur_carry.toml: its `ur_tool` sets 1.5 kg and a TCP 0.15 m beyond the flange
    in its first tick; the motion then runs to its target; the tool stays for the next task, and
    after a protective stop's reset (whose script restart sets the config's tool) it is sent again."""
    res = arm.resource
    _, phase = _run_ur_task(arm, "ur_carry", 30.0, traj__target_rad=REACH)
    events = arm.event_names()
    assert phase is Phase.DONE and events == ["UrCarry.done"], (events, res.fault_message)
    mass, offset = _tool_on_controller(res)
    assert mass == pytest.approx(1.5) and np.linalg.norm(offset) == pytest.approx(0.15, abs=2e-3)
    sim.inject("protective_stop")
    loop = TickRecorder(res, resource_clock(res), overrun_limit=10**6)
    loop.run_for(0.3)
    assert res.state.status & Status.FAULT
    res.safe_stop()
    reset_once_unlockable(res, loop)
    loop.run_for(0.5)
    res.clear_stop()
    mass, offset = _tool_on_controller(res)
    assert mass == pytest.approx(1.5) and np.linalg.norm(offset) == pytest.approx(0.15, abs=2e-3)
    task, loop2 = move(arm, HOME)
    assert loop2.run_task(task, timeout_s=20.0) is Phase.DONE, res.fault_message


def test_a_payload_above_the_arms_rating_asked_by_a_task_is_a_type_3_and_nothing_moves(
    sim: UrSimProcess, arm: Session
) -> None:
    res = arm.resource
    before, (mass_before, _) = _tcp(res), _tool_on_controller(res)
    _, phase = _run_ur_task(arm, "ur_carry", 5.0, traj__target_rad=REACH, tool__payload_kg=6.0)
    assert phase is Phase.FAULT and arm.event_names() == ["UrCarry.T3.ResourceFault"], arm.event_names()
    assert "payload 6 kg asked by the task exceeds the UR5e's rated 5 kg" in res.fault_message
    assert np.linalg.norm(_tcp(res) - before) < 0.002
    assert _tool_on_controller(res)[0] == mass_before
