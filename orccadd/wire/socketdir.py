"""Where the command socket lives: its directory made safely, its path checked before use.

A root daemon must not change a directory it did not create (a socket path pointed at `/tmp`
would make `/tmp` 0750), must not follow a symbolic link there, and must not serve from a
directory another user owns or may write into. The directory is created if absent (mode 0750,
group `daemon.socket_group`); an existing one is checked, never modified.
"""

from __future__ import annotations

import contextlib
import grp
import os
import socket
import stat
from pathlib import Path

from orccadd.errors import OrccaddError

DIR_MODE = 0o750


class SocketPathError(OrccaddError):
    """The socket's directory or path cannot be used safely; the message says why."""


def group_id(group: str) -> int:
    """The id of `group` (-1 for none); `SocketPathError` if there is no such group."""
    if not group:
        return -1
    try:
        return grp.getgrnam(group).gr_gid
    except KeyError:
        raise SocketPathError(f"daemon.socket_group (={group!r}) names no group of this system") from None


def prepare_socket_dir(directory: Path, group: str = "") -> int:
    """Create `directory` (0750, `group`) if absent, or check the existing one; the group id."""
    gid = group_id(group)
    try:
        os.mkdir(directory, DIR_MODE)
    except FileNotFoundError:
        raise SocketPathError(f"{directory}: its parent directory does not exist") from None
    except FileExistsError:
        check_socket_dir(directory)
        return gid
    os.chmod(directory, DIR_MODE)  # ours: made just now (the umask may have narrowed it)
    if gid >= 0:
        os.chown(directory, -1, gid)
    return gid


def check_socket_dir(directory: Path) -> None:
    """Refuse a directory that is a symbolic link, not a directory, not owned by this process's
    user, or writable by others without the sticky bit."""
    st = os.lstat(directory)
    if stat.S_ISLNK(st.st_mode):
        raise SocketPathError(f"{directory}: is a symbolic link; give the socket a real directory")
    if not stat.S_ISDIR(st.st_mode):
        raise SocketPathError(f"{directory}: is not a directory")
    if st.st_uid != os.getuid():
        raise SocketPathError(
            f"{directory}: is owned by uid {st.st_uid}, not by this daemon's user (uid {os.getuid()})"
        )
    if st.st_mode & stat.S_IWOTH and not st.st_mode & stat.S_ISVTX:
        raise SocketPathError(f"{directory}: anyone may write into it (mode {stat.S_IMODE(st.st_mode):o})")


def check_socket_path(path: Path) -> None:
    """Refuse a path taken by something that is not a socket, or by a socket someone serves."""
    try:
        st = os.lstat(path)
    except FileNotFoundError:
        return
    if not stat.S_ISSOCK(st.st_mode):
        raise SocketPathError(f"{path}: exists and is not a socket; remove it or choose another --socket")
    probe = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    try:
        probe.connect(str(path))
    except OSError:
        return  # a socket nobody serves: left over, the command daemon replaces it
    else:
        raise SocketPathError(f"{path}: another process is serving on it (a second orccadd?)")
    finally:
        with contextlib.suppress(OSError):
            probe.close()


def urgent_socket_path(public: str) -> str:
    """Where the real-time process takes `abort` and `stop` itself (`orccadd.daemon.urgent`)."""
    return public + ".urgent"


def bind_with_mode(sock: socket.socket, path: str | Path, umask: int) -> None:
    """Bind `sock` to `path` with the socket file's permissions masked by `umask` from the start
    (0o177: the owner only; 0o117: owner and group), no moment of a wider mode."""
    old = os.umask(umask)
    try:
        sock.bind(str(path))
    finally:
        os.umask(old)
