"""`python -m orccadd.ecatsim` as a child process (tests, benchmarks, demos)."""

from __future__ import annotations

import os
from pathlib import Path

from orccadd.simproc import SimulatorProcess


class EcatSimProcess(SimulatorProcess):
    """The EtherCAT slave simulator; `inject(fault, device=POSITION, frames=N)`. Its network
    namespace is named after this process (`orccadd-ecat-PID`) unless `--netns` is given: two
    test workers, each in a network namespace of its own, never make the same one."""

    module = "orccadd.ecatsim"
    what = "EtherCAT slave simulator"

    def __init__(self, config: str | Path, *extra: str, timeout_s: float = 60.0) -> None:
        args = list(extra)
        if "--netns" not in args:
            args += ["--netns", f"orccadd-ecat-{os.getpid()}"]
        super().__init__(config, *args, timeout_s=timeout_s)
