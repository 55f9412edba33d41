"""The controller generations the simulator can be: their software version and their cycle.

The RTDE `v` answer (major, minor, bugfix, build), the dashboard's `PolyscopeVersion` and
`version`, and the rate of the controller's cycle and RTDE stream (e-Series 500 Hz, CB3 125 Hz).
ur_rtde picks its recipes, its script lines (`$5.4` ...) and its stream rate from the version.
"""

from __future__ import annotations

from dataclasses import dataclass, replace


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
    def direct_torque(self) -> bool:
        """ur_rtde 1.6's control script calls `direct_torque` on 5.26 and later only (its `$5.26`
        lines); on an older controller its command 66 does nothing."""
        return self.version[:2] >= DIRECT_TORQUE_SINCE

    def with_software(self, text: str) -> Series:
        """The same generation running another software version ("5.26.0"); ValueError if it
        is not one of this generation's (its major version)."""
        parts = [int(p) for p in text.split(".")]
        if not 2 <= len(parts) <= 4 or parts[0] != self.version[0]:
            raise ValueError(f"{text!r} is not a software version of the {self.name} ({self.version[0]}.x.y)")
        major, minor, bugfix, build = (*parts, 0, 0)[:4]
        return replace(self, version=(major, minor, bugfix, build))

    @property
    def polyscope(self) -> str:
        """The dashboard's `PolyscopeVersion` answer."""
        return f"URSoftware {self.version_text} ({self.build_date})"


DIRECT_TORQUE_SINCE = (5, 26)  # the version ur_rtde 1.6's script needs for direct torque
E_SERIES = Series("e-Series", (5, 26, 0, 0), 500.0, "Jan 01 2026")  # with direct torque (5.26)
CB3 = Series("CB3", (3, 15, 7, 106331), 125.0, "Nov 02 2021")
