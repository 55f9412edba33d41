"""The Slave Information Interface: the EEPROM image an ESC loads its identity and settings from
(ETG.1000.6 5.4, ETG.2010), built from what a simulated slave is.

Words 0-7 configure the ESC (PDI control and configuration, SYNC pulse length, station alias,
and a CRC-8 over bytes 0-13 in word 7); words 8-0x3F hold the identity (vendor id, product code,
revision, serial number) and the mailboxes (standard receive and send mailbox: offset and size,
the protocols served); categories follow from word 0x40, each a type word, a size in words and
its data: strings (10), general (30: CoE details, the name's string), FMMU (40), sync managers
(41), distributed clocks are the ESC's own feature register; the end marker is 0xFFFF.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

CATEGORY_STRINGS = 10
CATEGORY_GENERAL = 30
CATEGORY_FMMU = 40
CATEGORY_SYNC_MANAGERS = 41
CATEGORY_END = 0xFFFF

MAILBOX_COE = 0x0004  # word 0x1C: mailbox protocols (bit 2 CoE)
COE_SDO = 0x01  # general category, CoE details
COE_SDO_INFO = 0x02
COE_PDO_ASSIGN = 0x04
COE_PDO_CONFIG = 0x08
COE_COMPLETE_ACCESS = 0x20

FMMU_UNUSED, FMMU_OUTPUTS, FMMU_INPUTS, FMMU_MAILBOX_STATE = 0x00, 0x01, 0x02, 0x03
SM_UNUSED, SM_MAILBOX_OUT, SM_MAILBOX_IN, SM_OUTPUTS, SM_INPUTS = 0, 1, 2, 3, 4  # SM type byte


@dataclass(frozen=True)
class SyncManagerEntry:
    """One sync manager's default as the SII gives it (8 bytes in category 41)."""

    start: int  # physical start address in the ESC's memory
    length: int  # bytes (0 for process data: the PDO mapping decides)
    control: int  # the control register's value (mode, direction, interrupts, watchdog)
    activate: int  # the activate register's value (bit 0: enabled)
    kind: int  # SM_MAILBOX_OUT, SM_MAILBOX_IN, SM_OUTPUTS, SM_INPUTS


@dataclass(frozen=True)
class SlaveInfo:
    """What the SII says of a slave."""

    vendor_id: int
    product_code: int
    revision: int
    serial: int
    name: str
    mailbox_out: tuple[int, int]  # (offset, size): the master writes here (SM0)
    mailbox_in: tuple[int, int]  # (offset, size): the master reads here (SM1)
    sync_managers: tuple[SyncManagerEntry, ...]
    fmmus: tuple[int, ...] = (FMMU_OUTPUTS, FMMU_INPUTS, FMMU_MAILBOX_STATE)
    coe_details: int = COE_SDO | COE_PDO_ASSIGN | COE_PDO_CONFIG | COE_COMPLETE_ACCESS
    pdi_control: int = 0x05  # SPI slave: the application's microcontroller
    sync_pulse_10ns: int = 1000  # SYNC0 pulse length: 10 µs
    alias: int = 0


def crc8(data: bytes) -> int:
    """The SII's header checksum: CRC-8, polynomial x^8 + x^2 + x + 1, initial value 0xFF."""
    crc = 0xFF
    for byte in data:
        crc ^= byte
        for _ in range(8):
            crc = ((crc << 1) ^ 0x07) & 0xFF if crc & 0x80 else (crc << 1) & 0xFF
    return crc


def _category(kind: int, data: bytes) -> bytes:
    if len(data) % 2:
        data += b"\x00"
    return struct.pack("<HH", kind, len(data) // 2) + data


def build_image(info: SlaveInfo, size_bytes: int = 2048) -> bytes:
    """The EEPROM's content, `size_bytes` long (unused words 0xFFFF, as an erased EEPROM)."""
    head = bytearray(struct.pack("<HHHHH", info.pdi_control, 0, info.sync_pulse_10ns, 0, info.alias))
    head += bytes(14 - len(head))
    head += struct.pack("<BB", crc8(bytes(head)), 0)
    ident = struct.pack("<IIII", info.vendor_id, info.product_code, info.revision, info.serial)
    mailboxes = struct.pack("<8x4H4HH", 0, 0, 0, 0, *info.mailbox_out, *info.mailbox_in, MAILBOX_COE)
    image = bytearray(head + ident + mailboxes)
    image += bytes(0x3E * 2 - len(image))
    image += struct.pack("<HH", size_bytes * 8 // 1024 - 1, 1)  # size in kbit - 1, version 1
    name = info.name.encode("ascii")[:255]
    image += _category(CATEGORY_STRINGS, bytes([1, len(name)]) + name)
    general = bytearray(32)
    general[3] = 1  # the name: string 1
    general[5] = info.coe_details
    image += _category(CATEGORY_GENERAL, bytes(general))
    image += _category(CATEGORY_FMMU, bytes(info.fmmus))
    sms = b"".join(
        struct.pack("<HHBBBB", s.start, s.length, s.control, 0, s.activate, s.kind)
        for s in info.sync_managers
    )
    image += _category(CATEGORY_SYNC_MANAGERS, sms)
    image += struct.pack("<H", CATEGORY_END)
    if len(image) > size_bytes:
        raise ValueError(f"the SII of {info.name!r} needs {len(image)} bytes, the EEPROM has {size_bytes}")
    return bytes(image) + b"\xff" * (size_bytes - len(image))
