"""A shared-memory channel between a controller and a plant process (same machine).

Layout (one `SharedMemory` block): an int64 control area, the state (t, q, dq, tau, the tool's
measured wrench: 6, the camera's features: 8 and target_visible: 1, zeros without a camera) and
the command vector. State and command are each written under a
sequence lock (odd while writing), so a reader never sees a torn vector and neither side ever
waits for the other. Lifecycle requests (activate, clear stop, …) go through a
request/acknowledge counter pair; safe stop is a single store, so it can be asked from a tick.
"""

from __future__ import annotations

from enum import IntEnum
from multiprocessing import resource_tracker, shared_memory

import numpy as np
import numpy.typing as npt


class Ctl:
    """Indices in the int64 control area (plain ints: indexing with an IntEnum costs ~0.2 µs more)."""

    STATE_SEQ = 0
    CMD_SEQ = 1
    REQ_SEQ = 2
    REQ_CODE = 3
    REQ_ARG = 4
    ACK_SEQ = 5
    ACK_RESULT = 6
    HEARTBEAT = 7  # incremented by the plant every step
    STOP = 8  # 1: the controller asks for a safe stop
    STATUS = 9  # the plant's Status flags
    FAULT_CODE = 10
    CMD_MODE = 11
    CONTROL_PORT = 12  # the plant's control channel on 127.0.0.1 (0: none, or not yet open)


CTL_SIZE = 16
WRENCH_SIZE = 6
CAMERA_SIZE = 9  # `sim_camera`: the features (8), then target_visible (1)
SIGNALS_SIZE = WRENCH_SIZE + CAMERA_SIZE  # the state's signals after t, q, dq, tau


class Request(IntEnum):
    """Lifecycle requests to the plant (not for a tick)."""

    ACTIVATE = 1
    SWITCH_MODE = 2
    DEACTIVATE = 3
    CLEAR_STOP = 4
    INJECT_FAULT = 5
    RESET_FAULT = 6
    SHUTDOWN = 7


class PlantChannel:
    """Views on the shared block. `create=True` on the controller side, False on the plant side."""

    def __init__(self, dof: int, name: str | None = None, create: bool = False) -> None:
        self.dof = dof
        self.state_size = 1 + 3 * dof + SIGNALS_SIZE
        n_f64 = self.state_size + dof
        size = CTL_SIZE * 8 + n_f64 * 8
        self.shm = shared_memory.SharedMemory(name=name, create=create, size=size if create else 0)
        if not create:
            # Python < 3.13 registers attached blocks too, and would unlink the creator's block
            # when this process exits: only the creator owns it.
            resource_tracker.unregister(self.shm._name, "shared_memory")  # type: ignore[attr-defined]
        buf = self.shm.buf
        self.ctl: npt.NDArray[np.int64] = np.ndarray((CTL_SIZE,), dtype=np.int64, buffer=buf)
        f64: npt.NDArray[np.float64] = np.ndarray((n_f64,), dtype=np.float64, buffer=buf, offset=CTL_SIZE * 8)
        self.state = f64[: self.state_size]  # t, q, dq, tau, wrench, features, target_visible
        self.cmd = f64[self.state_size :]
        if create:
            self.ctl[:] = 0
            f64[:] = 0.0

    @property
    def name(self) -> str:
        return self.shm.name

    # ---- state: the plant writes, the controller reads ------------------------------------
    def publish_state(
        self,
        t_s: float,
        q: np.ndarray,
        dq: np.ndarray,
        tau: np.ndarray,
        status: int,
        wrench: np.ndarray,
        camera: np.ndarray | None = None,
    ) -> None:
        """`camera`: the features then target_visible (`CAMERA_SIZE`); None: zeros (no camera)."""
        ctl, st, n = self.ctl, self.state, self.dof
        n3 = 1 + 3 * n
        ctl[Ctl.STATE_SEQ] += 1  # odd: writing
        st[0] = t_s
        st[1 : 1 + n] = q
        st[1 + n : 1 + 2 * n] = dq
        st[1 + 2 * n : n3] = tau
        st[n3 : n3 + WRENCH_SIZE] = wrench
        st[n3 + WRENCH_SIZE :] = 0.0 if camera is None else camera
        ctl[Ctl.STATUS] = status
        ctl[Ctl.STATE_SEQ] += 1

    def read_state(self, out: np.ndarray, tries: int = 3) -> int:
        """Copy a consistent state into `out` (len `state_size`: 1 + 3·dof + 6 + 9); returns the
        plant's status, or -1 if no consistent snapshot came in `tries` (never spins: the writer
        may be a lower-priority process preempted on this very CPU)."""
        return self._snapshot(Ctl.STATE_SEQ, self.state, out, Ctl.STATUS, tries)[1]

    def _snapshot(
        self, seq_i: int, src: np.ndarray, out: np.ndarray, word_i: int, tries: int
    ) -> tuple[int, int]:
        """Seqlock read of `src` and control word `word_i`: (sequence, word), or (-1, -1)."""
        ctl = self.ctl
        for _ in range(tries):
            s1 = int(ctl[seq_i])
            if s1 & 1:
                continue
            out[:] = src
            word = int(ctl[word_i])
            if s1 == int(ctl[seq_i]):
                return s1, word
        return -1, -1

    # ---- command: the controller writes, the plant reads ----------------------------------
    def send_command(self, mode: int, cmd: np.ndarray) -> None:
        ctl = self.ctl
        ctl[Ctl.CMD_SEQ] += 1
        ctl[Ctl.CMD_MODE] = mode
        self.cmd[:] = cmd
        ctl[Ctl.CMD_SEQ] += 1

    def take_command(self, out: np.ndarray, tries: int = 3) -> tuple[int, int]:
        """Copy the latest command into `out`; returns (sequence number, mode), or (-1, -1) if
        no consistent snapshot came in `tries`."""
        return self._snapshot(Ctl.CMD_SEQ, self.cmd, out, Ctl.CMD_MODE, tries)

    def close(self, unlink: bool = False) -> None:
        del self.ctl, self.state, self.cmd
        self.shm.close()
        if unlink:
            self.shm.unlink()
