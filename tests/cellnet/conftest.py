"""Daemons of a cell on this machine: each a real orccadd on the simulated arm, a Zenoh peer on a
loopback TLS endpoint with a certificate of a test authority made per session."""

from __future__ import annotations

import socket
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest

from orccadd.cellnet.certs import make_cell_certs
from tests.daemon.conftest import Daemon, robot_config, start_daemon_with

pytest.importorskip("zenoh")

PEERS = ("arm-a", "arm-b", "arm-c", "console", "viewer", "stranger")


def connected(session: Any, timeout_s: float = 30.0) -> Any:
    """`session` once it has a peer (a put before goes nowhere: a test of what a peer's message
    does would pass without it), bounded; the session."""
    deadline = time.monotonic() + timeout_s
    while not list(session.info.peers_zid()):
        assert time.monotonic() < deadline, f"the session found no peer within {timeout_s} s"
        time.sleep(0.02)
    return session


def until_matched(session: Any, key: str, timeout_s: float = 30.0) -> None:
    """Return once `session` knows a subscriber on `key`: Zenoh sends a put only to the
    subscribers it knows of, and a peer's declarations come after the connection."""
    publisher = session.declare_publisher(key)
    try:
        deadline = time.monotonic() + timeout_s
        while not publisher.matching_status.matching:
            assert time.monotonic() < deadline, f"no subscriber on {key} within {timeout_s} s"
            time.sleep(0.02)
    finally:
        publisher.undeclare()


@pytest.fixture(scope="session")
def certs(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return make_cell_certs(tmp_path_factory.mktemp("certs"), PEERS)


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def cell_table(
    name: str,
    robot: str,
    certs: Path | None,
    listen: list[str],
    connect: list[str],
    control: tuple[str, ...] = (),
    read: tuple[str, ...] = (),
    extra: str = "",
    daemons: tuple[str, ...] = (),
) -> str:
    lines = [
        "[cell]",
        f'name = "{name}"',
        f'robot = "{robot}"',
        f"listen = {listen!r}".replace("'", '"'),
        f"connect = {connect!r}".replace("'", '"'),
    ]
    if certs is not None:
        lines += [
            f'ca = "{certs / "ca.pem"}"',
            f'certificate = "{certs / (robot + ".pem")}"',
            f'private_key = "{certs / (robot + ".key")}"',
            f"control = {list(control)!r}".replace("'", '"'),
            f"read = {list(read)!r}".replace("'", '"'),
        ]
        if daemons:
            lines.append(f"daemons = {list(daemons)!r}".replace("'", '"'))
    return "\n".join(lines) + "\n" + extra


@dataclass
class Member:
    name: str
    endpoint: str
    daemon: Daemon
    dir: Path


def start_member(
    tmp: Path, cell: str, name: str, certs: Path | None, connect: list[str], **table: object
) -> Member:
    d = tmp / name
    d.mkdir()
    proto = "tls" if certs is not None else "tcp"
    endpoint = f"{proto}/127.0.0.1:{free_port()}"
    config = robot_config(d)
    text = config.read_text() + "\n" + cell_table(cell, name, certs, [endpoint], connect, **table)  # type: ignore[arg-type]
    config.write_text(text)
    return Member(name, endpoint, start_daemon_with(d, config), d)


DAEMONS = ("arm-a", "arm-b", "arm-c")


def console_file(
    tmp: Path, cell: str, who: str, certs: Path | None, connect: list[str], daemons: tuple[str, ...] = DAEMONS
) -> Path:
    """A console's `[cell]` file: with TLS, it takes answers from `daemons` only."""
    path = tmp / f"{who}.toml"
    path.write_text(cell_table(cell, who, certs, [], connect, daemons=daemons if certs else ()))
    return path


@pytest.fixture
def cell_of_three(tmp_path: Path, certs: Path) -> Iterator[list[Member]]:
    """arm-a, arm-b, arm-c: each controlled by `console` and by the others, read by `viewer`."""
    members: list[Member] = []
    try:
        for name in ("arm-a", "arm-b", "arm-c"):
            others = [m.endpoint for m in members]
            control = ("console", *(n for n in ("arm-a", "arm-b", "arm-c") if n != name))
            members.append(
                start_member(tmp_path, "test", name, certs, others, control=control, read=("viewer",))
            )
        yield members
    finally:
        for m in members:
            m.daemon.stop()
