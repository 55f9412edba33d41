"""What the simulator reads of a `dynamixel` robot config's `[resource.settings]`.

    [resource.settings]
    port = "/tmp/orccadd-dxl-6axis"   # the serial device (the simulator makes this link)
    baud_rate = 4000000               # bit/s, one of the X series' rates (Baud Rate(8))
    [[resource.settings.servos]]      # one per joint, in joint order
    id = 1
    model = "XM540-W270"
    direction = 1                     # +1: the joint turns with the servo's positive (CCW) sense
    offset_rad = 0.0                  # joint angle at Present Position 2048
    gear_ratio = 1.0                  # horn turns per joint turn
    operating_mode = "position"       # the backend's choice; the simulator does not use it

    q_rad = offset_rad + direction · (position − 2048) · 2π / 4096 / gear_ratio

The backend's own loader is the strict one (it owns the table and may have more keys); the
simulator reads only these keys, with the same checks on them, and leaves the rest alone.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal

from orccadd.config.robot import RobotConfig
from orccadd.config.schema import field, load_dataclass
from orccadd.dxlsim.models import MODELS
from orccadd.dxlsim.table import BAUD_RATES_BIT_S
from orccadd.errors import ConfigError

OPERATING_MODES = {
    "current": 0,
    "velocity": 1,
    "position": 3,
    "extended_position": 4,
    "current_based_position": 5,
    "pwm": 16,
}
KEY = "resource.settings"


@dataclass(frozen=True)
class ServoEntry:
    id: int = field(bounds=(0, 252))
    model: str = field()
    direction: Literal[1, -1] = field(default=1)
    offset_rad: float = field(default=0.0, bounds=(-100.0, 100.0))
    gear_ratio: float = field(default=1.0, bounds=(0.0, 1000.0), open_lo=True)
    operating_mode: str = field(default="position", choices=tuple(OPERATING_MODES))


@dataclass(frozen=True)
class ChainSettings:
    port: str = field()
    servos: tuple[ServoEntry, ...] = field(min_len=1)
    baud_rate: int = field(default=1_000_000)


def _known(cls: type[Any], raw: dict[str, Any]) -> dict[str, Any]:
    return {k: v for k, v in raw.items() if k in cls.__dataclass_fields__}


def read_chain_settings(cfg: RobotConfig) -> ChainSettings:
    """The chain of a robot config (`read_robot_config`'s result), checked against its joints."""
    file = cfg.source
    raw = dict(cfg.resource.settings or {})
    servos = raw.get("servos")
    if isinstance(servos, list):
        raw["servos"] = [_known(ServoEntry, s) if isinstance(s, dict) else s for s in servos]
    s = load_dataclass(ChainSettings, _known(ChainSettings, raw), file, KEY)
    if s.baud_rate not in BAUD_RATES_BIT_S:
        rates = ", ".join(str(b) for b in BAUD_RATES_BIT_S)
        raise ConfigError(file, f"{KEY}.baud_rate", f"(={s.baud_rate!r}) must be one of {rates}")
    if len(s.servos) != cfg.dof:
        raise ConfigError(
            file, f"{KEY}.servos", f"has {len(s.servos)} entries, must have one per joint ({cfg.dof})"
        )
    seen: set[int] = set()
    for i, servo in enumerate(s.servos):
        if servo.model not in MODELS:
            raise ConfigError(
                file, f"{KEY}.servos[{i}].model", f"(={servo.model!r}) must be one of {', '.join(MODELS)}"
            )
        if servo.id in seen:
            raise ConfigError(file, f"{KEY}.servos[{i}].id", f"(={servo.id!r}) is used twice")
        seen.add(servo.id)
    return s
