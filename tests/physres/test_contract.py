"""The Physical Resource contract, re-run by every backend (on the wall clock)."""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from orccadd.ecatsim.process import EcatSimProcess
from orccadd.errors import ResourceError
from orccadd.fault import FaultKind
from orccadd.physres import PhysicalResource
from orccadd.physres.description import ClockSource, Source
from orccadd.robot import create_resource, load_robot_config, with_backend
from orccadd.state import JointState
from orccadd.types import CommandMode, Lifecycle, Status
from orccadd.ursim.process import UrSimProcess
from tests.canopen_rig import Rig, canopen_rig
from tests.conftest import ROOT, UR5E, variant_text
from tests.physres.test_dynamixel import DxlRig, dxl_rig

BACKENDS = ["sim", "sim_process", "canopen402", "dynamixel", "ur_rtde", "ethercat402"]
# the shipped config each backend's description is read from at collection (`describe` needs no
# device): a test in a mode the backend does not declare is not generated for it at all
UR_SIM = ROOT / "configs/robots/ur5e-rtde-sim.toml"
ECAT_SIM = ROOT / "configs/robots/ethercat-6axis-sim.toml"
UNLOCK_DELAY_S = 1  # the simulated UR controller's: a protective stop can be unlocked 1 s after it

# ur_rtde blocks in C++ holding the interpreter: only a thread can time such a test out
pytestmark = pytest.mark.timeout(120, method="thread")


@pytest.fixture(scope="module")
def can_rig(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Rig]:
    """One bus and six simulated CiA 402 drives (separate processes) for the module's tests."""
    with canopen_rig(tmp_path_factory.mktemp("contract-rig")) as rig:
        yield rig


@pytest.fixture
def dxl(tmp_path: Path) -> Iterator[DxlRig]:
    """Six simulated DYNAMIXEL servos (a separate process, one per test: a test may leave the
    arm fallen), the contract's category 1 allowed by declaring torque off at rest safe."""
    with dxl_rig(
        tmp_path,
        ("category = 2", "category = 1"),
        ("deceleration_rad_s2 = 4.0", "deceleration_rad_s2 = 10.0"),
        ("baud_rate = 4_000_000", "baud_rate = 4_000_000\ntorque_off_at_rest = true"),
    ) as rig:
        yield rig


@pytest.fixture(scope="module")
def ur_sim(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[Path, UrSimProcess]]:
    """A simulated UR controller (a separate process) for the module's tests, and the config
    that reaches it: the contract's category 1 (power off at rest), so `power_on` for the next."""
    config = tmp_path_factory.mktemp("contract-ur") / "ur.toml"
    config.write_text(
        variant_text(
            UR_SIM,
            ("category = 2", "category = 1"),
            ('host = "127.0.0.1"', 'host = "127.0.0.1"\npower_on = true'),
        )
    )
    unlock = ("--unlock-delay-s", str(UNLOCK_DELAY_S))
    with UrSimProcess(UR_SIM, "--boot", "running", *unlock, "--priority", "70") as sim:
        yield config, sim


@pytest.fixture(scope="module")
def ecat_sim() -> Iterator[EcatSimProcess]:
    """Six simulated EtherCAT drives on a veth link (a separate process, root: its namespace)."""
    if os.geteuid() != 0:
        pytest.skip("the EtherCAT simulator's link needs root")
    with EcatSimProcess(ECAT_SIM, "--priority", "70") as sim:
        yield sim


@pytest.fixture(params=BACKENDS)
def resource(request: pytest.FixtureRequest) -> Iterator[PhysicalResource]:
    if request.param == "canopen402":
        cfg = load_robot_config(request.getfixturevalue("can_rig").config)
    elif request.param == "dynamixel":
        cfg = load_robot_config(request.getfixturevalue("dxl").config)
    elif request.param == "ur_rtde":
        cfg = load_robot_config(request.getfixturevalue("ur_sim")[0])
    elif request.param == "ethercat402":
        request.getfixturevalue("ecat_sim")
        cfg = load_robot_config(ECAT_SIM)
    else:
        cfg = with_backend(load_robot_config(UR5E), request.param)
    res = create_resource(cfg)
    res.configure()
    yield res
    if res.lifecycle is not Lifecycle.FINALIZED:
        res.shutdown()


@pytest.fixture
def inject_device_fault(
    request: pytest.FixtureRequest, resource: PhysicalResource
) -> tuple[Callable[[], None], str]:
    """Make the device report a fault: through the resource where it declares injection, at
    the device otherwise (a simulated drive's over-current); and the joint the fault is about
    ("" for the whole arm)."""
    third = resource.model.joint_names[2]
    if "device" in resource.description.fault_injection:
        return (lambda: resource.inject_fault("device", "over-current")), ""
    if resource.description.backend == "dynamixel":
        dxl: DxlRig = request.getfixturevalue("dxl")
        return (lambda: dxl.sim.inject("overload", device=3)), third  # ID 3: the third joint
    if resource.description.backend == "ur_rtde":
        sim: UrSimProcess = request.getfixturevalue("ur_sim")[1]
        return (lambda: sim.inject("protective_stop")), ""  # the controller stops the whole arm
    if resource.description.backend == "ethercat402":
        ecat: EcatSimProcess = request.getfixturevalue("ecat_sim")
        return (lambda: ecat.inject("overcurrent", device=3)), third  # the third slave on the line
    rig: Rig = request.getfixturevalue("can_rig")
    return (lambda: rig.drives.inject("overcurrent", device=3)), third  # node 3: the third joint


