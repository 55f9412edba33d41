"""`python -m orccadd.ecatsim` as a child process (tests, benchmarks, demos)."""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

from orccadd.simproc import SimulatorProcess


class EcatSimProcess(SimulatorProcess):
    """The EtherCAT slave simulator; `inject(fault, device=POSITION, frames=N)`. Its network
    namespace is named after this process (`orccadd-ecat-PID`) unless `--netns` is given: two
    test workers, each in a network namespace of its own, never make the same one. `stop` leaves
    no link behind, even after `kill` (a simulator killed cannot remove its own): the namespace
    deleted takes the pair with it."""

    module = "orccadd.ecatsim"
    what = "EtherCAT slave simulator"

    def __init__(self, config: str | Path, *extra: str, timeout_s: float = 60.0) -> None:
        args = list(extra)
        if "--netns" not in args:
            args += ["--netns", f"orccadd-ecat-{os.getpid()}"]
        self.netns = args[args.index("--netns") + 1]
        super().__init__(config, *args, timeout_s=timeout_s)

    def stop(self, timeout_s: float | None = None) -> int:
        code = super().stop(timeout_s)
        if Path("/var/run/netns", self.netns).exists():
            subprocess.run(["ip", "netns", "del", self.netns], capture_output=True, check=False)
        return code
