"""A resource's output actions are performed on its own thread, in order: queuing one never
waits on the device, and one that fails is a fault of that resource until a reset."""

from __future__ import annotations

import threading
from collections.abc import Iterator

import pytest

from orccadd.daemon.outputs import OutputWorker
from orccadd.errors import ResourceError
from orccadd.physres.base import PhysicalResource
from orccadd.robot import create_resource, load_robot_config, with_backend
from orccadd.runtime.threads import ThreadGroup
from orccadd.types import CommandMode, Status
from tests.daemon.conftest import ROBOT
from tests.ursim.conftest import wait_until


@pytest.fixture
def arm() -> Iterator[PhysicalResource]:
    res = create_resource(with_backend(load_robot_config(ROBOT), "sim"))
    res.configure()
    res.activate(CommandMode.TORQUE)
    try:
        yield res
    finally:
        res.shutdown()


def test_queuing_never_waits_on_the_device_and_actions_keep_their_order(
    arm: PhysicalResource, monkeypatch: pytest.MonkeyPatch
) -> None:
    release, done = threading.Event(), []

    def slow_output(name: str) -> None:  # a device call that takes as long as the device wants
        release.wait(10)
        done.append(name)

    monkeypatch.setattr(arm, "set_output", slow_output)
    threads = ThreadGroup("test")
    worker = OutputWorker(arm, threads)
    for name in ("close_gripper", "open_gripper", "close_gripper"):
        worker.request(name)  # returns while the device holds the first call
    assert done == []  # (were it waiting, the device would have answered first)
    release.set()
    wait_until(lambda: len(done) == 3, what="the actions performed")
    assert done == ["close_gripper", "open_gripper", "close_gripper"]
    assert worker.performed == 3 and worker.failed == 0
    worker.close()
    assert threads.join(5.0) == []


@pytest.mark.parametrize("error", [ResourceError("the controller refused it"), OSError(5, "I/O error")])
def test_a_failed_action_is_a_fault_of_its_resource_until_a_reset(
    arm: PhysicalResource, monkeypatch: pytest.MonkeyPatch, error: Exception
) -> None:
    def failing(name: str) -> None:
        raise error

    assert not arm.read(0.0).status & Status.FAULT
    monkeypatch.setattr(arm, "set_output", failing)
    threads = ThreadGroup("test")
    worker = OutputWorker(arm, threads)
    worker.request("close_gripper")
    wait_until(lambda: worker.failed == 1, what="the failure")
    st = arm.read(0.002)
    assert st.status & Status.FAULT  # the task's ResourceFault at its next tick
    assert arm.fault is not None and arm.fault.kind == "device"
    assert "output close_gripper not performed" in arm.fault_message
    assert str(error.args[-1]) in arm.fault_message
    assert arm.read(0.004).status & Status.FAULT  # latched: the next reads too
    arm.clear_output_fault()  # what a reset does first
    assert not arm.read(0.006).status & Status.FAULT
    worker.close()
    assert threads.join(5.0) == []


def test_an_action_the_resource_does_not_have_is_a_fault_too(arm: PhysicalResource) -> None:
    threads = ThreadGroup("test")
    worker = OutputWorker(arm, threads)
    worker.request("no_such_output")  # the sim arm has no outputs: its set_output refuses
    wait_until(lambda: worker.failed == 1, what="the refusal")
    assert arm.read(0.0).status & Status.FAULT and "has no output 'no_such_output'" in arm.fault_message
    worker.close()
    assert threads.join(5.0) == []
