"""A resource's output actions (a mission's `emit R.Y`: a digital output set or cleared),
performed on a thread of the resource's own, in the order the automaton emitted them.

The automaton thread serves every resource and must never wait on a device: a UR's I/O call
goes through its link process and can take seconds. It only queues the action here. An action
the device refuses, or whose call raises, is a fault of that resource
(`PhysicalResource.output_failed`): its next read shows FAULT, its active task raises
ResourceFault, and the mission handles that as it handles any type 3; a reset clears it.
"""

from __future__ import annotations

import logging
import queue

from orccadd.physres.base import PhysicalResource
from orccadd.runtime.threads import ThreadGroup

log = logging.getLogger("orccadd")


class OutputWorker:
    """The output actions of `resource`, one at a time on a thread of `threads`."""

    def __init__(self, resource: PhysicalResource, threads: ThreadGroup) -> None:
        self.resource = resource
        self.performed = 0  # actions the device took
        self.failed = 0
        self._queue: queue.SimpleQueue[str | None] = queue.SimpleQueue()
        threads.start(self._run, name=f"outputs-{resource.name}")

    def request(self, name: str) -> None:
        """Queue the output action `name` (the automaton thread's call: it never waits)."""
        self._queue.put(name)

    def close(self) -> None:
        """The thread ends once what was queued before is done (join its group after)."""
        self._queue.put(None)

    def _run(self) -> None:
        while (name := self._queue.get()) is not None:
            try:
                self.resource.set_output(name)
                self.performed += 1
            except Exception as e:  # refused, the link gone, a bug: the resource's fault, said
                self.failed += 1
                why = f"{type(e).__name__}: {e}" if not str(e) else str(e)
                log.warning("%s: output %s not performed: %s", self.resource.name, name, why)
                self.resource.output_failed(name, why)
