"""The dynamixel resource against the simulated servo chain in another process (`python -m
orccadd.dxlsim` on a pseudo-terminal): startup checks, a position motion under a Robot-Task on
the wall clock, an overload and its reset, an unplugged servo, the port itself vanishing, CRC
noise, mode switches. Timing is checked to orders of magnitude only (a shared 2-core VM)."""

from __future__ import annotations

import re
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from dynamixel_sdk import COMM_SUCCESS, PacketHandler, PortHandler

from orccadd.drivers.dynamixel import table as T
from orccadd.dxlsim.process import DxlSimProcess
from orccadd.errors import ConfigError, ResourceError
from orccadd.fault import FaultKind
from orccadd.physres.dynamixel import DynamixelArm
from orccadd.robot import create_resource, load_robot_config
from orccadd.session import Session
from orccadd.task import RobotTask
from orccadd.task.loop import resource_clock
from orccadd.types import CommandMode, Phase, Status
from tests.conftest import ROOT, variant_text
from tests.safety import TickRecorder, assert_commands_within_limits, assert_safe_stop_in_time, status_shows

SIM = ROOT / "configs/robots/dxl-6axis-sim.toml"
MOVE_CSP = ROOT / "configs/tasks/move_joints_csp.toml"
TARGET = [0.6, -0.3, -1.2, 0.5, 0.4, -0.5]
BACK = [0.0, -0.16, -1.41, 0.0, 0.1, 0.0]
SETTINGS = "baud_rate = 4_000_000"
pytestmark = pytest.mark.timeout(120)

# the SDK's busy polling and the pty's worker: see tests/physres/conftest.py
LOOP_AT_REALTIME = False


@dataclass
class DxlRig:
    config: Path  # the robot config the simulator serves (its port)
    sim: DxlSimProcess
    sim_args: tuple[str, ...] = ()  # what it was started with

    @property
    def port(self) -> str:
        """The link the simulator serves: the resource's port."""
        return str(self.sim.port)

    def restart(self, *extra: str) -> None:
        """A new simulator on the same link (after `sim.kill()`: a USB adapter unplugged, then
        plugged back in): fresh servos, their torque off, their EEPROM the factory's."""
        self.sim.stop()
        self.sim = DxlSimProcess(self.config, *self.sim_args, *extra)

    def variant(self, *edits: tuple[str, str], name: str = "variant.toml") -> Path:
        """The rig's config with more edits (the resource's view; the simulator keeps its own)."""
        p = self.config.with_name(name)
        text = self.config.read_text()
        for old, new in edits:
            assert old in text, old
            text = text.replace(old, new, 1)
        p.write_text(text)
        return p


@contextmanager
def dxl_rig(
    tmp: Path, *edits: tuple[str, str], sim_args: tuple[str, ...] = (), base: Path = SIM
) -> Iterator[DxlRig]:
    """`base` (dxl-6axis-sim.toml) with `edits`, its port under `tmp`, and the simulator serving
    it (started with `sim_args`)."""
    config = tmp / "dxl.toml"
    port_line = re.search(r'^port = "[^"]*"$', base.read_text(), re.M)
    assert port_line, f"{base} names no port"
    config.write_text(variant_text(base, (port_line[0], f'port = "{tmp / "ttyDXL"}"'), *edits))
    # the servos are hardware: at real-time priority, above the test's loop (tests/physres/conftest.py)
    priority = () if "--priority" in sim_args else ("--priority", "70")
    rig = DxlRig(config, DxlSimProcess(config, *priority, *sim_args), (*priority, *sim_args))
    try:
        yield rig
    finally:
        rig.sim.stop()


@pytest.fixture
def rig(tmp_path: Path) -> Iterator[DxlRig]:
    with dxl_rig(tmp_path) as r:
        yield r


@pytest.fixture
def session(rig: DxlRig) -> Iterator[Session]:
    s = Session.from_config(load_robot_config(rig.config), CommandMode.POSITION)
    try:
        yield s
    finally:
        s.close()


