"""SIGTERM's last step in the real-time process (`RealtimeProcess._release`): every resource's
`shutdown`, bounded in all, so that a device call that never returns (a port or a bus gone) does
not keep the process from ending; one that hangs or fails is named in the log and the exit code
says so. Stand-in resources, no daemon."""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from types import SimpleNamespace
from typing import cast

import pytest

from orccadd.daemon import rtproc
from orccadd.daemon.rtproc import RealtimeProcess


class StandIn:
    def __init__(self, name: str, shutdown: Callable[[], object] = lambda: None) -> None:
        self.name = name
        self._shutdown = shutdown
        self.released = False

    def shutdown(self) -> None:
        self._shutdown()
        self.released = True


def release(*resources: StandIn) -> bool:
    return RealtimeProcess._release(
        cast(RealtimeProcess, SimpleNamespace(resources=list(resources), in_processes=False))
    )


def test_every_resource_is_released() -> None:
    arm, gripper = StandIn("arm"), StandIn("gripper")
    assert release(arm, gripper) and arm.released and gripper.released


def test_a_release_that_hangs_is_named_and_the_others_are_released(
    monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    monkeypatch.setattr(rtproc, "RELEASE_S", 0.5)
    stuck = threading.Event()
    arm = StandIn("arm", lambda: stuck.wait(60.0))  # a close() on a port that never returns
    gripper = StandIn("gripper")
    try:
        with caplog.at_level(logging.ERROR):
            assert not release(arm, gripper)
        assert gripper.released and not arm.released
        assert "release: 1 thread(s) still running after 0.5 s: ['release:arm']" in caplog.text
    finally:
        stuck.set()


def test_a_release_that_fails_is_named(caplog: pytest.LogCaptureFixture) -> None:
    def fails() -> None:
        raise OSError(5, "Input/output error")

    gripper = StandIn("gripper")
    with caplog.at_level(logging.ERROR):
        assert not release(StandIn("arm", fails), gripper)
    assert gripper.released and "arm: releasing its hardware failed" in caplog.text
