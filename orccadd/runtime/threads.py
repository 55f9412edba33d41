"""Threads with an owner: `ThreadGroup` starts them, hands their errors to the owner, tells them
to stop, joins them and names any that outlived their join.

A thread's exception is never lost: it is logged with its traceback, kept (`errors`) and passed to
the owner's `on_error(name, exception)` from that thread, before the thread ends.

`daemon=False` (the real-time process's groups): the threads are joined, not abandoned; one
stuck in a C call past its join (a socket without a timeout, a bus driver) is named in the log,
and the process's end does not wait for it (`orccadd.daemon.rtproc.main` exits without joining
what its owners gave up on). The simulators' groups keep `daemon=True` (a blocked `accept`).
"""

from __future__ import annotations

import logging
import sys
import sysconfig
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

log = logging.getLogger("orccadd.threads")
STDLIB = sysconfig.get_paths()["stdlib"]  # `line_of` names the first frame outside it

ErrorHandler = Callable[[str, BaseException], None]


class ThreadGroup:
    """The threads one object runs. `stopping` is set by `join` before it waits: a thread's loop
    watches it (or the owner closes what the thread blocks on first)."""

    def __init__(self, owner: str, *, daemon: bool = True, on_error: ErrorHandler | None = None) -> None:
        self.owner = owner
        self.daemon = daemon
        self.on_error = on_error
        self.stopping = threading.Event()
        self.errors: list[tuple[str, BaseException]] = []  # (thread name, what ended it)
        self._threads: list[threading.Thread] = []
        self._lock = threading.Lock()

    def start(self, target: Callable[..., Any], *args: Any, name: str) -> threading.Thread:
        full = f"{self.owner}:{name}"
        t = threading.Thread(target=self._run, args=(full, target, args), name=full, daemon=self.daemon)
        with self._lock:
            self._threads = [x for x in self._threads if x.is_alive()]  # the ended ones forgotten
            self._threads.append(t)
        t.start()
        return t

    def _run(self, name: str, target: Callable[..., Any], args: tuple[Any, ...]) -> None:
        try:
            target(*args)
        except BaseException as e:
            log.error("%s failed: %s: %s", name, type(e).__name__, e, exc_info=True)
            with self._lock:
                self.errors.append((name, e))
            if self.on_error is not None:
                self.on_error(name, e)

    def alive(self) -> list[str]:
        with self._lock:
            return [t.name for t in self._threads if t.is_alive()]

    def join(self, timeout_s: float) -> list[str]:
        """Set `stopping`, wait up to `timeout_s` in all for every thread (but the caller's own);
        the names of those still running, logged as an error."""
        self.stopping.set()
        end = time.monotonic() + timeout_s
        me = threading.current_thread()
        with self._lock:
            threads = [t for t in self._threads if t is not me]
        for t in threads:
            t.join(max(0.0, end - time.monotonic()))
        left = [t.name for t in threads if t.is_alive()]
        if left:
            log.error("%s: %d thread(s) still running after %g s: %s", self.owner, len(left), timeout_s, left)
        return left


def threads_left() -> list[str]:
    """The process's non-daemon threads still running but the caller's: what would keep the
    interpreter from exiting."""
    me = threading.current_thread()
    return [t.name for t in threading.enumerate() if t is not me and not t.daemon and t.is_alive()]


def line_of(thread: threading.Thread) -> str:
    """Where `thread` is now: the innermost line outside the standard library, as
    `orccadd/x.py:123 (read_cycle)` ("" if it is not running). The words for a thread that hangs."""
    frame = sys._current_frames().get(thread.ident or -1)
    while frame is not None and frame.f_code.co_filename.startswith(STDLIB) and frame.f_back:
        frame = frame.f_back
    if frame is None:
        return ""
    parts = Path(frame.f_code.co_filename).parts
    path = Path(*parts[parts.index("orccadd") :]) if "orccadd" in parts else Path(*parts[-2:])
    return f"{path}:{frame.f_lineno} ({frame.f_code.co_name})"
