"""Task files and wiring: good ones build, bad ones are refused naming both ends or the cycle."""

from __future__ import annotations

import numpy as np
import pytest

from orccadd.errors import ConfigError, WiringError
from orccadd.session import Session
from orccadd.task import load_task_file
from orccadd.task.builder import build_task
from orccadd.types import CommandMode
from tests.conftest import MOVE_TASK, UR5E


@pytest.fixture
def session():  # type: ignore[no-untyped-def]
    s = Session.open(UR5E)
    yield s
    s.close()


def build(session: Session, path):  # type: ignore[no-untyped-def]
    return build_task(load_task_file(path), session.resource, session.registry, session.queue)


def test_shipped_task_builds_in_dependency_order(session: Session) -> None:
    task = build(session, MOVE_TASK)
    order = [m.name for m in task.modules]
    assert order.index("traj") < order.index("ct")
    assert order.index("traj") < order.index("reached")
    sig = task.signature
    assert sig.name == "MoveJoints" and sig.command is CommandMode.TORQUE and sig.has_post
    assert "TrackingLost" in sig.t2 and "PreconditionTimeout" in sig.t2
    assert {"NearJointLimit", "LimitViolation", "ResourceFault", "Overrun"} <= set(sig.t3)
    names = session.registry.names()
    assert "MoveJoints.done" in names and "MoveJoints.T2.TrackingLost" in names


def test_wiring_shares_buffers(session: Session) -> None:
    task = build(session, MOVE_TASK)
    mods = {m.name: m for m in task.modules}
    assert mods["ct"].inputs["q_des"].value is mods["traj"].outputs["q_des"].value
    assert mods["ct"].inputs["q"].value is session.resource.state.q_rad
    assert task.command is mods["ct"].outputs["tau"].value


BAD_WIRING = [
    (
        ('"traj.dq_des -> ct.dq_des",', '"traj.q_des -> ct.dq_des",'),
        WiringError,
        "unit mismatch: traj.q_des is in rad, ct.dq_des expects rad/s",
    ),
    (
        ('"traj.ddq_des -> ct.ddq_des",', ""),
        WiringError,
        "ct.ddq_des (input of computed_torque 'ct') is not connected (outputs that fit: traj.ddq_des)",
    ),
    (
        ('"arm.q -> ct.q",', '"arm.q -> ct.q",\n  "traj.q_des -> ct.q",'),
        WiringError,
        "ct.q already has a writer: arm.q (wires[2]); an input takes exactly one",
    ),
    (
        ("ki = 4000.0", "ki = 4000.0\ngain = 3"),
        ConfigError,
        "modules.ct.gain is not a parameter of computed_torque (parameters:",
    ),
    (
        ('"traj.q_des -> ct.q_des",', '"traj.q_des -> ct.q_des",\n  "reached.fired -> ct.kp",'),
        WiringError,
        "ct has no input 'kp' (inputs: q, dq, q_des, dq_des, ddq_des)",
    ),
    (
        ('"arm.q -> traj.q",', '"arm.q -> traj.q",\n  "traj.finished -> lost.q",'),
        WiringError,
        "shape mismatch: traj.finished [bool, bool] cannot feed lost.q [(6,), rad]",
    ),
    (
        ('"ct.tau -> arm.tau_cmd",', ""),
        WiringError,
        "arm.tau_cmd (the command input of the resource) is not connected (outputs that fit: ct.tau)",
    ),
    (
        ('"arm.q -> reached.q",', '"arm.q -> reached.q",\n  "ct.q -> traj.q",'),
        WiringError,
        "ct has no output 'q' (outputs: tau); ct.q is an input",
    ),
    (
        ('"arm.q -> traj.q",', '"arm.q -> traj.q",\n  "traj.q_des ->ct.q_des extra",'),
        ConfigError,
        "must read 'MODULE.OUTPUT -> MODULE.INPUT'",
    ),
    (
        ('type = "computed_torque"', 'type = "computed_torq"'),
        ConfigError,
        "modules.ct.type (='computed_torq') is not a module type (known:",
    ),
    (
        ("kp = 900.0", "kp = -1.0"),
        ConfigError,
        "modules.ct.kp (=-1.0) must be in [0, 100000] 1/s^2",
    ),
    (
        ('post = "reached.fired"', 'post = "traj.q_goal"'),
        WiringError,
        "traj.q_goal [(6,), rad] is not an event",
    ),
    (('command = "torque"', 'command = "position"'), WiringError, "arm.tau_cmd"),
    (
        ('set = { "traj.speed_scale" = 0.4 }', 'set = { "traj.speed_scale" = 4.0 }'),
        ConfigError,
        "events.T1[0].set.traj.speed_scale (=4.0) must be in [0.01, 1]",
    ),
    (
        ('signal = "arm.dq"', 'signal = "traj.q_des"'),
        ConfigError,
        "preconditions[0].signal (='traj.q_des') must be a measured signal "
        "(arm.q, arm.dq, arm.tau, arm.wrench)",
    ),
    (  # the file's `resource` is the resource's name in its wires (the mission binds the task)
        ('resource = "arm"', 'resource = "vehicle"'),
        WiringError,
        "wires[0] (='arm.q'): no module 'arm' (modules: vehicle, traj",
    ),
]


