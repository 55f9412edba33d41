"""One CAN bus of the master: its python-can bus, its `canopen.Network` (startup only), its
SYNC, and a tick's frames handed to the bus in one write.

A tick queues its frames (RPDOs, then SYNC, then our heartbeat when due) with `queue` and hands
them over with `flush`. On SocketCAN a frame is one `write` system call to the kernel, which
python-can makes at once (`queue` is `send`). Over socketcand, python-can's client makes a TCP
write (and a setsockopt) per frame, each waking the server: `BatchingSocketcandBus` is that
client with its receive path and message text unchanged, whose `queue` keeps the frame's text
and whose `flush` writes a tick's frames to the server in one TCP write (six axes at 500 Hz:
the resource's `write()` median 224 µs with a write per frame, 95-102 µs batched).
"""

from __future__ import annotations

import contextlib
import socket
from typing import Any

import can
import canopen
from can.interfaces.socketcand.socketcand import SocketCanDaemonBus, convert_can_message_to_ascii_message

from orccadd.drivers.canopen.settings import Bus
from orccadd.errors import ResourceError


class BatchingSocketcandBus(SocketCanDaemonBus):  # type: ignore[misc]
    """python-can's socketcand client whose `queue`d frames leave in one TCP write (`flush`).

    `send` stays python-can's own (immediate): its periodic tasks (our startup heartbeat) and the
    `canopen` library's SDO client use it from their threads."""

    def __init__(self, channel: str, host: str, port: int, **kwargs: Any) -> None:
        super().__init__(channel, host, port, **kwargs)  # type: ignore[no-untyped-call]
        sock = getattr(self, "_SocketCanDaemonBus__socket", None)  # python-can 4.x keeps it private
        if not isinstance(sock, socket.socket):
            raise can.CanInterfaceNotImplementedError(
                f"python-can {can.__version__}: its socketcand client has no socket to batch frames on"
            )
        self._tcp = sock
        self._queued: list[str] = []

    def fileno(self) -> int:
        """The connection's descriptor, readable when frames are there (drain with `recv(0.0)`
        before waiting on it: frames already parsed are not counted)."""
        return self._tcp.fileno()

    def queue(self, msg: can.Message) -> None:
        """Keep `msg` (as python-can would send it) for the next `flush`. Tick-safe."""
        self._queued.append(convert_can_message_to_ascii_message(msg))

    def flush(self) -> None:
        """Write the queued frames in order, in one TCP write. Tick-safe (one system call)."""
        if self._queued:
            payload = "".join(self._queued).encode("ascii")
            self._queued.clear()
            try:
                self._tcp.sendall(payload)
            except OSError as e:
                raise can.CanOperationError(f"socketcand send: {e}") from e


def open_bus(bus: Bus) -> can.BusABC:
    """The python-can bus for `bus`: SocketCAN as python-can has it, socketcand batched."""
    kwargs = bus.bus_kwargs()
    if bus.interface == "socketcand":
        kwargs.pop("interface")
        return BatchingSocketcandBus(**kwargs)
    return can.Bus(**kwargs)


class BusPort:
    """One bus of the master (`axes`: indices in joint order of the axes it carries)."""

    def __init__(self, bus: Bus) -> None:
        self.conf = bus
        self.axes = bus.axes
        self.where = bus.where()
        self.bus: can.BusABC | None = None
        self.network: canopen.Network | None = None
        self.nodes: list[canopen.RemoteNode] = []
        self.sync_task: can.broadcastmanager.CyclicSendTaskABC | None = None
        self.startup_heartbeat: can.broadcastmanager.CyclicSendTaskABC | None = None
        self.syncs_sent = 0
        self.sync_wall_s = 0.0  # wall-clock time (s) when the loop last queued SYNC
        self.error = ""
        # SocketCAN: the kernel's broadcast manager produces SYNC, jitter-free and independent of
        # the loop. Elsewhere python-can would need a thread in the real-time process for it: the
        # control loop sends SYNC itself, once per tick, after the RPDOs.
        self.sync_by_kernel = bus.interface == "socketcan"
        self._queue: Any = None
        self.fileno = -1  # the bus's file descriptor once open (-1: none to wait on)

    def open(self) -> canopen.Network:
        try:
            self.bus = open_bus(self.conf)
        except (can.CanError, OSError, ValueError) as e:
            raise ResourceError(f"CAN bus {self.where}: cannot open: {e}") from None
        self._queue = getattr(self.bus, "queue", self.bus.send)
        try:  # to wait for frames (`tpdo_wait_us`): SocketCAN's socket, socketcand's connection
            self.fileno = self.bus.fileno()
        except NotImplementedError:
            self.fileno = -1
        net = canopen.Network(self.bus)
        net.NOTIFIER_CYCLE = 0.05
        net.connect()
        self.network = net
        return net

    def start_heartbeat(self, msg: can.Message, period_s: float) -> None:
        """Our heartbeat from python-can's periodic send until `stop_heartbeat`."""
        assert self.bus is not None
        try:
            self.startup_heartbeat = self.bus.send_periodic(msg, period_s)
        except (can.CanError, OSError) as e:
            raise ResourceError(f"CAN bus {self.where}: cannot send our heartbeat: {e}") from None

    def stop_heartbeat(self) -> None:
        task, self.startup_heartbeat = self.startup_heartbeat, None
        if task is not None:
            with contextlib.suppress(can.CanError, OSError):
                task.stop()

    def cyclic(self, sync: can.Message, period_s: float) -> None:
        """From startup to the cyclic exchange: the control thread reads the bus itself from now
        on (the network's reader thread stops), SYNC by the kernel where it can."""
        net = self.network
        if net is not None and net.notifier is not None:
            net.notifier.stop(1.0)
            net.notifier = None
        if self.sync_by_kernel and self.bus is not None:
            self.sync_task = self.bus.send_periodic(sync, period_s)

    @property
    def cyclic_started(self) -> bool:
        return self.network is not None and self.network.notifier is None

    def queue(self, msg: can.Message) -> None:
        """A frame for this tick's `flush` (sent at once where a frame is one system call)."""
        if self._queue is None:
            return
        try:
            self._queue(msg)
        except (can.CanError, OSError) as e:
            self.error = self.error or f"CAN bus {self.where}: {e}"

    def flush(self) -> None:
        flush = getattr(self.bus, "flush", None)
        if flush is not None:
            try:
                flush()
            except (can.CanError, OSError) as e:
                self.error = self.error or f"CAN bus {self.where}: {e}"

    def close(self, last_frames: list[can.Message]) -> None:
        """Stop SYNC and heartbeat, send `last_frames` (disable voltage), close the bus."""
        self.stop_heartbeat()
        if self.sync_task is not None:
            with contextlib.suppress(can.CanError, OSError):
                self.sync_task.stop()
            self.sync_task = None
        if self.bus is not None:
            for msg in last_frames:
                try:
                    self.bus.send(msg)
                except (can.CanError, OSError):
                    break
        net, self.network = self.network, None
        if net is not None and net.notifier is not None:
            net.notifier.stop(1.0)
            net.notifier = None
        bus, self.bus = self.bus, None
        self._queue = None
        if bus is not None:
            with contextlib.suppress(can.CanError, OSError):
                bus.shutdown()
