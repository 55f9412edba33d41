"""The configs orccadd ships, and `--config NAME`: a path, or the name of a shipped robot config.

A source checkout has them in `configs/` (robots, tasks, missions, urdf); an installed wheel puts
the same tree in `<prefix>/share/orccadd/configs/` (the relative paths inside the files, such as
`urdf = "../urdf/ur5e.urdf"`, hold in both). `ORCCADD_CONFIG_PATH` (folders separated by `:`)
comes first, then `./configs`, the checkout's, the installed tree.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

from orccadd.errors import ConfigError

CHECKOUT = Path(__file__).resolve().parents[2] / "configs"
# the robot the systemd service runs (packaging/systemd/orccadd.service): this PC's robot
SERVICE_CONFIG = Path("/etc/orccadd/robots/robot.toml")
INSTALLED = Path(sys.prefix) / "share" / "orccadd" / "configs"


def config_dirs() -> list[Path]:
    """The config trees, first found first (only those that exist)."""
    env = [Path(p) for p in os.environ.get("ORCCADD_CONFIG_PATH", "").split(":") if p]
    out: list[Path] = []
    for d in (*env, Path.cwd() / "configs", CHECKOUT, INSTALLED):
        if d.is_dir() and d.resolve() not in [o.resolve() for o in out]:
            out.append(d)
    return out


def shipped(kind: str) -> dict[str, Path]:
    """`kind` ("robots", "missions", "tasks") by name (file name without its suffix)."""
    found: dict[str, Path] = {}
    for d in config_dirs():
        for p in sorted((d / kind).glob("*")):
            if p.suffix in (".toml", ".mission") and p.stem not in found:
                found[p.stem] = p
    return found


def robot_config_path(name_or_path: str) -> Path:
    """A robot config given as a path (it exists) or as the name of a shipped one."""
    p = Path(name_or_path)
    if exists(p):
        return p
    robots = shipped("robots")
    key = p.stem if p.suffix == ".toml" and len(p.parts) == 1 else name_or_path
    if key in robots:
        return robots[key]
    raise ConfigError(
        name_or_path,
        "",
        f"no such file, and no shipped robot config of that name (shipped: {', '.join(robots) or 'none'}; "
        "`orccadd --list-configs`)",
    )


def is_bare_name(arg: str) -> bool:
    """A mission or config given by name (`demo`), not by path (`./demo.mission`, `a/b`)."""
    return "/" not in arg and "." not in arg and arg not in ("", "..")


def is_file(p: Path) -> bool:
    """Whether `p` is a regular file; False for a name the system refuses (too long, a NUL)."""
    try:
        return p.is_file()
    except (OSError, ValueError):
        return False


def exists(p: Path) -> bool:
    """Whether `p` exists; False for a name the system refuses (too long, a NUL)."""
    try:
        return p.exists()
    except (OSError, ValueError):
        return False


def mission_path(name_or_path: str) -> Path:
    """A mission given as a path (it exists) or by the name of a shipped one (`demo`)."""
    p = Path(name_or_path)
    if exists(p) or not is_bare_name(name_or_path):
        return p
    missions = shipped("missions")
    if name_or_path in missions:
        return missions[name_or_path]
    raise ConfigError(
        name_or_path,
        "",
        f"no such file, and no shipped mission of that name (shipped: {', '.join(missions) or 'none'}; "
        "`orccadd --list-configs`)",
    )


def list_configs() -> str:
    """The shipped robot configs and missions, one per line, for `orccadd --list-configs`."""
    lines = []
    for kind in ("robots", "missions"):
        items = shipped(kind)
        lines.append(f"{kind}:")
        lines += [f"  {name:24s} {path}" for name, path in items.items()] or ["  (none)"]
    return "\n".join(lines)
