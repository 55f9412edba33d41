"""EtherCAT frames and their datagrams (ETG.1000.4, the data link layer), as they travel in an
Ethernet frame of type 0x88A4.

After the Ethernet header, a 2-byte EtherCAT header (little-endian: the datagrams' length in
bits 0–10, the type in bits 12–15, 1 for datagrams), then the datagrams, each a 10-byte header
— command, index, address (a position or a station address and a register offset, or one
logical address), length in bits 0–10 with "circulated" in bit 14 and "more follow" in bit 15,
interrupt word — its data, and its 16-bit working counter. Every field is little-endian.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, replace
from enum import IntEnum

ETHERTYPE = 0x88A4
ETH_HEADER = struct.Struct("!6s6sH")  # destination, source, type (network order)
ECAT_HEADER = struct.Struct("<H")
DATAGRAM_HEADER = struct.Struct("<BBIHH")  # command, index, address, length and flags, IRQ
WKC = struct.Struct("<H")
TYPE_DATAGRAMS = 1
LENGTH_MASK = 0x07FF
CIRCULATED = 0x4000
MORE = 0x8000
ETH_MIN_PAYLOAD = 46  # an Ethernet frame's payload is padded to this


class FrameError(ValueError):
    """Bytes that are not an EtherCAT frame, saying where."""


class Command(IntEnum):
    """A datagram's command: how it addresses slaves and whether it reads, writes or both."""

    NOP = 0
    APRD = 1  # auto-increment (position) read
    APWR = 2
    APRW = 3
    FPRD = 4  # configured station address read
    FPWR = 5
    FPRW = 6
    BRD = 7  # broadcast read
    BWR = 8
    BRW = 9
    LRD = 10  # logical read
    LWR = 11
    LRW = 12
    ARMW = 13  # auto-increment read, multiple write
    FRMW = 14  # configured address read, multiple write


@dataclass(frozen=True)
class Datagram:
    command: Command
    index: int  # the master's number for it, echoed back
    address: int  # 32 bits: (ADO << 16) | ADP for position and station addressing; logical otherwise
    data: bytes
    wkc: int = 0  # the working counter: incremented by each slave that took it
    irq: int = 0
    circulated: bool = False

    @property
    def adp(self) -> int:
        """The position (auto-increment) or station address: the address's low 16 bits."""
        return self.address & 0xFFFF

    @property
    def ado(self) -> int:
        """The register offset in the slave: the address's high 16 bits."""
        return self.address >> 16

    def answered(self, data: bytes, wkc: int) -> Datagram:
        """This datagram as the chain returns it: its data and working counter."""
        return replace(self, data=data, wkc=wkc)


def parse(payload: bytes) -> list[Datagram]:
    """The datagrams of an EtherCAT frame's payload (after the Ethernet header; Ethernet padding
    after the datagrams is ignored). `FrameError` naming the byte where it goes wrong."""
    if len(payload) < ECAT_HEADER.size:
        raise FrameError(f"an EtherCAT frame of {len(payload)} bytes: shorter than its 2-byte header")
    (header,) = ECAT_HEADER.unpack_from(payload)
    length, kind = header & LENGTH_MASK, header >> 12
    if kind != TYPE_DATAGRAMS:
        raise FrameError(f"EtherCAT frame type {kind}: only type {TYPE_DATAGRAMS} (datagrams) is served")
    end = ECAT_HEADER.size + length
    if end > len(payload):
        have = len(payload) - ECAT_HEADER.size
        raise FrameError(f"the EtherCAT header says {length} bytes of datagrams, the frame has {have}")
    out: list[Datagram] = []
    at = ECAT_HEADER.size
    more = True
    while more:
        if at + DATAGRAM_HEADER.size + WKC.size > end:
            raise FrameError(f"datagram {len(out)} at byte {at}: past the datagrams' {length} bytes")
        command, index, address, flags, irq = DATAGRAM_HEADER.unpack_from(payload, at)
        size = flags & LENGTH_MASK
        data_at = at + DATAGRAM_HEADER.size
        if data_at + size + WKC.size > end:
            what = f"{size} bytes of data past the datagrams' end"
            raise FrameError(f"datagram {len(out)} at byte {at}: {what}")
        try:
            cmd = Command(command)
        except ValueError:
            raise FrameError(f"datagram {len(out)} at byte {at}: no command {command}") from None
        (wkc,) = WKC.unpack_from(payload, data_at + size)
        data = bytes(payload[data_at : data_at + size])
        out.append(Datagram(cmd, index, address, data, wkc, irq, bool(flags & CIRCULATED)))
        more = bool(flags & MORE)
        at = data_at + size + WKC.size
    if at != end:
        raise FrameError(f"{end - at} bytes after the last datagram (its 'more' bit is clear)")
    return out


def encode(datagrams: list[Datagram]) -> bytes:
    """An EtherCAT frame's payload carrying `datagrams` (unpadded)."""
    if not datagrams:
        raise FrameError("an EtherCAT frame carries one datagram at least")
    body = bytearray()
    for i, d in enumerate(datagrams):
        if len(d.data) > LENGTH_MASK:
            raise FrameError(f"datagram {i}: {len(d.data)} bytes of data (at most {LENGTH_MASK})")
        flags = len(d.data) | (CIRCULATED if d.circulated else 0) | (MORE if i < len(datagrams) - 1 else 0)
        body += DATAGRAM_HEADER.pack(d.command, d.index, d.address, flags, d.irq)
        body += d.data
        body += WKC.pack(d.wkc)
    if len(body) > LENGTH_MASK:
        raise FrameError(f"{len(body)} bytes of datagrams in one frame (at most {LENGTH_MASK})")
    return ECAT_HEADER.pack(len(body) | TYPE_DATAGRAMS << 12) + bytes(body)


@dataclass(frozen=True)
class EthernetFrame:
    destination: bytes
    source: bytes
    datagrams: list[Datagram]

    @staticmethod
    def parse(frame: bytes) -> EthernetFrame:
        """An Ethernet frame of type 0x88A4; `FrameError` for another type or bad datagrams."""
        if len(frame) < ETH_HEADER.size:
            raise FrameError(f"an Ethernet frame of {len(frame)} bytes: shorter than its header")
        dst, src, kind = ETH_HEADER.unpack_from(frame)
        if kind != ETHERTYPE:
            raise FrameError(f"Ethernet type 0x{kind:04X}, not EtherCAT's 0x{ETHERTYPE:04X}")
        return EthernetFrame(dst, src, parse(frame[ETH_HEADER.size :]))

    def encode(self) -> bytes:
        """The frame on the wire, its payload padded to Ethernet's minimum."""
        payload = encode(self.datagrams)
        payload += bytes(max(0, ETH_MIN_PAYLOAD - len(payload)))
        return ETH_HEADER.pack(self.destination, self.source, ETHERTYPE) + payload
