"""`[resource.settings]` of the `ethercat402` backend: the network interface, the drives in chain
order, the process data layout and its timing.

    [resource.settings]
    interface = "eth1"             # the NIC the chain hangs on (root or CAP_NET_RAW: docs/install.md)
    mode = "csp"                   # csp | csv | cst, every drive
    distributed_clocks = true      # SYNC0 at the control period on every drive that has DC
    lost_frames = 3                # lost frames / short working counters in a row -> type 3
    [[resource.settings.slaves]]   # one per joint, in joint order = their order on the chain
    vendor_id = 0x00000000         # the identity the slave's SII must give (checked at startup)
    product_code = 0x00000402
    revision = 0x00000001          # 0: any revision
    eds = "../eds/orccadd-cia402-ecat.eds"   # its CoE dictionary (next to this file, $ORCCADD_EDS_PATH)
    counts_per_rev = 131072
    gear_ratio = 101.0
    rated_torque_nm = 0.74         # the motor's rated torque (0x6076): torques are per mille of it

The process data are mapped by the backend at startup, over CoE SDO, in the PDOs `rx_pdo` and
`tx_pdo` (default 0x1600 and 0x1A00, assigned to SM2 and SM3): controlword, the targets of the
modes the drive has (0x607A, 0x60FF, 0x6071) and the mode of operation; statusword, position,
velocity and torque actual values, mode display and error code. Every check of the description
happens here (slaves per joint, descriptions found, the mode and the mapped objects in each);
the interface is checked when the resource starts (one that does not exist or is down is
refused, naming it). `[resource.settings.simulator]` is read by `python -m orccadd.ecatsim`
only: the network namespace it makes and the name of its end of the link.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Literal

from orccadd.config.robot import RobotConfig
from orccadd.config.schema import field, load_dataclass
from orccadd.drivers.canopen.capabilities import object_dictionary, read_capabilities
from orccadd.drivers.canopen.settings import find_eds
from orccadd.errors import ConfigError

# objects the backend maps: the mode's target must be there; the others are mapped if the drive has them
RX_OBJECTS = ((0x6040, 0, 16), (0x607A, 0, 32), (0x60FF, 0, 32), (0x6071, 0, 16), (0x6060, 0, 8))
TX_OBJECTS = (
    (0x6041, 0, 16),
    (0x6064, 0, 32),
    (0x606C, 0, 32),
    (0x6077, 0, 16),
    (0x6061, 0, 8),
    (0x603F, 0, 16),
)
TARGET_OF_MODE = {"csp": 0x607A, "csv": 0x60FF, "cst": 0x6071}
_IFNAME = re.compile(r"^[A-Za-z0-9_.:-]{1,15}$")


@dataclass(frozen=True)
class SlaveConfig:
    vendor_id: int = field(bounds=(0, 0xFFFFFFFF))
    product_code: int = field(bounds=(0, 0xFFFFFFFF))
    eds: str = field()
    revision: int = field(default=0, bounds=(0, 0xFFFFFFFF))  # 0: any
    counts_per_rev: int = field(default=4096, bounds=(1, 2**31 - 1))
    gear_ratio: float = field(default=100.0, bounds=(0.0, 1e6), open_lo=True)
    rated_torque_nm: float = field(default=1.0, bounds=(0.0, 1e4), open_lo=True)
    rx_pdo: int = field(default=0x1600, bounds=(0x1600, 0x17FF))
    tx_pdo: int = field(default=0x1A00, bounds=(0x1A00, 0x1BFF))


@dataclass(frozen=True)
class SimulatorConfig:
    """Where `python -m orccadd.ecatsim` puts the slaves: a namespace and its end of a veth pair."""

    netns: str = field(default="orccadd-ecat")
    peer: str = field(default="ecs0")


@dataclass(frozen=True)
class EthercatSettings:
    slaves: tuple[SlaveConfig, ...] = field(min_len=1)
    interface: str = field(default="eth1")
    mode: Literal["csp", "csv", "cst"] = field(default="csp")
    distributed_clocks: bool = field(default=True)
    # SYNC0 this long after the cycle's start on the reference clock, where the tick is released
    # (0: three quarters of the period): the drives take the outputs at SYNC0, so the tick's frame
    # must have passed them by then, and latch the inputs the next tick's frame reads
    sync0_shift_us: int = field(default=0, bounds=(0, 100_000))
    lost_frames: int = field(default=3, bounds=(1, 1000))
    # how long a tick waits for its frame to come back (0: a third of the period)
    receive_timeout_us: int = field(default=0, bounds=(0, 100_000))
    state_timeout_s: float = field(default=5.0, bounds=(0.1, 120.0))
    sdo_timeout_s: float = field(default=0.5, bounds=(0.01, 10.0))
    # the keeper (the cyclic exchange until the loop's first tick) and the mailbox/AL-state
    # watcher at SCHED_FIFO (0: time-shared): below the control thread (80), above the rest; a
    # time-shared keeper starved on a busy machine would let the slaves' SM watchdog expire
    io_priority: int = field(default=65, bounds=(0, 98))
    following_error_rad: float = field(default=0.1, bounds=(0.0, 10.0), open_lo=True)  # CSP, 0x6065
    following_error_timeout_ms: int = field(default=100, bounds=(0, 65535))  # 0x6066
    simulator: SimulatorConfig = field(default=SimulatorConfig())
    eds_paths: tuple[str, ...] = field(default=())  # resolved (absolute) by the loader


def load_ethercat_settings(raw: Any, cfg: RobotConfig, file: str) -> EthercatSettings:
    s = load_dataclass(EthercatSettings, raw, file, "resource.settings")
    key = "resource.settings"
    if not _IFNAME.match(s.interface):
        raise ConfigError(file, f"{key}.interface", f"(={s.interface!r}) is not a network interface name")
    if len(s.slaves) != cfg.dof:
        raise ConfigError(
            file, f"{key}.slaves", f"has {len(s.slaves)} entries, must have one per joint ({cfg.dof})"
        )
    paths = []
    for i, sl in enumerate(s.slaves):
        where = f"{key}.slaves[{i}]"
        path = find_eds(sl.eds, Path(file).parent)
        if path is None:
            raise ConfigError(
                file, f"{where}.eds", f"(={sl.eds!r}) not found next to the config nor in $ORCCADD_EDS_PATH"
            )
        try:
            caps = read_capabilities(path, 1)
        except Exception as e:  # whatever the canopen library raises on a broken description
            raise ConfigError(file, f"{where}.eds", f"(={sl.eds!r}) cannot be read: {e}") from None
        try:
            caps.require(s.mode)
        except ValueError as e:
            raise ConfigError(file, f"{where} ({cfg.joints[i].name})", f"mode {s.mode!r}: {e}") from None
        od = object_dictionary(path, 1)
        for index, _sub, _bits in (*RX_OBJECTS[:1], *TX_OBJECTS[:3]):
            if index not in od:
                raise ConfigError(
                    file, f"{where}.eds", f"(={sl.eds!r}) has no object 0x{index:04X}: not a CiA 402 drive"
                )
        for pdo in (sl.rx_pdo, sl.tx_pdo):
            if pdo not in od:
                raise ConfigError(file, f"{where}", f"PDO 0x{pdo:04X} is not in {path.name}")
        paths.append(str(path))
    return replace(s, eds_paths=tuple(paths))