def move(s: Session, target: list[float]) -> tuple[RobotTask, TickRecorder]:
    """The shipped position-mode move, reached within 0.01 rad: the servos' position loops (P
    only, their default gains) stop 3-4 ticks (~5 mrad) short against the gear's friction."""
    task_file = Path(s.config.source).with_name("move_csp.toml")
    task_file.write_text(variant_text(MOVE_CSP, ("tolerance_rad = 0.005", "tolerance_rad = 0.01")))
    task = s.task(task_file)
    next(m for m in task.modules if m.name == "traj").configure({"target_rad": target})
    loop = TickRecorder(s.resource, resource_clock(s.resource), overrun_limit=10**6)
    loop.active = task
    task.activate()
    return task, loop


def settle(s: Session, loop: TickRecorder, flag: Status, timeout_s: float) -> None:
    end = time.monotonic() + timeout_s
    while not s.resource.state.status & flag:
        assert time.monotonic() < end, f"no {flag!r} within {timeout_s} s: {s.resource.fault_message}"
        loop.executor.run(max_ticks=20)


# ---- startup -------------------------------------------------------------------------------------
def test_a_wrong_model_in_the_config_is_refused_naming_the_id(rig: DxlRig) -> None:
    wrong = rig.variant(('id = 4\nmodel = "XM430-W350"', 'id = 4\nmodel = "XM540-W270"'))
    res = create_resource(load_robot_config(wrong))
    with pytest.raises(ResourceError) as e:
        res.configure()
    assert "servo 4 (forearm_roll, XM540-W270): the servo with ID 4 is a XM430-W350 (1020), " in str(e.value)
    assert "the config says XM540-W270 (1120)" in str(e.value)
    missing = rig.variant(("id = 6\n", "id = 7\n"))
    res = create_resource(load_robot_config(missing))
    with pytest.raises(ResourceError, match=r"servo 7 \(wrist_rotate, XM430-W350\) does not answer a ping"):
        res.configure()


def test_a_period_shorter_than_the_chains_read_and_write_is_refused_at_config_load(tmp_path: Path) -> None:
    slow = tmp_path / "slow.toml"
    slow.write_text(
        variant_text(
            SIM,
            (SETTINGS, "baud_rate = 1_000_000"),
            ("control_period_s = 0.005", "control_period_s = 0.0003"),
        )
    )
    with pytest.raises(ConfigError) as e:
        load_robot_config(slow)
    msg = "control_period_s (=0.0003) must be at least the dynamixel resource's read + write time"
    assert msg in str(e.value) and "(0.00112 + 0.00044 s)" in str(e.value)  # 112 + 44 bytes at 1 Mbit/s


def test_category_0_is_refused_on_the_gravity_loaded_arm(tmp_path: Path) -> None:
    cat0 = tmp_path / "cat0.toml"
    cat0.write_text(variant_text(SIM, ("category = 2", "category = 0")))
    with pytest.raises(ConfigError) as e:
        load_robot_config(cat0)
    assert "safe_stop.category (=0) would drop the arm: the dynamixel resource has no brakes" in str(e.value)


def test_startup_writes_the_eeprom_and_enables_without_a_jump(rig: DxlRig) -> None:
    # a goal left far away by someone else: torque on must not head for it
    port = PortHandler(rig.sim.port)
    assert port.openPort() and port.setBaudRate(4_000_000)
    try:
        assert PacketHandler(2.0).write4ByteTxRx(port, 1, T.GOAL_POSITION.address, 3000) == (COMM_SUCCESS, 0)
    finally:
        port.closePort()
    res = create_resource(load_robot_config(rig.config))
    assert isinstance(res, DynamixelArm)
    try:
        res.configure()
        assert res.read(time.monotonic()).status & Status.TORQUE_OFF
        res.activate(CommandMode.POSITION)
        q0 = res.state.q_rad.copy()
        for _ in range(40):
            now = time.monotonic()
            res.read(now)
            res.keep_alive(now)
            time.sleep(0.005)
        assert np.abs(res.state.q_rad - q0).max() < 0.01
        servos = rig.sim.status()["servos"]
        assert all(s["torque_enable"] == 1 and s["operating_mode"] == 3 for s in servos)
        assert abs(servos[0]["goal_position"] - servos[0]["present_position"]) < 5
        assert [res.chain.read(j, T.RETURN_DELAY_TIME) for j in range(6)] == [0] * 6
        assert res.chain.read(0, T.VELOCITY_LIMIT) == 115
    finally:
        res.shutdown()