def hold_mode(res: PhysicalResource) -> CommandMode:
    """Torque where the backend has it (gravity compensation holds the arm), position otherwise."""
    return CommandMode.TORQUE if CommandMode.TORQUE in res.description.modes else CommandMode.POSITION


def drive(
    res: PhysicalResource,
    seconds: float,
    push: float = 0.0,
    until: Callable[[JointState], bool] | None = None,
) -> None:
    """Hold the arm every period on the wall clock, and push it: in torque mode gravity
    compensation + `push` N·m on every joint, in position mode joint 0 moving at `push` / 10 rad/s.
    `until`: return as soon as a read state satisfies it (at most `seconds` all the same)."""
    data = res.model.new_data()
    period = res.config.control_period_s
    t_start = time.monotonic()
    t_end = t_start + seconds
    target = res.read(time.monotonic()).q_rad.copy()
    q0 = float(target[0])
    while time.monotonic() < t_end:
        st = res.read(time.monotonic())
        if res.mode is CommandMode.POSITION:
            # on the wall clock, not per pass: a busy machine makes passes longer than a period
            target[0] = q0 + push / 10 * (time.monotonic() - t_start)
            res.write(time.monotonic(), target)
        else:
            res.write(time.monotonic(), pin.computeGeneralizedGravity(res.model.model, data, st.q_rad) + push)
        if until is not None and until(st):
            return
        time.sleep(period)


def at_rest(st: JointState, flags: Status) -> bool:
    """`flags` all set and every joint still (what a stop ends in)."""
    return st.status & flags == flags and bool(np.abs(st.dq_rad_s).max() < 0.01)


def test_activate_reports_the_measured_position(resource: PhysicalResource) -> None:
    resource.activate(hold_mode(resource))
    q0 = resource.state.q_rad.copy()
    assert np.abs(q0).max() > 0.1  # the configured initial pose, not zeros
    drive(resource, 0.2)
    assert np.abs(resource.state.q_rad - q0).max() < 0.01
    assert not resource.state.status & (Status.FAULT | Status.COMM_LOST | Status.LIMIT_VIOLATION)


@pytest.mark.applies(mode=CommandMode.TORQUE)
def test_torque_beyond_limit_is_clamped(resource: PhysicalResource) -> None:
    resource.activate(CommandMode.TORQUE)
    resource.read(time.monotonic())
    flags = resource.write(time.monotonic(), np.full(resource.dof, 1e4))
    assert flags & Status.CMD_CLAMPED and not flags & Status.LIMIT_VIOLATION
    resource.safe_stop()


def test_position_steps_within_the_speed_limit_pass_unchanged(resource: PhysicalResource) -> None:
    # 0.1 + (0.3 - 0.1) == 0.30000000000000004: a step that needs no clamping must not be
    # rebuilt from the last command (that flagged a limit violation on exact commands)
    resource.activate(CommandMode.POSITION)
    q = resource.read(time.monotonic()).q_rad.copy()
    for x in np.linspace(q[0], 0.0, 100):  # bring joint 0 to zero at an allowed speed
        q[0] = x
        assert not resource.write(time.monotonic(), q) & Status.LIMIT_VIOLATION
    for k in range(1, 200):  # hovering around zero, as a held joint does: there it rounds
        cmd = q.copy()
        cmd[0] = 1e-7 * k * (1.0 if k % 3 else -0.37)
        flags = resource.write(time.monotonic(), cmd)
        assert not flags & (Status.CMD_CLAMPED | Status.LIMIT_VIOLATION), (k, flags)
    fast = q + 1.0  # a jump no joint can make in one period
    flags = resource.write(time.monotonic(), fast)
    assert flags & Status.CMD_CLAMPED and flags & Status.LIMIT_VIOLATION
    joint = resource.model.joint_names[0]
    f = resource.fault
    assert f is not None and (f.kind, f.resource, f.joint) == (FaultKind.LIMIT, resource.name, joint), f
    assert f.text.startswith(f"command clamped: commanded position of {joint} "), f
    resource.safe_stop()


def test_safe_stop_brings_the_arm_to_rest(resource: PhysicalResource) -> None:
    resource.activate(hold_mode(resource))
    drive(resource, 0.3, push=3.0)
    assert np.abs(resource.state.dq_rad_s).max() > 0.2
    assert resource.config.safe_stop.category == 1  # sim-ur5e's: decelerate, then torque off
    resource.safe_stop()
    st = resource.read(time.monotonic())
    assert st.status & Status.STOPPING and not st.status & Status.TORQUE_OFF, Status(st.status)
    stopped_torque_off = Status.STOPPED | Status.TORQUE_OFF
    drive(resource, 2.0, until=lambda s: at_rest(s, stopped_torque_off))
    st = resource.state
    assert st.status & stopped_torque_off == stopped_torque_off, Status(st.status)
    assert np.abs(st.dq_rad_s).max() < 0.01