@pytest.mark.parametrize(
    ("edit", "error", "message"),
    BAD_WIRING,
    ids=[f"{i}-{m[:30]}" for i, (_, _, m) in enumerate(BAD_WIRING)],
)
def test_bad_wiring_refused(session, task_variant, edit, error, message) -> None:  # type: ignore[no-untyped-def]
    path = task_variant(edit)
    with pytest.raises(error) as exc:
        build(session, path)
    assert message in str(exc.value), str(exc.value)
    assert str(path) in str(exc.value)


def write_task(path, wires: list[str], modules: dict[str, str]):  # type: ignore[no-untyped-def]
    """A minimal torque task file with these wires and modules (name -> type)."""
    body = "".join(f'[modules.{n}]\ntype = "{t}"\n' for n, t in modules.items())
    path.write_text(
        f'wires = {wires!r}\n[task]\nname = "T"\nresource = "arm"\ncommand = "torque"\n{body}'.replace(
            "'", '"'
        )
    )
    return path


def test_ports_named_in_wires_must_exist(session, tmp_path) -> None:  # type: ignore[no-untyped-def]
    p = write_task(
        tmp_path / "t.toml",
        [
            "arm.q -> a.q",
            "arm.dq -> a.dq",
            "b.q_des -> a.q_des",
            "a.dq_des -> a.dq_des",
            "a.ddq_des -> a.ddq_des",
            "a.tau -> arm.tau_cmd",
        ],
        {"a": "computed_torque", "b": "hold_position"},
    )
    with pytest.raises(WiringError, match=r"no output 'dq_des'"):
        build(session, p)
    write_task(
        p,
        [
            "arm.q -> w1.q",
            "w2.q_des -> w1.q_des",
            "arm.q -> w2.q",
            "arm.dq -> w2.dq",
            "w1.fired -> w2.finished_in",
            "arm.tau -> arm.tau_cmd",
        ],
        {"w1": "tracking_error_watch", "w2": "ruckig_trajectory"},
    )
    with pytest.raises(WiringError, match="no input 'finished_in'"):
        build(session, p)


def test_cycle_between_modules_is_printed_in_flow_order(session, tmp_path) -> None:  # type: ignore[no-untyped-def]
    from orccadd.modules import Module, ModuleContext, register

    @register("test_delay_free_gain")
    class Gain(Module):
        def __init__(self, name: str, ctx: ModuleContext) -> None:
            super().__init__(name, ctx)
            self.u = self.add_input("u", (ctx.dof,), "N.m")
            self.y = self.add_output("y", (ctx.dof,), "N.m")

        def update(self, t_s: float) -> None:
            np.multiply(self.u.value, 0.5, out=self.y.value)

    p = write_task(
        tmp_path / "cycle.toml",
        ["g1.y -> g2.u", "g2.y -> g3.u", "g3.y -> g1.u", "g3.y -> arm.tau_cmd"],
        {"g1": "test_delay_free_gain", "g2": "test_delay_free_gain", "g3": "test_delay_free_gain"},
    )
    with pytest.raises(WiringError) as exc:
        build(session, p)
    msg = str(exc.value)
    assert "algebraic loop g1 -> g2 -> g3 -> g1" in msg, msg
    assert "g1.y -> g2.u, g2.y -> g3.u, g3.y -> g1.u" in msg, msg


def test_misplaced_wires_key_gets_a_hint(session, tmp_path) -> None:  # type: ignore[no-untyped-def]
    p = tmp_path / "misplaced.toml"
    p.write_text(
        '[task]\nname = "T"\nresource = "arm"\ncommand = "torque"\n'
        '[modules.h]\ntype = "gravity_compensation"\nwires = ["arm.q -> h.q"]\n'
    )
    with pytest.raises(ConfigError, match="modules.h.wires belongs at the top level"):
        build(session, p)


def test_a_resources_own_signals_are_outputs_of_its_node_and_others_refuse_them(session: Session) -> None:
    """A UR measures the tool's wrench (`arm.wrench`, shared with the resource: no copy), and so
    does the simulated arm; a task that wires it is refused on a resource without it (CANopen
    drives), naming the outputs it has."""
    from orccadd.robot import create_resource, load_robot_config
    from tests.conftest import ROOT

    guarded = ROOT / "configs/tasks/approach_until_contact.toml"
    ur = create_resource(load_robot_config(ROOT / "configs/robots/ur5e-rtde-sim.toml"))  # not connected
    task = build_task(load_task_file(guarded), ur)
    contact = next(m for m in task.modules if m.name == "contact")
    assert contact.inputs["wrench"].value is ur.signals["wrench"]
    signals = ur.description.as_dict()["signals"]
    assert isinstance(signals, list) and [s.split(" ")[0] for s in signals] == ["wrench", "speed_scaling"]
    on_sim = build(session, guarded)  # the same wire on the simulated arm: its F/T sensor
    sim_contact = next(m for m in on_sim.modules if m.name == "contact")
    assert sim_contact.inputs["wrench"].value is session.resource.signals["wrench"]
    drives = create_resource(load_robot_config(ROOT / "configs/robots/canopen-6axis.toml"))  # not opened
    with pytest.raises(WiringError, match=r"arm has no output 'wrench' \(outputs: q, dq, tau\)"):
        build_task(load_task_file(guarded), drives)
    scaled = build_task(load_task_file(ROOT / "configs/tasks/ur_move_joints.toml"), ur)
    traj = next(m for m in scaled.modules if m.name == "traj")
    assert traj.inputs["speed_scaling"].value is ur.signals["speed_scaling"]