def sdk_torque_on(rig: DxlRig, dxl_id: int) -> None:
    """Another program left servo `dxl_id` enabled, holding where it is."""
    port = PortHandler(rig.sim.port)
    assert port.openPort() and port.setBaudRate(4_000_000)
    ph = PacketHandler(2.0)
    try:
        present, result, _ = ph.read4ByteTxRx(port, dxl_id, T.PRESENT_POSITION.address)
        assert result == COMM_SUCCESS
        assert ph.write4ByteTxRx(port, dxl_id, T.GOAL_POSITION.address, present) == (COMM_SUCCESS, 0)
        assert ph.write1ByteTxRx(port, dxl_id, T.TORQUE_ENABLE.address, 1) == (COMM_SUCCESS, 0)
    finally:
        port.closePort()


def test_a_servo_left_enabled_is_refused_if_its_eeprom_must_change_else_taken_over(rig: DxlRig) -> None:
    sdk_torque_on(rig, 3)  # factory EEPROM: Return Delay Time 250, Velocity Limit 128, ...
    res = create_resource(load_robot_config(rig.config))
    with pytest.raises(ResourceError) as e:
        res.configure()
    assert "servo 3 (elbow, XM540-W270) has its torque on and needs Return Delay Time(9) = 0" in str(e.value)
    assert rig.sim.status()["servos"][2]["torque_enable"] == 1  # never switched off under the arm
    port = PortHandler(rig.sim.port)
    assert port.openPort() and port.setBaudRate(4_000_000)
    assert PacketHandler(2.0).write1ByteTxRx(port, 3, T.TORQUE_ENABLE.address, 0) == (COMM_SUCCESS, 0)
    port.closePort()
    res = create_resource(load_robot_config(rig.config))
    res.configure()  # writes the EEPROM
    res.shutdown()
    sdk_torque_on(rig, 3)  # the same EEPROM now: the servo is taken over as it is
    res = create_resource(load_robot_config(rig.config))
    try:
        res.configure()
        res.activate(CommandMode.POSITION)
        assert all(s["torque_enable"] == 1 for s in rig.sim.status()["servos"])
        q0 = res.state.q_rad.copy()
        for _ in range(20):
            now = time.monotonic()
            res.read(now)
            res.keep_alive(now)
            time.sleep(0.005)
        assert np.abs(res.state.q_rad - q0).max() < 0.01
    finally:
        res.shutdown()


# ---- motion, faults ------------------------------------------------------------------------------
def test_a_position_motion_under_a_robot_task_on_the_wall_clock(rig: DxlRig, session: Session) -> None:
    task, loop = move(session, TARGET)
    loop.executor.run(max_ticks=1000, until=lambda: task.phase is not Phase.RUN)
    assert task.phase is Phase.DONE, (task.phase, task.fault_reason, session.resource.fault_message)
    np.testing.assert_allclose(session.resource.state.q_rad, TARGET, atol=0.01)
    np.testing.assert_allclose(rig.sim.status()["q_rad"], TARGET, atol=0.01)  # the arm, not a register
    ticks = loop.ticks()
    assert_commands_within_limits(ticks, session.config)
    assert not (ticks.status.astype(int) & (Status.FAULT | Status.COMM_LOST | Status.LIMIT_VIOLATION)).any()


