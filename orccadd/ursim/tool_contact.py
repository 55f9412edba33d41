"""`tool_contact(direction)`: is the tool in contact, and since how many cycles.

URScript: "Returns: the number of time steps back to just before the contact have started. A
value larger than 0 means that a contact is detected. A value of 0 means no contact." The
direction's first three elements are a vector in the base frame giving the direction in which
contacts are detected (the way the tool moves towards the obstacle); all zero: any direction.

Here the contact is the measured external force (`actual_TCP_force`, as the controller sees
it) resisting a motion along the direction: F·(−d̂) above `THRESHOLD_N` (or |F| above it for
no direction). The controller records every cycle's force (`record`); while in contact the
answer counts back to the last cycle that was not, so it is 1 in the first cycle of a contact
and grows by one each cycle it lasts.
"""

from __future__ import annotations

import math

import numpy as np

from orccadd.state import FloatArray

THRESHOLD_N = 5.0
HISTORY_CYCLES = 1000


class ContactHistory:
    """The last `HISTORY_CYCLES` force readings (base frame, N), newest last."""

    def __init__(self, cycles: int = HISTORY_CYCLES) -> None:
        self._forces = np.zeros((cycles, 3))
        self._n = 0  # readings recorded (the ring's next slot: _n % cycles)

    def record(self, force_n: FloatArray) -> None:
        self._forces[self._n % len(self._forces)] = force_n[0:3]
        self._n += 1

    def clear(self) -> None:
        self._n = 0

    def steps_in_contact(self, direction: FloatArray) -> int:
        """0 without contact now, else the cycles since the last one without (at most the
        history's length)."""
        size = min(self._n, len(self._forces))
        if size == 0:
            return 0
        d = np.asarray(direction[0:3], dtype=np.float64)
        norm = math.sqrt(float(d @ d))
        order = (np.arange(self._n - 1, self._n - 1 - size, -1)) % len(self._forces)
        forces = self._forces[order]  # newest first
        if norm < 1e-9:
            touching = np.sqrt((forces * forces).sum(axis=1)) > THRESHOLD_N
        else:
            touching = forces @ (-d / norm) > THRESHOLD_N
        if not touching[0]:
            return 0
        free = np.flatnonzero(~touching)
        return int(free[0]) if len(free) else size
