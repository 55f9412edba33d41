"""The controller generations the simulator can be: their software version and their cycle.

The RTDE `v` answer (major, minor, bugfix, build), the dashboard's `PolyscopeVersion` and
`version`, and the rate of the controller's cycle and RTDE stream (e-Series 500 Hz, CB3 125 Hz).
ur_rtde picks its recipes, its script lines (`$5.4` ...) and its stream rate from the version.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Series:
    """A controller generation: its software version and its cycle."""

    name: str
    version: tuple[int, int, int, int]  # major, minor, bugfix, build (RTDE 'v')
    rate_hz: float
    build_date: str

    @property
    def version_text(self) -> str:
        return ".".join(str(v) for v in self.version)

    @property
    def polyscope(self) -> str:
        """The dashboard's `PolyscopeVersion` answer."""
        return f"URSoftware {self.version_text} ({self.build_date})"


E_SERIES = Series("e-Series", (5, 11, 1, 108318), 500.0, "Nov 22 2021")
CB3 = Series("CB3", (3, 15, 7, 106331), 125.0, "Nov 02 2021")