def test_the_4_dof_openmanipulator_x_moves_under_a_robot_task(tmp_path: Path) -> None:
    """configs/robots/openmanipulator-x-sim.toml: four XM430-W350 (ids 11-14) at 1 Mbit/s; a
    waist swing to a pose that needs little torque (the P-only loops sag by load/stiffness)."""
    config = tmp_path / "omx.toml"
    port = ('port = "/tmp/orccadd-omx"', f'port = "{tmp_path / "ttyOMX"}"')
    config.write_text(variant_text(ROOT / "configs/robots/openmanipulator-x-sim.toml", port))
    target = [0.8, -0.35, -0.85, -0.9]
    sim = DxlSimProcess(config, "--priority", "70")
    try:
        s = Session.from_config(load_robot_config(config), CommandMode.POSITION)
        try:
            task, loop = move(s, target)
            loop.executor.run(max_ticks=1000, until=lambda: task.phase is not Phase.RUN)
            assert task.phase is Phase.DONE, (task.phase, task.fault_reason, s.resource.fault_message)
            st = sim.status()
            np.testing.assert_allclose(st["q_rad"], target, atol=0.01)
            assert [sv["position_pid"] for sv in st["servos"]] == [[800, 100, 0]] * 4  # the config's I gain
            assert_commands_within_limits(loop.ticks(), s.config)
        finally:
            s.close()
    finally:
        sim.stop()


def test_an_overload_mid_motion_faults_stops_and_a_reset_reboots_the_servo(
    rig: DxlRig, session: Session
) -> None:
    res = session.resource
    task, loop = move(session, TARGET)
    loop.run_for(0.2)  # moving
    rig.sim.inject("overload", device=1)
    loop.executor.run(max_ticks=60)
    assert task.phase is Phase.FAULT
    assert [n for n in session.event_names() if ".T3." in n] == ["MoveJointsCSP.T3.ResourceFault"]
    assert "servo 1 (waist, XM540-W270): hardware error: overload (bit 5)" in res.fault_message
    assert res.state.fault_code == 1 << 8 | 0x20
    ticks = loop.ticks()
    assert_safe_stop_in_time(ticks, status_shows(ticks, Status.FAULT))
    assert_commands_within_limits(ticks, session.config)
    settle(session, loop, Status.STOPPED, 5.0)
    assert not res.state.status & Status.TORQUE_OFF  # category 2: the others hold
    res.reset_fault()
    servo1 = rig.sim.status()["servos"][0]
    assert (servo1["hardware_error_status"], servo1["torque_enable"]) == (0, 1)  # rebooted, re-enabled
    res.read(time.monotonic())
    assert not res.state.status & Status.FAULT and res.fault_message == ""
    res.clear_stop()
    again, loop = move(session, BACK)
    loop.executor.run(max_ticks=1000, until=lambda: again.phase is not Phase.RUN)
    assert again.phase is Phase.DONE, (again.fault_reason, res.fault_message)
    np.testing.assert_allclose(res.state.q_rad, BACK, atol=0.01)


def test_an_unplugged_servo_is_comm_lost_naming_it(rig: DxlRig, session: Session) -> None:
    res = session.resource
    task, loop = move(session, TARGET)
    loop.run_for(0.2)
    rig.sim.inject("unplug", device=5)
    loop.executor.run(max_ticks=60)
    assert task.phase is Phase.FAULT
    assert [n for n in session.event_names() if ".T3." in n] == ["MoveJointsCSP.T3.CommLost"]
    assert (
        "servo 5 (wrist_angle, XM430-W350) does not answer: 10 sync reads in a row stopped"
        in res.fault_message
    )
    ticks = loop.ticks()
    assert_safe_stop_in_time(ticks, status_shows(ticks, Status.COMM_LOST))
    assert_commands_within_limits(ticks, session.config)
    settle(session, loop, Status.STOPPED, 5.0)  # the other five are still read and stopped
    assert res.diagnostics().details["lost"] == "servo 5 (wrist_angle, XM430-W350)"


