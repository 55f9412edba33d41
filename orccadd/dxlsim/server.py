"""The simulator's loop: bytes from the controller in, status packets out on time, the arm moving.

One thread does everything, in order, so nothing needs a lock: read what the controller wrote,
cut it into instruction packets, let the chain execute each, queue the status packets at the
time their last byte would reach the controller (`link`), write those that are due, integrate
the arm up to now, serve the control channel. It sleeps in `select` until the next status packet
is due, a byte arrives, or `IDLE_S` passes (the arm keeps moving between transactions).
"""

from __future__ import annotations

import heapq
import select
import time
from collections.abc import Callable

from orccadd.dxlsim.chain import Chain
from orccadd.dxlsim.control import ControlServer
from orccadd.dxlsim.link import PtyLink, wire_time_s
from orccadd.dxlsim.protocol import PacketReader

USB_PACKET_DATA = 62  # an FTDI adapter's USB packet: 64 bytes, 2 of them its status
IDLE_S = 0.001
EARLY_S = 0.0001  # a status packet due sooner than this is written now (select's own jitter)
RECEIVE_TIMEOUT_S = 0.1  # an unfinished packet older than this is dropped (a servo's timeout)
MAX_CATCH_UP_S = 1.0  # a longer gap (the process was stopped) is skipped, not integrated


class Server:
    def __init__(
        self, chain: Chain, link: PtyLink, control: ControlServer | None = None, latency_s: float = 0.0
    ) -> None:
        self.chain = chain
        # the USB adapter's latency timer: the part of a status packet short of a full USB packet
        # (62 bytes of data) waits in the adapter until the timer runs out, as an FTDI chip
        # holds it: the reply is complete at the controller that much later
        self.latency_s = latency_s
        self.link = link
        self.control = control
        self.reader = PacketReader()
        self.baud = chain.baud
        self._outbox: list[tuple[float, int, bytes]] = []  # (due time, sequence, bytes)
        self._sequence = 0
        self._rx_start_s = 0.0  # when the first byte of the packet being received arrived
        self._last_rx_s = 0.0
        self.bus_free_s = 0.0  # when the last status packet queued leaves the line

    def run(self, stop: Callable[[], bool]) -> None:
        """Serve until `stop()` (checked at least every `IDLE_S`)."""
        self.chain.start(time.monotonic())
        while not stop():
            now = time.monotonic()
            timeout = IDLE_S
            if self._outbox:
                timeout = max(0.0, min(timeout, self._outbox[0][0] - now - EARLY_S))
            fds = [self.link.master, *(self.control.fds() if self.control else [])]
            readable, _, _ = select.select(fds, [], [], timeout)
            now = time.monotonic()
            self.chain.advance_to(now, MAX_CATCH_UP_S)
            if self.link.master in readable:
                self.receive(self.link.read(), now)
            self.flush(time.monotonic())
            if self.control is not None and readable:
                self.control.serve([fd for fd in readable if fd != self.link.master], self.chain, now)

    def receive(self, data: bytes, now_s: float) -> None:
        """Bytes the controller wrote, read at `now_s`: execute the packets they complete."""
        if not data:
            return
        if self.reader.pending and now_s - self._last_rx_s > RECEIVE_TIMEOUT_S:
            self.reader.discard_partial()
        if not self.reader.pending:
            self._rx_start_s = now_s
        self._last_rx_s = now_s
        for packet in self.reader.feed(data):
            arrived_s = self._rx_start_s + wire_time_s(packet.wire_bytes, self.baud)
            self._rx_start_s = arrived_s  # the next packet of the same write follows it
            t = max(arrived_s, self.bus_free_s)
            late_s = 0.0
            for reply in self.chain.handle(packet, now_s):
                late_s = late_s or self.chain.delay_s()  # one transaction's replies late together
                t += reply.delay_s + wire_time_s(len(reply.data), self.baud)
                # whole USB packets leave at once; a reply's tail shorter than one waits the timer
                held = self.latency_s if len(reply.data) % USB_PACKET_DATA else 0.0
                self._queue(t + late_s + held, self.chain.corrupt(reply.data))
            self.bus_free_s = t + late_s  # what follows on the bus comes after it
        if not self.reader.pending:
            self._rx_start_s = now_s

    def _queue(self, due_s: float, data: bytes) -> None:
        self._sequence += 1
        heapq.heappush(self._outbox, (due_s, self._sequence, data))

    def flush(self, now_s: float) -> None:
        """Write the status packets due by `now_s`."""
        while self._outbox and self._outbox[0][0] - EARLY_S <= now_s:
            _, _, data = heapq.heappop(self._outbox)
            self.link.write(data)
