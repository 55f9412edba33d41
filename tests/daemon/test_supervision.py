"""The reset's device work (`orccadd.daemon.supervision`), with a stand-in resource and loop:
whatever ends its thread is the reset's answer (an OSError from a device, a bug: a refusal in
words naming the resource, never a success), and a thread that hangs is named with its step and
line, in the reply that expires and in every later refusal. No daemon, no device: conditions are
polled with generous bounds, nothing is timed."""

from __future__ import annotations

import errno
import threading
import time
from collections.abc import Callable, Iterator
from types import SimpleNamespace
from typing import Any, cast

import pytest

from orccadd.config.robot import RobotConfig
from orccadd.daemon.loop import SwitchingLoop
from orccadd.daemon.procedure import MissionControl
from orccadd.daemon.replies import CommandError, Pending, Result
from orccadd.daemon.supervision import Supervisor
from orccadd.errors import ResourceError
from orccadd.fault import FaultKind
from orccadd.physres.base import PhysicalResource
from orccadd.types import Status

BOUND_S = 20.0


class StandIn:
    """A resource safe-stopped at rest whose `reset_fault` is the test's."""

    name = "arm"
    fault_message = ""
    description = SimpleNamespace(fault_reset=True)

    def __init__(self, reset_fault: Callable[[], None]) -> None:
        self._reset_fault = reset_fault
        self.state = SimpleNamespace(status=int(Status.STOPPED))
        self.cleared = False

    @property
    def stopping_or_stopped(self) -> bool:
        return not self.cleared

    def clear_output_fault(self) -> None:
        pass

    def reset_fault(self) -> None:
        self._reset_fault()

    def clear_stop(self) -> None:
        self.cleared = True


class Loop:
    hold = object()

    def request_safe_stop(self) -> None:
        pass

    def request_switch(self, task: object, fresh: bool) -> int:
        return 1

    def switched(self, request: int) -> bool:
        return True


def supervisor(res: StandIn) -> Supervisor:
    cfg = SimpleNamespace(control_period_s=0.005)
    mission = SimpleNamespace(running=False)
    sup = Supervisor(
        cast(RobotConfig, cfg),
        cast(PhysicalResource, res),
        cast(SwitchingLoop, Loop()),
        cast(MissionControl, mission),
        lambda *a, **k: None,
    )
    sup.stop("the port is gone", FaultKind.COMM_LOST)  # a fault to reset
    return sup


def answer(pending: Result | Pending) -> Result:
    """Poll the reply as the automaton thread does, until it answers (or raises)."""
    assert isinstance(pending, Pending)
    end = time.monotonic() + BOUND_S
    while True:
        got = pending.poll()
        if got is not None:
            return got
        assert time.monotonic() < end, "the reset never answered"
        time.sleep(0.005)


def test_a_reset_answers_success_once_the_stop_is_cleared() -> None:
    res = StandIn(lambda: None)
    sup = supervisor(res)
    assert answer(sup.begin_reset(lambda: None)) == {"reset": True}
    assert res.cleared and sup.fault is None


@pytest.mark.parametrize(
    "error",
    [
        OSError(errno.EIO, "Input/output error"),  # a serial port's, from a driver below the backend
        ValueError("a bug"),
    ],
    ids=["oserror", "bug"],
)
def test_a_reset_whose_device_work_raises_anything_is_refused_naming_the_resource(error: Exception) -> None:
    """It was: only OrccaddError was caught, any other exception ended the thread silently and
    the reset answered success without `clear_stop` having run."""

    def fails() -> None:
        raise error

    res = StandIn(fails)
    sup = supervisor(res)
    with pytest.raises(CommandError) as e:
        answer(sup.begin_reset(lambda: None))
    msg = str(e.value)
    assert msg.startswith("the reset of arm failed in the device's fault reset (reset_fault): "), msg
    assert f"{type(error).__name__}: {error}" in msg, msg
    assert not res.cleared and sup.fault is not None  # still safe-stopped, still to reset


def test_a_resource_error_is_the_refusal_in_its_own_words() -> None:
    def refuses() -> None:
        raise ResourceError("arm: the port /dev/ttyUSB0 is still gone (...): plug its adapter back in")

    sup = supervisor(StandIn(refuses))
    with pytest.raises(CommandError, match=r"^arm: the port /dev/ttyUSB0 is still gone"):
        answer(sup.begin_reset(lambda: None))


@pytest.fixture
def hanging() -> Iterator[threading.Event]:
    release = threading.Event()
    yield release
    release.set()  # the thread ends with the test


def test_a_reset_that_hangs_is_named_with_its_step_and_line_then_refused_until_it_ends(
    hanging: threading.Event,
) -> None:
    """It was: the reply expired saying only that it did not end, and every later `reset`
    answered "a reset is already under way", for ever, without saying what hangs."""

    def waits_on_the_device() -> None:
        hanging.wait(BOUND_S * 3)

    res = StandIn(waits_on_the_device)
    sup = supervisor(res)
    pending = sup.begin_reset(lambda: None)
    assert isinstance(pending, Pending)
    assert pending.poll() is None
    with pytest.raises(CommandError) as e:
        pending.expire()
    msg = str(e.value)
    assert msg.startswith("the reset of arm did not end within 32 s (still running for "), msg
    assert "in the device's fault reset (reset_fault), at daemon/test_supervision.py:" in msg, msg
    assert "(waits_on_the_device)" in msg and "refused until it ends" in msg, msg
    with pytest.raises(CommandError) as again:
        sup.begin_reset(lambda: None)
    assert str(again.value).startswith("a reset of arm is already under way (for "), again.value
    assert "(waits_on_the_device)" in str(again.value)
    hanging.set()  # the device answers at last: the next reset begins
    end = time.monotonic() + BOUND_S
    while sup._resetting is not None and sup._resetting.running():
        assert time.monotonic() < end, "the reset thread did not end"
        time.sleep(0.005)
    res._reset_fault = lambda: None
    result: Any = answer(sup.begin_reset(lambda: None))
    assert result == {"reset": True} and res.cleared


def test_a_reset_while_the_safe_procedure_runs_says_what_ends_it() -> None:
    """After a protective stop the mission's safe procedure awaits the operator: the refusal
    names the input it may wait for, and `stop`/`abort`, instead of only refusing."""
    sup = supervisor(StandIn(lambda: None))
    loaded = SimpleNamespace(describe=lambda: {"operator_inputs": ["Stop", "Go"]})
    sup.mission = cast(MissionControl, SimpleNamespace(running=True, mission=loaded))
    with pytest.raises(CommandError) as e:
        sup.begin_reset(lambda: None)
    words = str(e.value)
    assert "safe procedure, after the stop of arm" in words
    assert "`orccadctl send Stop` or `orccadctl send Go`" in words
    assert "`orccadctl stop` (or `abort`)" in words
