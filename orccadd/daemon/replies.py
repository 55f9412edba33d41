"""What a command handler of the real-time process returns: a result now, a `Pending` result
(completed by later control ticks, e.g. a reset or a tune), or a `CommandError`."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from orccadd.errors import OrccaddError

Result = dict[str, Any]


class CommandError(OrccaddError):
    """A command that cannot be done now (the message says why); nothing was changed."""


@dataclass
class Pending:
    """A reply that completes later. The automaton thread calls `poll()` on each wake-up (at
    least once a period while one is pending): it returns the result once ready, None meanwhile,
    or raises `CommandError`. After `deadline_ns` (CLOCK_MONOTONIC), `expire()` gives the reply."""

    poll: Callable[[], Result | None]
    deadline_ns: int
    expire: Callable[[], Result]