def test_device_fault_is_reported_and_reset(
    resource: PhysicalResource, inject_device_fault: tuple[Callable[[], None], str]
) -> None:
    inject, joint = inject_device_fault
    resource.activate(hold_mode(resource))
    drive(resource, 0.05)
    inject()
    injected_s = time.monotonic()
    drive(resource, 0.3, until=lambda s: bool(s.status & Status.FAULT))
    assert resource.state.status & Status.FAULT
    f = resource.fault  # typed: a device fault of this resource, about that joint, in words
    assert f is not None and (f.kind, f.resource, f.joint) == (FaultKind.DEVICE, resource.name, joint), f
    assert f.text and f.code, f  # the device's own code: EMCY, hardware error bits, safety mode
    resource.safe_stop()
    # stopped, and past the UR controller's unlock delay (a protective stop is reset 1 s after it)
    reset_allowed_s = injected_s + UNLOCK_DELAY_S + 0.2
    drive(
        resource,
        2.0,
        until=lambda s: bool(s.status & Status.STOPPED) and time.monotonic() > reset_allowed_s,
    )
    assert resource.state.status & Status.STOPPED
    assert resource.description.fault_reset
    resource.reset_fault()
    drive(resource, 0.5, until=lambda s: not s.status & Status.FAULT)
    assert not resource.state.status & Status.FAULT, resource.fault_message
    resource.clear_stop()
    drive(resource, 0.2)
    assert not resource.state.status & (Status.FAULT | Status.STOPPED | Status.STOPPING)


@pytest.mark.applies(mode="mode")  # the `mode` parameter's
@pytest.mark.parametrize("mode", [CommandMode.TORQUE, CommandMode.POSITION])
def test_a_command_with_nan_or_inf_is_not_sent(resource: PhysicalResource, mode: CommandMode) -> None:
    resource.activate(mode)
    st = resource.read(time.monotonic())
    good = np.zeros(resource.dof) if mode is CommandMode.TORQUE else st.q_rad.copy()
    for bad_value in (np.nan, np.inf, -np.inf):
        bad = good.copy()
        bad[2] = bad_value
        flags = resource.write(time.monotonic(), bad)
        assert flags & Status.LIMIT_VIOLATION, (bad_value, flags)  # a type 3 exception for the task
    assert resource.rejected_count == 3
    assert resource.fault is not None and resource.fault.kind is FaultKind.COMMAND, resource.fault
    assert "NaN or an infinity" in resource.fault.text
    drive(resource, 0.05)  # the device never saw them: the arm's state stays finite
    assert np.isfinite(resource.state.vector).all()
    resource.safe_stop()


def test_the_description_matches_the_config_and_the_device(resource: PhysicalResource) -> None:
    d = resource.description
    cfg = resource.config
    assert d.backend == cfg.resource.backend
    assert d.joints == cfg.joint_names
    assert resource.supported_modes and resource.supported_modes <= d.modes
    assert cfg.safe_stop.category in d.stop_categories
    assert d.read_time_s + d.write_time_s <= cfg.control_period_s
    assert d.position.source is not Source.ABSENT  # every backend measures where the arm is


def test_diagnostics_are_a_typed_snapshot(resource: PhysicalResource) -> None:
    resource.activate(hold_mode(resource))
    drive(resource, 0.05)
    diag = resource.diagnostics()
    assert diag.backend == resource.description.backend
    assert diag.lifecycle == "active" and diag.mode == hold_mode(resource).name.lower()
    assert diag.fault_message == "" and "fault" not in diag.status
    assert all(isinstance(v, int | float | str) for v in diag.details.values())


def test_ticks_without_a_command_keep_the_arm_held(resource: PhysicalResource) -> None:
    """read + keep_alive (a task waiting for its preconditions): the device keeps its holding
    command and none of its watchdogs trips."""
    resource.activate(CommandMode.POSITION)
    q0 = resource.read(time.monotonic()).q_rad.copy()
    t_end = time.monotonic() + 0.3  # longer than the plant's command watchdog (100 ms)
    seen = 0
    while time.monotonic() < t_end:
        now = time.monotonic()
        seen |= resource.read(now).status
        resource.keep_alive(now)
        time.sleep(resource.config.control_period_s)
    assert not seen & (Status.FAULT | Status.COMM_LOST | Status.LIMIT_VIOLATION), resource.fault_message
    assert np.abs(resource.state.q_rad - q0).max() < 0.01


def test_undeclared_optional_interfaces_are_refused(resource: PhysicalResource) -> None:
    with pytest.raises(ResourceError, match="cannot inject a 'meteor' fault"):
        resource.inject_fault("meteor", "x")
    if resource.description.clock is ClockSource.LOOP:
        with pytest.raises(ResourceError, match="paced by the loop"):
            resource.wait_for_cycle(0.01)
