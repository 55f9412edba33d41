"""The process data the `ethercat402` backend maps on each drive, and how they are packed.

One RxPDO: controlword, then the target of each cyclic mode the drive has (CSP 0x607A, CSV
0x60FF, CST 0x6071) and the mode of operation (0x6060), so a task switches mode within one cycle
by the byte it sends. One TxPDO: statusword, position actual value, and what the drive has of
velocity and torque actual values, mode display and error code (0x603F: a fault's cause in the
cycle it happens). What a drive lacks (by its description) is left out; the layout is then the
same in the backend's struct formats and in the slave's SM lengths.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

import canopen
from canopen.objectdictionary import ODVariable

from orccadd.drivers.ethercat.settings import RX_OBJECTS, TX_OBJECTS

_CODES = {
    (8, False): "B",
    (8, True): "b",
    (16, False): "H",
    (16, True): "h",
    (32, False): "I",
    (32, True): "i",
}
_SIGNED = frozenset(
    {
        canopen.objectdictionary.INTEGER8,
        canopen.objectdictionary.INTEGER16,
        canopen.objectdictionary.INTEGER32,
    }
)


@dataclass(frozen=True)
class PdoLayout:
    """The objects of a drive's RxPDO and TxPDO, in order, and their packing (little-endian)."""

    rx: tuple[int, ...]  # indices (sub-index 0 each)
    tx: tuple[int, ...]
    rx_bits: tuple[int, ...]
    tx_bits: tuple[int, ...]
    rx_format: str
    tx_format: str

    @property
    def rx_bytes(self) -> int:
        return struct.calcsize(self.rx_format)

    @property
    def tx_bytes(self) -> int:
        return struct.calcsize(self.tx_format)

    def entries(self, transmit: bool) -> list[int]:
        """The mapping entries (index << 16 | sub << 8 | bits) of the TxPDO or the RxPDO."""
        objects, bits = (self.tx, self.tx_bits) if transmit else (self.rx, self.rx_bits)
        return [index << 16 | b for index, b in zip(objects, bits, strict=True)]


def layout_for(od: canopen.ObjectDictionary) -> PdoLayout:
    """The layout for a drive described by `od`: every object of `RX_OBJECTS` / `TX_OBJECTS` it
    has as a mappable variable."""
    parts: dict[bool, tuple[list[int], list[int], str]] = {}
    for transmit, wanted in ((False, RX_OBJECTS), (True, TX_OBJECTS)):
        objects, bits, fmt = [], [], "<"
        for index, _sub, size in wanted:
            var = od.get(index)
            if not isinstance(var, ODVariable) or not (var.pdo_mappable or index in (0x6060, 0x6061)):
                continue
            objects.append(index)
            bits.append(size)
            fmt += _CODES[(size, var.data_type in _SIGNED)]
        parts[transmit] = (objects, bits, fmt)
    (rx, rx_bits, rx_fmt), (tx, tx_bits, tx_fmt) = parts[False], parts[True]
    return PdoLayout(tuple(rx), tuple(tx), tuple(rx_bits), tuple(tx_bits), rx_fmt, tx_fmt)
