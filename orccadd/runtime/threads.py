"""Threads with an owner: `ThreadGroup` starts them, tells them to stop, joins them and names
any that outlived their join. No thread is left to die with the interpreter unseen.

The threads are still daemon threads underneath: a thread stuck in a C call (a socket without
a timeout, a bus driver) must not keep a process from ending once its owner has given up on it;
but the owner has waited for it, and said so in the log.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from typing import Any

log = logging.getLogger("orccadd.threads")


class ThreadGroup:
    """The threads one object runs. `stopping` is set by `join` before it waits: a thread's loop
    watches it (or the owner closes what the thread blocks on first)."""

    def __init__(self, owner: str) -> None:
        self.owner = owner
        self.stopping = threading.Event()
        self._threads: list[threading.Thread] = []
        self._lock = threading.Lock()

    def start(self, target: Callable[..., Any], *args: Any, name: str) -> threading.Thread:
        t = threading.Thread(target=target, args=args, name=f"{self.owner}:{name}", daemon=True)
        with self._lock:
            self._threads = [x for x in self._threads if x.is_alive()]  # the ended ones forgotten
            self._threads.append(t)
        t.start()
        return t

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
