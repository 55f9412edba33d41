"""Threads with an owner: started, told to stop, joined; a straggler is named, not forgotten."""

from __future__ import annotations

import logging
import threading

import pytest

from orccadd.runtime.threads import ThreadGroup, threads_left


def test_join_stops_and_waits_for_every_thread() -> None:
    group = ThreadGroup("sim")
    ended: list[str] = []

    def worker(tag: str) -> None:
        group.stopping.wait()
        ended.append(tag)

    for tag in ("a", "b"):
        group.start(worker, tag, name=tag)
    assert sorted(group.alive()) == ["sim:a", "sim:b"]
    assert group.join(5.0) == []
    assert sorted(ended) == ["a", "b"] and group.alive() == []


def test_a_thread_that_does_not_end_is_named_in_the_log(caplog: pytest.LogCaptureFixture) -> None:
    group = ThreadGroup("server")
    release = threading.Event()
    group.start(release.wait, name="stuck")  # ignores `stopping`
    try:
        with caplog.at_level(logging.ERROR, logger="orccadd.threads"):
            assert group.join(0.1) == ["server:stuck"]
        assert "server: 1 thread(s) still running" in caplog.text and "server:stuck" in caplog.text
    finally:
        release.set()
    assert group.join(5.0) == []


def test_a_thread_may_join_its_own_group_without_waiting_for_itself() -> None:
    group = ThreadGroup("self")
    result: list[list[str]] = []
    t = group.start(lambda: result.append(group.join(1.0)), name="closer")
    t.join(5.0)
    assert result == [[]]


def test_a_threads_exception_reaches_its_owner_and_is_kept(caplog: pytest.LogCaptureFixture) -> None:
    seen: list[tuple[str, str]] = []
    group = ThreadGroup("unit-arm", daemon=False, on_error=lambda name, e: seen.append((name, str(e))))

    def bug() -> None:
        raise OSError(5, "Input/output error")

    with caplog.at_level(logging.ERROR, logger="orccadd.threads"):
        t = group.start(bug, name="control")
        t.join(5.0)
    assert not t.daemon
    assert seen == [("unit-arm:control", "[Errno 5] Input/output error")]
    assert [(name, type(e)) for name, e in group.errors] == [("unit-arm:control", OSError)]
    assert "unit-arm:control failed: OSError" in caplog.text and "Traceback" in caplog.text
    assert group.join(1.0) == []


def test_threads_left_names_the_non_daemon_threads_still_running() -> None:
    release = threading.Event()
    owned = ThreadGroup("owned", daemon=False)
    loose = ThreadGroup("loose")  # daemon threads: they do not keep the process alive
    owned.start(release.wait, name="waits")
    loose.start(release.wait, name="waits")
    try:
        assert "owned:waits" in threads_left() and "loose:waits" not in threads_left()
    finally:
        release.set()
    assert owned.join(5.0) == [] and loose.join(5.0) == []
    assert "owned:waits" not in threads_left()