def _until(ok: Callable[[], bool], what: str, timeout_s: float = 20.0) -> None:
    """Poll `ok` until it holds (a generous bound: this is a condition, not a timing check)."""
    end = time.monotonic() + timeout_s
    while not ok():
        assert time.monotonic() < end, f"{what}: not within {timeout_s:g} s"
        time.sleep(0.01)


def test_the_port_vanishing_mid_motion_is_comm_lost_naming_it_and_a_reset_reopens_it_once_back(
    rig: DxlRig, session: Session
) -> None:
    """The servo simulator killed mid-motion, as a USB adapter unplugged: its pseudo-terminal hangs
    up (always readable, reads end of file, writes and tcflush fail with EIO). It was: the tick
    that met it raised termios.error, the next one spun for ever in `drop_late_reply` holding the
    chain's lock (no more ticks, no CommLost, a reset and SIGTERM waiting on the lock). Now:
    CommLost naming the port in the first tick after the kill, the safe stop in that tick, the
    loop ticking on; `reset` refused naming the port while it is gone; the simulator restarted
    on the same link: `reset` opens it and checks the chain (fresh servos: EEPROM written, torque
    off), `clear_stop` enables them holding, and the arm moves again."""
    res = session.resource
    assert isinstance(res, DynamixelArm)
    task, loop = move(session, TARGET)
    loop.run_for(0.2)
    before = len(loop.ticks().seq)
    rig.sim.kill()
    loop.executor.run(max_ticks=200, until=lambda: task.phase is not Phase.RUN)
    assert task.phase is Phase.FAULT, (task.phase, res.fault_message)
    loop.executor.run(max_ticks=5)  # the next tick's read shows the stop
    assert [n for n in session.event_names() if ".T3." in n] == ["MoveJointsCSP.T3.CommLost"]
    assert f"arm: the port {rig.port} is gone (" in res.fault_message, res.fault_message
    ticks = loop.ticks()
    lost = [i for i in range(len(ticks.seq)) if int(ticks.status[i]) & Status.COMM_LOST]
    assert lost and lost[0] - before < 2, (before, lost[:3])  # the first tick after the kill
    assert_safe_stop_in_time(ticks, status_shows(ticks, Status.COMM_LOST))
    assert_commands_within_limits(ticks, session.config)
    settle(session, loop, Status.STOPPED, 20.0)  # position mode: each servo holds its last goal
    assert loop.executor.run(max_ticks=40) == 40  # the loop ticks on, the port left alone
    with pytest.raises(ResourceError) as e:
        res.reset_fault()
    assert f"arm: the port {rig.port} is still gone (cannot open the DYNAMIXEL port {rig.port}" in str(
        e.value
    )
    assert "plug its adapter back in, then reset again" in str(e.value)
    rig.restart("--initial-q-rad", ",".join(f"{q:.6f}" for q in res.state.q_rad))
    res.reset_fault()
    loop.executor.run(max_ticks=400, until=lambda: not res.state.status & Status.COMM_LOST)
    assert not res.state.status & (Status.COMM_LOST | Status.FAULT), res.fault_message
    assert res.fault_message == ""
    assert [res.chain.read(j, T.RETURN_DELAY_TIME) for j in range(6)] == [0] * 6  # EEPROM written again
    res.clear_stop()
    assert all(sv["torque_enable"] == 1 for sv in rig.sim.status()["servos"])
    again, loop = move(session, BACK)
    loop.executor.run(max_ticks=1000, until=lambda: again.phase is not Phase.RUN)
    assert again.phase is Phase.DONE, (again.fault_reason, res.fault_message)
    np.testing.assert_allclose(rig.sim.status()["q_rad"], BACK, atol=0.01)


