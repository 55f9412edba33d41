"""The shipped generic CiA 402 description is the generator's output, and canopen reads it as a
drive with what orccadd needs (heartbeat consumer entries that take a producer id, CSP/CSV/CST)."""

from __future__ import annotations

import canopen

from orccadd.drivers.canopen.capabilities import consumer_entry
from tools.make_cia402_eds import OUT, OUT_ECAT, eds


def test_the_shipped_file_is_the_generators_output() -> None:
    assert OUT.read_text() == eds(), "run: python tools/make_cia402_eds.py"
    assert OUT_ECAT.read_text() == eds(ethercat=True), "run: python tools/make_cia402_eds.py"


def test_canopen_reads_it_as_a_cia_402_drive() -> None:
    od = canopen.import_od(str(OUT), 5)
    assert od[0x1000].default == 0x00020192
    assert od[0x6502].default & 0x380 == 0x380  # CSP, CSV, CST
    assert od[0x1400][1].default == 0x205 and od[0x1800][1].default == 0x185  # $NODEID resolved
    assert consumer_entry(od, 0x7F) == 1  # our heartbeat can be watched
    for index in (0x6040, 0x6041, 0x6060, 0x6061, 0x6064, 0x606C, 0x6071, 0x6077, 0x607A, 0x60FF):
        assert od[index].pdo_mappable, hex(index)
