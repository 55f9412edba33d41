"""`python -m orccadd.dxlsim` as a child process (tests, benchmarks)."""

from __future__ import annotations

from pathlib import Path

from orccadd.simproc import SimulatorProcess


class DxlSimProcess(SimulatorProcess):
    """The servo simulator; `port` is the serial link it serves; `inject(fault, device=ID)`."""

    module = "orccadd.dxlsim"
    what = "servo simulator"

    def __init__(
        self, config: str | Path, *extra: str, env: dict[str, str] | None = None, timeout_s: float = 60.0
    ) -> None:
        super().__init__(config, *extra, env=env, timeout_s=timeout_s)
        self.port = self.fields["port"]