def test_the_port_found_gone_by_a_write_is_comm_lost_in_words_in_that_tick(
    rig: DxlRig, session: Session
) -> None:
    """A tick's write may be the first to meet the vanished port (write(2) and tcflush fail with
    EIO): the CommLost it returns already has the words, for the type 3 of that tick."""
    res = session.resource
    assert isinstance(res, DynamixelArm)
    assert not tick_holding(res, 10) & (Status.FAULT | Status.COMM_LOST), res.fault_message
    rig.sim.kill()
    assert res.write(time.monotonic(), res.state.q_rad.copy()) & Status.COMM_LOST  # hold where it is
    assert res.fault is not None and res.fault.kind is FaultKind.COMM_LOST, res.fault
    assert f"arm: the port {rig.port} is gone (" in res.fault_message, res.fault_message
    assert res.read(time.monotonic()).status & Status.COMM_LOST


class Ticker:
    """Read + keep_alive every 5 ms in a thread of its own, as the daemon's control thread: the
    safe stop called in the tick that first reads CommLost (as a task's type 3 would)."""

    def __init__(self, res: DynamixelArm) -> None:
        self.res = res
        self.ticks = 0
        self.first_lost = -1  # the tick that first read CommLost
        self.seen = 0  # the status flags read (`forget` starts again)
        self._forget = threading.Event()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="ticker", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        res = self.res
        while not self._stop.is_set():
            now = time.monotonic()
            status = res.read(now).status
            if self._forget.is_set():
                self._forget.clear()
                self.seen = 0
            self.seen |= status
            if status & Status.COMM_LOST and self.first_lost < 0:
                self.first_lost = self.ticks
                res.safe_stop()
            res.keep_alive(now)
            self.ticks += 1
            time.sleep(0.005)

    def forget(self) -> None:
        """`seen` from the next tick on (the ticker's own thread clears it)."""
        self._forget.set()
        _until(lambda: not self._forget.is_set(), "the ticker forgetting")

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(20.0)
        assert not self._thread.is_alive(), "a tick never returned"


@pytest.mark.parametrize("mode", [CommandMode.POSITION, CommandMode.VELOCITY])
def test_the_port_vanishing_while_holding_is_comm_lost_the_ticks_go_on_and_a_reset_reopens_it(
    rig: DxlRig, session: Session, mode: CommandMode
) -> None:
    """The port vanishes while the arm holds (no task: read and keep_alive, as the Hold task):
    CommLost naming the port within two ticks of the kill, the ticks go on, and the stop counts
    as done: at once in position mode (each servo holds its last goal), once the Bus Watchdog's
    time has passed in velocity mode (the servos stop on it). The simulator restarted, `reset`
    and `clear_stop` run beside the ticks (as the daemon's reset thread does): the fresh servos
    take the mode's Operating Mode and hold the arm, the ticks never stopping."""
    res = session.resource
    assert isinstance(res, DynamixelArm)
    if mode is not CommandMode.POSITION:
        res.switch_mode(mode)
    assert not tick_holding(res, 20) & (Status.FAULT | Status.COMM_LOST), res.fault_message
    ticker = Ticker(res)
    try:
        _until(lambda: ticker.ticks > 20, "the ticker running")
        at_kill = ticker.ticks
        rig.sim.kill()
        _until(lambda: ticker.first_lost >= 0, "CommLost")
        assert ticker.first_lost - at_kill <= 2, (at_kill, ticker.first_lost)
        assert f"arm: the port {rig.port} is gone (" in res.fault_message, res.fault_message
        _until(lambda: bool(res.state.status & Status.STOPPED), "the stop counted as done")
        ticks = ticker.ticks
        _until(lambda: ticker.ticks > ticks + 40, "the ticks going on")
        with pytest.raises(ResourceError, match="is still gone"):
            res.reset_fault()
        rig.restart("--initial-q-rad", ",".join(f"{q:.6f}" for q in res.state.q_rad))
        res.reset_fault()
        _until(lambda: not res.state.status & Status.COMM_LOST, "reads without CommLost")
        res.clear_stop()
        ticker.forget()
        ticks = ticker.ticks
        q0 = rig.sim.status()["q_rad"]
        _until(lambda: ticker.ticks > ticks + 60, "the ticks holding")
        q1 = rig.sim.status()["q_rad"]
    finally:
        ticker.stop()
    assert not ticker.seen & (Status.FAULT | Status.COMM_LOST | Status.TORQUE_OFF), res.fault_message
    code = {CommandMode.POSITION: 3, CommandMode.VELOCITY: 1}[mode]
    servos = rig.sim.status()["servos"]
    assert all(sv["operating_mode"] == code and sv["torque_enable"] == 1 for sv in servos), servos
    assert max(abs(a - b) for a, b in zip(q0, q1, strict=True)) < 0.02, (q0, q1)  # held


