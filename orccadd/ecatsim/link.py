"""The simulator's wire: one end of a virtual Ethernet pair, inside a network namespace of its own.

`VethLink` makes the namespace and the pair (`ip netns add`, `ip link add … type veth`), moves
the slaves' end into the namespace and brings both ends up; the master's end stays where the
controller runs, named as its config's `interface`. A raw packet socket on the slaves' end,
bound to EtherCAT's EtherType 0x88A4, receives the master's frames, each with the kernel's time
stamp of its arrival, and sends the answers (frames a socket sends are not looped back to it).
`close` deletes the namespace, and with it the pair.

Leftovers of a simulator that was killed (the namespace, a veth of the master's name) are
removed before the new pair is made; an interface of that name that is not a veth is never
touched: the link is refused, naming it.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import socket
import struct
import subprocess
import threading
import time
from pathlib import Path

ETH_P_ECAT = 0x88A4
SO_TIMESTAMPNS = 35  # the kernel's receive time of each frame (CLOCK_REALTIME, ns)
_TIMESPEC = struct.Struct("@qq")
CLONE_NEWNET = 0x40000000
NETNS_DIR = Path("/var/run/netns")


class LinkError(OSError):
    """The virtual link could not be made, saying what failed."""


def _ip(*args: str, check: bool = True) -> subprocess.CompletedProcess[str]:
    try:
        done = subprocess.run(["ip", *args], capture_output=True, text=True, timeout=10, check=False)
    except FileNotFoundError:
        raise LinkError("`ip` (iproute2) is not installed: apt-get install iproute2") from None
    if check and done.returncode != 0:
        raise LinkError(f"ip {' '.join(args)}: {done.stderr.strip() or f'exit {done.returncode}'}")
    return done


def interface_kind(name: str) -> str | None:
    """'veth', another kind ('' for a plain NIC), or None where no interface has that name."""
    done = _ip("-d", "-o", "link", "show", "dev", name, check=False)
    if done.returncode != 0:
        return None
    words = done.stdout.split()
    return "veth" if "veth" in words else ""


def _in_namespace(netns: str, make: type[socket.socket], *args: int) -> socket.socket:
    """A socket made inside `netns` (from a thread that enters it: the process stays where it is)."""
    libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
    result: list[socket.socket | BaseException] = []

    def enter_and_make() -> None:
        try:
            fd = os.open(NETNS_DIR / netns, os.O_RDONLY)
            try:
                if libc.setns(fd, CLONE_NEWNET) != 0:
                    err = ctypes.get_errno()
                    raise OSError(err, f"setns into {netns}: {os.strerror(err)}")
            finally:
                os.close(fd)
            result.append(make(*args))
        except BaseException as e:
            result.append(e)

    t = threading.Thread(target=enter_and_make, name=f"netns-{netns}")
    t.start()
    t.join()
    got = result[0]
    if isinstance(got, BaseException):
        raise got
    return got


class VethLink:
    def __init__(self, master_interface: str, slave_interface: str, netns: str) -> None:
        self.master_interface = master_interface
        self.slave_interface = slave_interface
        self.netns = netns
        self._remove_leftovers()
        _ip("netns", "add", netns)
        try:
            _ip("link", "add", master_interface, "type", "veth", "peer", "name", slave_interface)
            _ip("link", "set", slave_interface, "netns", netns)
            _ip("link", "set", master_interface, "up")
            _ip("-n", netns, "link", "set", slave_interface, "up")
            self.sock = _in_namespace(
                netns, socket.socket, socket.AF_PACKET, socket.SOCK_RAW, socket.htons(ETH_P_ECAT)
            )
            self.sock.bind((slave_interface, ETH_P_ECAT))
            self.sock.setblocking(False)
            self.sock.setsockopt(socket.SOL_SOCKET, SO_TIMESTAMPNS, 1)
            self._wait_until_up()
        except BaseException:
            self._delete()
            raise

    def _wait_until_up(self, timeout_s: float = 5.0) -> None:
        """Both ends operational: a link just brought up drops what is sent on it until the
        kernel's link watch has attached its queue (up to a second later), and a master that
        scanned then would find no slave."""
        end = time.monotonic() + timeout_s
        while True:
            here = _ip("-o", "link", "show", "dev", self.master_interface).stdout
            there = _ip("-n", self.netns, "-o", "link", "show", "dev", self.slave_interface).stdout
            if "state UP" in here and "state UP" in there:
                return
            if time.monotonic() > end:
                link = f"{self.master_interface} <-> {self.slave_interface}"
                raise LinkError(f"the link {link} not up within {timeout_s:g} s")
            time.sleep(0.02)

    def _remove_leftovers(self) -> None:
        kind = interface_kind(self.master_interface)
        if kind == "":
            raise LinkError(
                f"interface {self.master_interface} exists and is not a veth: the simulator makes its "
                "own link and never touches a real one (name another interface)"
            )
        if (NETNS_DIR / self.netns).exists():
            _ip("netns", "del", self.netns, check=False)
        if kind == "veth":
            _ip("link", "del", self.master_interface, check=False)

    def fileno(self) -> int:
        return self.sock.fileno()

    def receive(self) -> tuple[bytes, int] | None:
        """A frame if one waits, with the time it reached the link (CLOCK_MONOTONIC ns, from
        the kernel's receive time stamp); None if none waits."""
        try:
            data, ancillary, _flags, _addr = self.sock.recvmsg(2048, 64)
        except BlockingIOError:
            return None
        for level, kind, value in ancillary:
            if level == socket.SOL_SOCKET and kind == SO_TIMESTAMPNS and len(value) >= _TIMESPEC.size:
                sec, nsec = _TIMESPEC.unpack_from(value)
                return data, sec * 1_000_000_000 + nsec - (time.time_ns() - time.monotonic_ns())
        return data, time.monotonic_ns()

    def send(self, frame: bytes) -> None:
        self.sock.send(frame)

    def _delete(self) -> None:
        _ip("netns", "del", self.netns, check=False)  # the pair goes with its end inside
        if interface_kind(self.master_interface) == "veth":
            _ip("link", "del", self.master_interface, check=False)

    def close(self) -> None:
        sock = getattr(self, "sock", None)
        if sock is not None:
            sock.close()
        self._delete()
