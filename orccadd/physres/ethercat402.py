"""`ethercat402` backend: an arm of CiA 402 drives on an EtherCAT line (CoE), through SOEM.

Under way (issue 45): the description, the claims and the settings; the lifecycle and the ticks
come with `drivers.ethercat.master`.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from orccadd.config.robot import RobotConfig
from orccadd.drivers.ethercat.settings import EthercatSettings, load_ethercat_settings
from orccadd.errors import ResourceError
from orccadd.physres.base import PhysicalResource
from orccadd.physres.description import MEASURED, Quantity, ResourceDescription, Source
from orccadd.types import CommandMode

COMMAND_OF_MODE = {"csp": CommandMode.POSITION, "csv": CommandMode.VELOCITY, "cst": CommandMode.TORQUE}


class Ethercat402Arm(PhysicalResource):
    Settings = EthercatSettings

    @classmethod
    def claims(cls, config: RobotConfig) -> tuple[str, ...]:
        s: EthercatSettings = config.backend_settings
        return (f"EtherCAT line on {s.interface}",)

    @classmethod
    def describe(cls, config: RobotConfig) -> ResourceDescription:
        """The configured mode and torque (CST) beside it: the RxPDO carries every mode's target
        and the mode of operation, so the drives switch while enabled, within one cycle."""
        s: EthercatSettings = config.backend_settings
        first = COMMAND_OF_MODE[s.mode]
        return ResourceDescription(
            backend="ethercat402",
            joints=config.joint_names,
            modes=frozenset({first, CommandMode.TORQUE}),
            mode_switch_needs_disable=False,
            position=MEASURED,
            velocity=MEASURED,  # the drive's velocity actual value (0x606C)
            torque=Quantity(Source.ESTIMATED, "the drive's torque actual value 0x6077, from motor current"),
            brakes=True,
            stop_categories=frozenset({0, 1, 2}),
            read_time_s=0.0,  # the frame sent at the end of the last tick is back: no waiting
            write_time_s=0.0,
            fault_reset=True,
        )

    @classmethod
    def load_settings(cls, raw: Mapping[str, Any], cfg: RobotConfig, file: str) -> EthercatSettings:
        return load_ethercat_settings(raw, cfg, file)

    def _on_configure(self) -> None:
        raise ResourceError(
            f"resource {self.name!r}: the ethercat402 backend's master is not built yet (issue 45)"
        )
