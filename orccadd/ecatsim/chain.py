"""A line of ESCs as a frame passes through them: each datagram served by every slave in turn,
its working counter counted, its position address incremented.

Addressing (ETG.1000.4 5.2): a position (auto-increment) datagram is for the slave that finds
its address 0, and every slave adds one to it; a station-address datagram is for the slave whose
configured address it names; a broadcast is for all of them (a broadcast read ORs each slave's
bytes into the data); a logical one is for every slave whose FMMUs map part of it. The working
counter: +1 per slave that read, +1 per slave that wrote, +3 for a read-write (read and write);
LRW counts +1 for the inputs a slave put in and +2 for the outputs it took. ARMW and FRMW: the
addressed slave reads (+1), every other writes (+1) — the distributed clocks' reference time
handed down the line. Accesses an ESC refuses (a full mailbox, an empty one) do not count.

The frame reaches slave k `k × FORWARD_NS` after the first, and comes back through it after
passing the slaves beyond: what the distributed clocks' receive-time latches see.

Faults (`orccadd.ecatsim` injects them): a cable pulled before a slave (it and every slave after
it unreachable, the slave before closes its port 1), lost frames (no answer at all), and a slave
that leaves its process data alone for some frames (the working counter short of what the
master expects).
"""

from __future__ import annotations

from dataclasses import dataclass

from orccadd.ecatsim.esc import Esc
from orccadd.ecatsim.frame import Command, Datagram
from orccadd.ecatsim.registers import AlState

FORWARD_NS = 500  # one slave's forwarding delay and its cable, each way
LOOP_NS = 300  # the last slave turning the frame round (its port 1 closed)

_POSITION = frozenset({Command.APRD, Command.APWR, Command.APRW, Command.ARMW})
_STATION = frozenset({Command.FPRD, Command.FPWR, Command.FPRW, Command.FRMW})
_BROADCAST = frozenset({Command.BRD, Command.BWR, Command.BRW})
_LOGICAL = frozenset({Command.LRD, Command.LWR, Command.LRW})
_READS = frozenset({Command.APRD, Command.APRW, Command.FPRD, Command.FPRW, Command.BRD, Command.BRW})
_WRITES = frozenset({Command.APWR, Command.APRW, Command.FPWR, Command.FPRW, Command.BWR, Command.BRW})


@dataclass
class ChainCounters:
    frames: int = 0
    frames_lost: int = 0  # dropped on purpose (a fault)
    datagrams: int = 0


class Chain:
    def __init__(self, escs: list[Esc]) -> None:
        self.escs = escs
        self.counters = ChainCounters()
        self.cut_before = len(escs)  # position (0-based) of the first unreachable slave
        self.frames_to_lose = 0
        self.skip_process_data: dict[int, int] = {}  # position -> frames it leaves its process data
        self._wire()

    @property
    def reachable(self) -> list[Esc]:
        return self.escs[: self.cut_before]

    def _wire(self) -> None:
        last = len(self.reachable) - 1
        for pos, esc in enumerate(self.escs):
            esc.set_dl_status(port1_open=pos < last)

    # ---- faults ---------------------------------------------------------------------------------
    def unplug(self, position: int) -> None:
        """The cable before slave `position` (1-based, as masters number them) pulled."""
        if not 1 <= position <= len(self.escs):
            raise ValueError(f"no slave {position}: the chain has {len(self.escs)}")
        self.cut_before = position - 1
        self._wire()

    def replug(self) -> None:
        self.cut_before = len(self.escs)
        self._wire()

    def lose_frames(self, n: int) -> None:
        self.frames_to_lose += n

    def leave_process_data(self, position: int, frames: int) -> None:
        """Slave `position` (1-based) takes no process data for `frames` frames."""
        if not 1 <= position <= len(self.escs):
            raise ValueError(f"no slave {position}: the chain has {len(self.escs)}")
        self.skip_process_data[position - 1] = frames

    # ---- a frame --------------------------------------------------------------------------------
    def process(self, datagrams: list[Datagram], clock_ns: int) -> list[Datagram] | None:
        """The datagrams as they come back to the master; None: the frame is lost."""
        self.counters.frames += 1
        if self.frames_to_lose > 0:
            self.frames_to_lose -= 1
            self.counters.frames_lost += 1
            return None
        self.counters.datagrams += len(datagrams)
        out = [self._datagram(d, clock_ns) for d in datagrams]
        for pos in [p for p, n in self.skip_process_data.items() if n > 0]:
            self.skip_process_data[pos] -= 1
        return out

    def poll(self, clock_ns: int) -> None:
        for esc in self.escs:  # unreachable slaves run on: their watchdogs expire
            esc.poll(clock_ns)

    def _datagram(self, d: Datagram, clock_ns: int) -> Datagram:
        data = bytearray(d.data)
        adp, ado, wkc = d.adp, d.ado, d.wkc
        cmd = d.command
        reachable = self.reachable
        n = len(reachable)
        for pos, esc in enumerate(reachable):
            esc.arrival_ns = clock_ns + pos * FORWARD_NS
            esc.return_ns = clock_ns + (2 * (n - 1) - pos) * FORWARD_NS + LOOP_NS
            at_ns = esc.arrival_ns
            if cmd in _LOGICAL:
                if self.skip_process_data.get(pos, 0) > 0:
                    continue
                wkc += self._logical(esc, cmd, d.address, data, at_ns)
                continue
            if cmd in _POSITION:
                addressed = adp == 0
                adp = (adp + 1) & 0xFFFF
            elif cmd in _STATION:
                addressed = esc.station_address == adp
            elif cmd in _BROADCAST:
                addressed = True
                adp = (adp + 1) & 0xFFFF
            else:  # NOP
                continue
            if cmd in (Command.ARMW, Command.FRMW):
                if addressed:
                    wkc += esc.read(ado, data, at_ns)
                else:
                    wkc += esc.write(ado, bytes(data), at_ns)
                continue
            if not addressed:
                continue
            incoming = bytes(data)
            if cmd in _READS:
                read = bytearray(len(data))
                if esc.read(ado, read, at_ns, merge=cmd in _BROADCAST):
                    wkc += 1
                    if cmd in _BROADCAST:
                        for i, b in enumerate(read):
                            data[i] |= b
                    else:
                        data[:] = read
            if cmd in _WRITES and esc.write(ado, incoming, at_ns):
                wkc += 2 if cmd in _READS else 1
        address = (ado << 16) | adp if cmd not in _LOGICAL else d.address
        return Datagram(cmd, d.index, address, bytes(data), wkc & 0xFFFF, d.irq, d.circulated)

    @staticmethod
    def _logical(esc: Esc, cmd: Command, address: int, data: bytearray, at_ns: int) -> int:
        # below SAFE-OP the firmware holds the process data sync managers (PDI control bit 0):
        # neither read nor written, not counted; the master sees the slave missing in the count
        if esc.al_state not in (AlState.SAFE_OP, AlState.OP):
            return 0
        read = cmd in (Command.LRD, Command.LRW)
        write = cmd in (Command.LWR, Command.LRW)
        return esc.logical(address, data, read, write, at_ns)
