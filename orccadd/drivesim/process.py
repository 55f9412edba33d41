"""`python -m orccadd.drivesim` as a child process (tests, benchmarks, demos)."""

from __future__ import annotations

from orccadd.simproc import SimulatorProcess


class DriveSimProcess(SimulatorProcess):
    """The drive simulator; `inject(fault, device=NODE_ID, bus=CHANNEL)`."""

    module = "orccadd.drivesim"
    what = "drive simulator"
