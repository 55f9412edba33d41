"""The object store alone: defaults, SDO reads and writes as bytes, each refusal's abort code, the
owner's hooks and a subclass's in their order."""

from __future__ import annotations

import struct
from typing import Any

import pytest
from canopen.objectdictionary import ODVariable

from orccadd.drivesim.objects import ObjectStore, SdoAbortError
from tests.conftest import ROOT

EDS = str(ROOT / "configs" / "eds" / "orccadd-cia402.eds")


@pytest.fixture
def store() -> ObjectStore:
    return ObjectStore(EDS, 3)


def abort_of(call: Any, *args: Any) -> int:
    with pytest.raises(SdoAbortError) as e:
        call(*args)
    return e.value.code


def test_values_start_at_the_description_defaults_and_read_as_their_type(store: ObjectStore) -> None:
    assert store.get(0x1000) == 0x00020192 and store.read(0x1000, 0) == struct.pack("<I", 0x00020192)
    assert store.get(0x1014) == 0x83  # $NODEID+0x80
    assert store.read(0x1A00, 1) == struct.pack("<I", 0x60410010)
    assert store.read(0x6060, 0) == b"\x08"  # INTEGER8: one byte
    assert store.has(0x1A00, 8) and not store.has(0x1A00, 9)


def test_a_write_decodes_stores_and_calls_the_hook(store: ObjectStore) -> None:
    seen: list[int] = []
    store.on_write[(0x607A, 0)] = seen.append
    store.write(0x607A, 0, struct.pack("<i", -1000))
    assert store.get(0x607A) == -1000 and seen == [-1000]


@pytest.mark.parametrize(
    ("index", "sub", "data", "code"),
    [
        (0x2000, 0, b"\x00", 0x06020000),  # no object
        (0x1A00, 9, b"\x00\x00\x00\x00", 0x06090011),  # no such sub-index
        (0x1000, 0, b"\x00\x00\x00\x00", 0x06010002),  # read-only
        (0x607A, 0, b"\x01\x00", 0x06070010),  # 2 bytes for an INTEGER32
        (0x1A00, 0, b"\x09", 0x06090031),  # HighLimit 8
    ],
)
def test_a_refused_write_aborts_with_its_code_and_leaves_the_value(
    store: ObjectStore, index: int, sub: int, data: bytes, code: int
) -> None:
    before = dict(store.values)
    assert abort_of(store.write, index, sub, data) == code
    assert store.values == before


def test_below_the_low_limit_and_write_only(store: ObjectStore) -> None:
    store.vars[(0x6066, 0)].min = 10
    assert abort_of(store.write, 0x6066, 0, b"\x09\x00") == 0x06090032
    store.vars[(0x6040, 0)].access_type = "wo"
    assert abort_of(store.read, 0x6040, 0) == 0x06010001


def test_a_check_refuses_before_the_value_is_stored(store: ObjectStore) -> None:
    def no_odd(value: int) -> None:
        if value % 2:
            raise SdoAbortError(0x08000022)

    store.checks[(0x6040, 0)] = no_odd
    assert abort_of(store.write, 0x6040, 0, b"\x07\x00") == 0x08000022
    assert store.get(0x6040) == 0
    store.write(0x6040, 0, b"\x06\x00")
    assert store.get(0x6040) == 6


class Traced(ObjectStore):
    def __init__(self) -> None:
        super().__init__(EDS, 1)
        self.trace: list[str] = []

    def _before_store(self, var: ODVariable, value: Any) -> None:
        self.trace.append(f"before {value}")
        if value == 0x99:
            raise SdoAbortError(0x06010000)

    def _after_store(self, var: ODVariable, value: Any) -> None:
        self.trace.append(f"after {self.get(var.index, var.subindex)}")


def test_a_subclass_rules_come_before_the_limits_and_its_reaction_before_the_hook() -> None:
    store = Traced()
    store.on_write[(0x1A00, 0)] = lambda value: store.trace.append(f"hook {value}")
    store.write(0x1A00, 0, b"\x03")
    assert store.trace == ["before 3", "after 3", "hook 3"]
    store.trace.clear()
    assert abort_of(store.write, 0x1A00, 0, b"\x99") == 0x06010000  # its code, not HighLimit's
    assert store.trace == ["before 153"] and store.get(0x1A00) == 3


def test_defaults_of_the_communication_profile_only(store: ObjectStore) -> None:
    store.set(0x1017, 0, 500)
    store.set(0x607A, 0, 1234)
    store.defaults(comm_only=True)
    assert store.get(0x1017) != 500 and store.get(0x607A) == 1234
    store.defaults(comm_only=False)
    assert store.get(0x607A) == 0


def test_an_unsized_download_takes_the_object_size(store: ObjectStore) -> None:
    var = store.var(0x6066, 0)
    assert store.unsized(var, b"\x7b\x00\x00\x00") == b"\x7b\x00"
    assert abort_of(store.unsized, var, b"\x05\x00\x01\x00") == 0x06070012