def test_crc_noise_below_the_threshold_is_counted_and_the_motion_completes(
    rig: DxlRig, session: Session
) -> None:
    rig.sim.inject("noise", rate=0.001)  # ~9 % of the 92-byte status packets damaged
    try:
        task, loop = move(session, TARGET)
        loop.executor.run(max_ticks=1000, until=lambda: task.phase is not Phase.RUN)
    finally:
        rig.sim.inject("clear")
    assert task.phase is Phase.DONE, (task.fault_reason, session.resource.fault_message)
    details = session.resource.diagnostics().details
    assert int(details["crc_errors"]) > 0, details
    assert not (loop.ticks().status.astype(int) & Status.COMM_LOST).any()


def test_replies_a_little_late_are_dropped_whole_never_read_as_the_next_cycles(tmp_path: Path) -> None:
    """Two cyclic reads answered later than their deadline (wire time + read_timeout_s) and later
    than the next tick's request would go (half a millisecond past the 5 ms period): each is a
    timeout of the servo whose part was missing (the first), and its reply is waited for and
    dropped whole before the next request. Without that, the next request's read takes it as its
    own reply (the SDK drops only what is there before the request goes): one cycle stale, its own
    reply then late in turn, the shift going on until CommLost. The motion completes. The
    simulator at a real-time priority, as servos answer whatever the PC does (a loaded machine's
    own late replies are dropped whole too)."""
    with dxl_rig(tmp_path, sim_args=("--priority", "70")) as rig:
        s = Session.from_config(load_robot_config(rig.config), CommandMode.POSITION)
        try:
            res = s.resource
            task, loop = move(s, TARGET)
            loop.run_for(0.2)
            deadline_ms = float(res.diagnostics().details["cycle_deadline_ms"])
            margin_ms = 1e3 * res.settings.read_timeout_s
            wire_ms = deadline_ms - margin_ms
            period_ms = 1e3 * s.config.control_period_s
            assert period_ms + 0.5 < deadline_ms + margin_ms  # late past the period, within the drop
            rig.sim.request({"inject": "late", "ms": period_ms - wire_ms + 0.5, "packets": 2})
            loop.executor.run(max_ticks=1000, until=lambda: task.phase is not Phase.RUN)
            assert task.phase is Phase.DONE, (task.fault_reason, res.fault_message)
            d = res.diagnostics().details
            assert not (loop.ticks().status.astype(int) & Status.COMM_LOST).any()
        finally:
            s.close()
    reply_bytes = 8 + 6 * (10 + 4)  # the fast sync read's one status packet for six servos
    timeouts = int(d["timeouts"])  # a late reply already there when the read begins is on time
    assert timeouts >= 1 and d["timeouts_by_servo"] == f"1: {timeouts}, 2: 0, 3: 0, 4: 0, 5: 0, 6: 0", d
    # Dropped whole: a number of status packets, never a part of one. One per timeout whose reply
    # came within the drop window: each injected one does; a reply the loaded machine itself made
    # later than that window is cleared before the next request instead (the SDK's clearPort).
    dropped, part = divmod(int(d["late_bytes_dropped"]), reply_bytes)
    assert part == 0 and 1 <= dropped <= timeouts and int(d["crc_errors"]) == 0, d


