"""The socket's directory: made if absent, never changed if present, refused when unsafe."""

from __future__ import annotations

import os
import socket
import stat
from pathlib import Path

import pytest

from orccadd.wire.socketdir import SocketPathError, check_socket_path, prepare_socket_dir


def mode(p: Path) -> int:
    return stat.S_IMODE(os.lstat(p).st_mode)


def test_an_absent_directory_is_made_0750(tmp_path: Path) -> None:
    d = tmp_path / "run"
    prepare_socket_dir(d)
    assert mode(d) == 0o750


def test_an_existing_directory_is_checked_and_left_as_it_is(tmp_path: Path) -> None:
    d = tmp_path / "shared"
    d.mkdir(mode=0o1777)
    os.chmod(d, 0o1777)  # like /tmp: sticky, world-writable
    prepare_socket_dir(d)
    assert mode(d) == 0o1777  # not chmodded: the daemon did not create it


@pytest.mark.parametrize(
    ("make", "why"),
    [
        (lambda d, t: os.symlink(t, d), "is a symbolic link"),
        (lambda d, t: d.write_text("x"), "is not a directory"),
        (lambda d, t: (d.mkdir(), os.chown(d, 65534, 65534)), "is owned by uid 65534"),
        (lambda d, t: (d.mkdir(), os.chmod(d, 0o777)), "anyone may write into it"),
    ],
)
def test_an_unsafe_directory_is_refused_and_not_touched(tmp_path: Path, make, why: str) -> None:  # type: ignore[no-untyped-def]
    target = tmp_path / "elsewhere"
    target.mkdir(mode=0o755)
    d = tmp_path / "run"
    make(d, target)
    before = os.lstat(d)
    with pytest.raises(SocketPathError, match=why):
        prepare_socket_dir(d)
    after = os.lstat(d)
    assert (after.st_mode, after.st_uid, after.st_gid) == (before.st_mode, before.st_uid, before.st_gid)
    assert mode(target) == 0o755


def test_a_missing_group_is_named(tmp_path: Path) -> None:
    with pytest.raises(SocketPathError, match="socket_group .* names no group"):
        prepare_socket_dir(tmp_path / "run", "no-such-group-here")


def test_a_squatted_or_served_socket_path_is_refused(tmp_path: Path) -> None:
    squatted = tmp_path / "file.sock"
    squatted.write_text("")
    with pytest.raises(SocketPathError, match="is not a socket"):
        check_socket_path(squatted)
    served = tmp_path / "live.sock"
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as s:
        s.bind(str(served))
        s.listen(1)
        with pytest.raises(SocketPathError, match="another process is serving"):
            check_socket_path(served)
    check_socket_path(served)  # left over by a dead daemon: usable
    check_socket_path(tmp_path / "absent.sock")
