"""Who may do what on the daemon's sockets: the peer's credentials (SO_PEERCRED) against the
config's users and groups. `control` ⊃ `read`; root and the daemon's own user always control."""

from __future__ import annotations

import contextlib
import grp
import os
import pwd
import socket
import struct
from collections.abc import Sequence
from typing import Protocol

from orccadd.wire.commands import Role


class RoleConfig(Protocol):
    """The config's say on roles (`orccadd.config.robot.DaemonConfig` has these)."""

    @property
    def control_users(self) -> Sequence[str]: ...
    @property
    def control_groups(self) -> Sequence[str]: ...
    @property
    def read_users(self) -> Sequence[str]: ...
    @property
    def read_groups(self) -> Sequence[str]: ...


def peer_credentials(sock: socket.socket) -> tuple[int, int, int]:
    """(pid, uid, gid) of the process at the other end of a Unix socket."""
    raw = sock.getsockopt(socket.SOL_SOCKET, socket.SO_PEERCRED, struct.calcsize("3i"))
    pid, uid, gid = struct.unpack("3i", raw)
    return pid, uid, gid


class Roles:
    """Who may do what: `control` ⊃ `read`. Root and the daemon's own user always control."""

    def __init__(self, cfg: RoleConfig) -> None:
        self.cfg = cfg

    def _groups(self, uid: int, gid: int) -> set[str]:
        names = set()
        gids = {gid}
        with contextlib.suppress(KeyError):
            user = pwd.getpwuid(uid).pw_name
            gids |= set(os.getgrouplist(user, gid))
        for g in gids:
            with contextlib.suppress(KeyError):
                names.add(grp.getgrgid(g).gr_name)
        return names

    def role(self, uid: int, gid: int) -> Role | None:
        if uid in (0, os.getuid()):
            return Role.CONTROL
        try:
            user = pwd.getpwuid(uid).pw_name
        except KeyError:
            user = str(uid)
        groups = self._groups(uid, gid)
        c = self.cfg
        if user in c.control_users or groups & set(c.control_groups):
            return Role.CONTROL
        if user in c.read_users or groups & set(c.read_groups):
            return Role.READ
        return None