def test_mode_switches_hold_the_arm(rig: DxlRig, session: Session) -> None:
    res = session.resource
    assert res.description.mode_switch_needs_disable
    q0 = res.read(time.monotonic()).q_rad.copy()

    def hold(seconds: float) -> int:
        seen = 0
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            now = time.monotonic()
            seen |= res.read(now).status
            res.keep_alive(now)
            time.sleep(0.005)
        return seen

    for mode, code in ((CommandMode.VELOCITY, 1), (CommandMode.TORQUE, 0), (CommandMode.POSITION, 3)):
        res.switch_mode(mode)
        seen = hold(0.3)
        assert not seen & (Status.FAULT | Status.COMM_LOST | Status.TORQUE_OFF), (mode, res.fault_message)
        servos = rig.sim.status()["servos"]
        assert all(s["operating_mode"] == code and s["torque_enable"] == 1 for s in servos), mode
        assert np.abs(res.state.q_rad - q0).max() < 0.02, mode


def tick_holding(res: DynamixelArm, ticks: int) -> int:
    """`ticks` ticks of read + keep_alive 5 ms apart: the OR of the status flags read."""
    seen = 0
    for _ in range(ticks):
        now = time.monotonic()
        seen |= res.read(now).status
        res.keep_alive(now)
        time.sleep(0.005)
    return seen


def test_the_plain_sync_read_names_a_missing_servo_too(rig: DxlRig) -> None:
    """`fast_sync_read = false` (firmware without it): one status packet per servo."""
    plain = rig.variant((SETTINGS, f"{SETTINGS}\nfast_sync_read = false"))
    cfg = load_robot_config(plain)
    assert DynamixelArm.describe(cfg).read_time_s == pytest.approx((20 + 6 * 21) * 10 / 4e6)
    res = create_resource(cfg)
    try:
        res.configure()
        res.activate(CommandMode.POSITION)
        assert not tick_holding(res, 20) & (Status.FAULT | Status.COMM_LOST), res.fault_message
        rig.sim.inject("unplug", device=2)
        for _ in range(20):
            now = time.monotonic()
            if res.read(now).status & Status.COMM_LOST:
                break
            res.keep_alive(now)
        assert "servo 2 (shoulder, XM540-W270) does not answer" in res.fault_message
    finally:
        res.shutdown()


def test_a_servo_without_fast_sync_read_makes_the_cycle_a_plain_sync_read_and_describe_says_so(
    tmp_path: Path,
) -> None:
    """Fast Sync Read came with firmware 45: a servo with older firmware does not answer it, so
    the backend checks every servo's Firmware Version at startup and reads the chain by plain
    Sync Read (one status packet per servo) where one lacks it; where that would not fit in the
    period, it is refused naming the servo."""
    with dxl_rig(tmp_path, sim_args=("--firmware", "3=44")) as rig:
        res = create_resource(load_robot_config(rig.config))
        try:
            res.configure()
            res.activate(CommandMode.POSITION)
            assert not tick_holding(res, 40) & (Status.FAULT | Status.COMM_LOST), res.fault_message
            said = str(res.diagnostics().details["sync_read"])
            assert said.startswith("sync read: servo 3 (") and "has firmware 44" in said, said
            assert res.description.read_time_s == pytest.approx((20 + 6 * 21) * 10 / 4e6)
        finally:
            res.shutdown()
        tight = rig.variant(
            ("control_period_s = 0.005", "control_period_s = 0.0014"),
            (SETTINGS, f"{SETTINGS}\nread_timeout_s = 0.001"),
            name="tight.toml",
        )  # the fast read (0.39 ms with the write) and its timeout fit in 1.4 ms, the plain one not
        res = create_resource(load_robot_config(tight))
        with pytest.raises(ResourceError, match=r"servo 3 \(.*has firmware 44.*Update the servos' firmware"):
            res.configure()
        res.shutdown()


def test_servos_with_fast_sync_read_keep_it() -> None:
    assert DynamixelArm.describe(load_robot_config(SIM)).read_time_s < (20 + 6 * 21) * 10 / 4e6
